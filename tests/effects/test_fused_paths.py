"""Every effect renders the same on the fused CPU kernels as on the PyTorch path, with the
same gradients: the fused kernels change the speed, never the look."""

import pytest
import torch
import torch.nn.functional as F
from skimage import data

import wise
from tests.filters.paths import kernels

EFFECTS = wise.effects.available()


@pytest.fixture(scope="module")
def photos(astronaut: torch.Tensor) -> torch.Tensor:
    """Two photos at 192x192: the astronaut and the coffee cup."""
    coffee = torch.from_numpy(data.coffee()).permute(2, 0, 1)[None].float() / 255.0
    return torch.cat([F.interpolate(p, size=(192, 192), mode="area") for p in (astronaut, coffee)])


@pytest.mark.parametrize("name", EFFECTS)
def test_every_preset_renders_the_same_on_both_paths(name: str, photos: torch.Tensor) -> None:
    effect = wise.effects.create(name)
    for preset in effect.presets:
        params = effect.preset(preset)[None].expand(len(photos), -1)
        with torch.no_grad():
            with kernels("torch"):
                reference = effect(photos, params)
            with kernels("fused"):
                fused = effect(photos, params)
        difference = (fused - reference).abs()
        assert float(difference.mean()) <= 1e-4, f"{preset}: mean difference {float(difference.mean()):.2e}"
        assert float(difference.flatten().quantile(0.999)) <= 1e-2, f"{preset}: 99.9th percentile"


@pytest.mark.parametrize("name", EFFECTS)
def test_parameter_gradients_agree_on_both_paths(name: str, photos: torch.Tensor) -> None:
    effect = wise.effects.create(name)
    base = effect.preset(next(iter(effect.presets)))[None]
    masks = base[:, :, None, None].expand(2, -1, 12, 12).clone()
    masks += 0.1 * (torch.rand(masks.shape, generator=torch.Generator().manual_seed(0)) - 0.5)
    image = F.interpolate(photos, size=(96, 96), mode="area").double()
    grads = {}
    for path in ("torch", "fused"):
        params = masks.double().requires_grad_()
        with kernels(path):
            out = effect(image, params)
        weights = torch.rand(out.shape, generator=torch.Generator().manual_seed(1), dtype=out.dtype)
        (grads[path],) = torch.autograd.grad((out * weights).sum(), params)
    scale = float(grads["torch"].abs().max())
    assert float((grads["fused"] - grads["torch"]).abs().max()) <= 1e-6 * scale + 1e-9
