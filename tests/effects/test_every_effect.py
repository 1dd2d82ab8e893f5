"""Contracts every effect must meet: presets, gradients for every parameter, masks."""

import pytest
import torch
import torch.nn.functional as F

import wise
from wise.render import render

EFFECTS = wise.effects.available()


@pytest.fixture(scope="module")
def photo(astronaut: torch.Tensor) -> torch.Tensor:
    return F.interpolate(astronaut, size=(160, 160), mode="area")


@pytest.mark.parametrize("name", EFFECTS)
def test_presets_render_finite_images(name: str, photo: torch.Tensor) -> None:
    effect = wise.effects.create(name)
    assert len(effect.presets) >= 2
    outputs = []
    for preset in effect.presets:
        with torch.no_grad():
            out = effect(photo, effect.preset(preset)[None])
        assert out.shape == photo.shape and torch.isfinite(out).all()
        assert out.min() >= 0.0 and out.max() <= 1.0
        outputs.append(out)
    assert (outputs[0] - outputs[1]).abs().mean() > 0.01


@pytest.mark.parametrize("name", EFFECTS)
@pytest.mark.parametrize("local", [False, True])
def test_every_parameter_gets_a_gradient(name: str, local: bool, photo: torch.Tensor) -> None:
    effect = wise.effects.create(name)
    base = effect.preset(next(iter(effect.presets)))[None]
    params = base[:, :, None, None].expand(-1, -1, 20, 20).clone() if local else base.clone()
    params.requires_grad_()
    out = effect(photo, params)
    target = torch.rand(out.shape, generator=torch.Generator().manual_seed(0))
    ((out - target) ** 2).mean().backward()
    assert torch.isfinite(params.grad).all()
    magnitude = params.grad.abs().flatten(2).sum(-1)[0] if local else params.grad.abs()[0]
    missing = [n for n, g in zip(effect.param_names, magnitude) if not g > 0]
    assert not missing, f"{name}: no gradient for {missing}"


@pytest.mark.parametrize("name", EFFECTS)
def test_every_parameter_visibly_changes_the_output(name: str, photo: torch.Tensor) -> None:
    effect = wise.effects.create(name)
    base = effect.preset(next(iter(effect.presets)))
    weak = []
    with torch.no_grad():
        for i, spec in enumerate(effect.param_specs):
            low, high = base.clone(), base.clone()
            low[i], high[i] = -0.5, 0.5
            change = (effect(photo, low[None]) - effect(photo, high[None])).abs().mean(dim=1)
            # visible over the picture, or as strokes: a hundredth of it changed by 0.05 (accents)
            if change.mean() < 0.004 and change.flatten().quantile(0.99) < 0.05:
                weak.append(f"{spec.name} ({float(change.mean()):.4f} mean)")
    assert not weak, f"{name}: parameters without a visible effect over their range: {weak}"


@pytest.mark.parametrize("name", EFFECTS)
def test_constant_mask_equals_global_parameters(name: str, photo: torch.Tensor) -> None:
    effect = wise.effects.create(name)
    base = effect.preset(next(iter(effect.presets)))[None]
    with torch.no_grad():
        global_out = effect(photo, base)
        local_out = effect(photo, base[:, :, None, None].expand(-1, -1, 16, 16))
    difference = (global_out - local_out).abs()
    assert difference.mean() < 1e-4 and (difference > 0.05).float().mean() < 1e-3


@pytest.fixture(scope="module")
def photo_256(astronaut: torch.Tensor) -> torch.Tensor:
    return F.interpolate(astronaut, size=(256, 256), mode="area")


@pytest.mark.parametrize("name", ["specular", "shininess"])
def test_oil_paints_highlights_show_from_minimum_to_maximum(name: str, photo_256: torch.Tensor) -> None:
    # as a user sees them: rendered as `wise apply` renders, the others mid-range, on a 256-px photo
    # (every parameter of every effect: benchmarks/bench_medium.py --params)
    effect = wise.effects.create("oilpaint").eval()
    index = effect.param_names.index(name)
    low, high = torch.zeros(1, len(effect.param_specs)), torch.zeros(1, len(effect.param_specs))
    low[0, index], high[0, index] = -0.5, 0.5
    with torch.no_grad():
        change = (render(effect, photo_256, high) - render(effect, photo_256, low)).abs()
    mean, p99 = float(change.mean()), float(change.flatten().quantile(0.99))
    assert mean >= 2e-3 or p99 >= 5 / 255, (mean, p99 * 255)
