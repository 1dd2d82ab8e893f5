import torch

from wise.effects.recompute import recompute
from wise.filters import adjust_color


def test_recompute_matches_plain_autograd_and_keeps_only_inputs() -> None:
    image = torch.rand(1, 3, 16, 16, dtype=torch.float64, requires_grad=True)
    contrast = torch.tensor([1.3], dtype=torch.float64, requires_grad=True)
    saved: list[int] = []

    def pack(t: torch.Tensor) -> torch.Tensor:
        saved.append(t.numel())
        return t

    with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
        out = recompute(adjust_color, image, saturation=0.7, contrast=contrast, gamma=1.2)
    assert sum(saved) <= image.numel() + contrast.numel()
    (out * out).sum().backward()
    grads = image.grad.clone(), contrast.grad.clone()
    image.grad = contrast.grad = None
    plain = adjust_color(image, saturation=0.7, contrast=contrast, gamma=1.2)
    (plain * plain).sum().backward()
    assert torch.allclose(out, plain)
    assert torch.allclose(grads[0], image.grad) and torch.allclose(grads[1], contrast.grad)
