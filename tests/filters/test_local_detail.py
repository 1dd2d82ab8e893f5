import torch

from wise.filters.gaussian import local_detail, local_deviation


def test_local_detail_ignores_smooth_shading_but_sees_texture() -> None:
    ramp = torch.linspace(0.2, 0.8, 96, dtype=torch.float64).view(1, 1, 1, 96).expand(1, 1, 96, 96)
    texture = ramp + 0.05 * torch.randn(1, 1, 96, 96, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    inner = (..., slice(24, 72), slice(24, 72))  # away from the replicated border
    assert float(local_detail(ramp, 2.0, 4.0, scale=1.0)[inner].max()) < 1e-4
    assert float(local_detail(texture, 2.0, 4.0, scale=1.0)[inner].min()) > 0.02
    assert float(local_deviation(ramp, 4.0, scale=1.0)[inner].min()) > 0.01  # the deviation counts the shading


def test_local_detail_has_gradients() -> None:
    image = torch.rand(1, 1, 12, 12, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x: local_detail(x, 1.0, 1.5, scale=1.0), (image,), nondet_tol=1e-12)
