import pytest
import torch
import torch.nn.functional as F

import wise
from tests.effects.reference_xdog import REFERENCE_PORTRAIT, REFERENCE_SKETCH
from wise.errors import WiseError


@pytest.fixture(scope="module")
def effect() -> wise.effects.Effect:
    return wise.effects.create("xdog")


@pytest.fixture(scope="module")
def photo(astronaut: torch.Tensor) -> torch.Tensor:
    return F.interpolate(astronaut, size=(192, 192), mode="area")


def test_api_and_presets(effect) -> None:
    assert "xdog" in wise.effects.available()
    assert [s.name for s in effect.param_specs] == [
        "brightness",
        "contrast",
        "saturation",
        "details",
        "stroke_width",
        "contour",
        "blackness",
        "shading",
    ]
    portrait = effect.params_to_dict(effect.preset("portrait"))
    assert portrait["details"] == pytest.approx(2.27) and portrait["blackness"] == pytest.approx(0.15)
    sketch = effect.params_to_dict(effect.preset("sketch"))
    assert sketch["shading"] > 0 and sketch["blackness"] < REFERENCE_SKETCH["blackness"]
    with pytest.raises(WiseError, match="no preset"):
        effect.preset("nope")
    with pytest.raises(WiseError, match="unknown effect"):
        wise.effects.create("nope")


def test_output_is_a_line_drawing(effect, photo) -> None:
    with torch.no_grad():
        out = effect(photo, effect.preset("portrait")[None])
    assert out.shape == photo.shape
    assert torch.equal(out[:, 0], out[:, 1]) and torch.equal(out[:, 0], out[:, 2])
    white, black = (out > 0.95).float().mean(), (out < 0.05).float().mean()
    assert white > 0.5 and 0.02 < black < 0.4
    assert white + black > 0.9


def test_presets_differ(effect, photo) -> None:
    with torch.no_grad():
        portrait = effect(photo, effect.preset("portrait")[None])
        sketch = effect(photo, effect.preset("sketch")[None])
    assert (portrait - sketch).abs().mean() > 0.05


@pytest.mark.parametrize("local", [False, True])
def test_every_parameter_gets_a_gradient(effect, photo, local: bool) -> None:
    base = effect.preset("portrait")[None]
    params = base[:, :, None, None].expand(-1, -1, 24, 24).clone() if local else base.clone()
    params.requires_grad_()
    out = effect(photo, params)
    torch.manual_seed(0)
    target = torch.rand_like(out)
    ((out - target) ** 2).mean().backward()
    grad = params.grad.abs().flatten(2).sum(-1) if local else params.grad.abs()
    assert torch.isfinite(params.grad).all()
    for name, g in zip(effect.param_names, grad[0]):
        assert g > 0, f"no gradient for {name}"


def test_constant_mask_equals_global(effect, photo) -> None:
    base = effect.preset("portrait")[None]
    with torch.no_grad():
        global_out = effect(photo, base)
        full_size = effect(photo, base[:, :, None, None].expand(-1, -1, *photo.shape[-2:]))
        upsampled = effect(photo, base[:, :, None, None].expand(-1, -1, 16, 16))
    assert torch.equal(global_out, full_size)
    # upsampling a constant mask rounds some values by an ulp, which the line threshold magnifies
    assert torch.allclose(global_out, upsampled, atol=1e-4)


def test_quarter_resolution_mask_equals_upsampled_mask(effect, photo) -> None:
    torch.manual_seed(1)
    mask = effect.preset("portrait")[None, :, None, None] + 0.2 * (torch.rand(1, len(effect.param_specs), 48, 48) - 0.5)
    upsampled = F.interpolate(mask, size=photo.shape[-2:], mode="bilinear", align_corners=False)
    with torch.no_grad():
        assert torch.allclose(effect(photo, mask), effect(photo, upsampled), atol=1e-5)


def test_local_mask_changes_output_locally(effect, photo) -> None:
    base = effect.preset("portrait")[None, :, None, None].expand(-1, -1, 192, 192).clone()
    edited = base.clone()
    edited[:, effect.param_names.index("blackness"), :, :96] = 0.5
    with torch.no_grad():
        before, after = effect(photo, base), effect(photo, edited)
    changed = (before - after).abs()
    assert changed[..., :90].mean() > 0.02
    assert changed[..., 110:].max() == 0


def test_same_look_at_every_resolution(effect, astronaut) -> None:
    params = effect.preset("portrait")[None]
    with torch.no_grad():
        small = effect(F.interpolate(astronaut, size=(256, 256), mode="area"), params)
        large = effect(astronaut, params)
    large_down = F.interpolate(large, size=(256, 256), mode="area")
    assert (small.mean() - large_down.mean()).abs() < 0.03
    assert (small - large_down).abs().mean() < 0.12


def test_checkpointing_gives_the_same_values_and_gradients(photo) -> None:
    plain, checkpointed = wise.effects.create("xdog"), wise.effects.create("xdog", checkpoint=True)
    results = []
    for effect in (plain, checkpointed):
        params = effect.preset("portrait")[None].clone().requires_grad_()
        out = effect(photo, params)
        out.mean().backward()
        results.append((out.detach(), params.grad))
    assert torch.allclose(results[0][0], results[1][0])
    assert torch.allclose(results[0][1], results[1][1], rtol=1e-4, atol=1e-6)


def test_kernel_size_trades_quality(photo) -> None:
    params = wise.effects.create("xdog").params_from_dict({"details": 0.0})[None]
    with torch.no_grad():
        outputs = [wise.effects.create("xdog", kernel_size=d)(photo, params) for d in (1, 3)]
    assert (outputs[0] - outputs[1]).abs().mean() > 0
    with pytest.raises(WiseError, match="kernel size"):
        wise.effects.create("xdog", kernel_size=0)


def test_bad_inputs(effect, photo) -> None:
    params = effect.preset("portrait")[None]
    with pytest.raises(WiseError, match=r"\(B, 3, H, W\)"):
        effect(photo[0], params)
    with pytest.raises(WiseError, match="parameters must have shape"):
        effect(photo, params[:, :5])
    with pytest.raises(WiseError, match="float"):
        effect((photo * 255).to(torch.uint8), params)


def test_shading_adds_tones_and_a_gradient_where_lines_are_white(effect, photo) -> None:
    plain = effect.preset("portrait")[None]
    assert effect.params_to_dict(plain[0])["shading"] == pytest.approx(0.0)
    with torch.no_grad():
        lines = effect(photo, plain)
        shaded = effect(photo, effect.params_from_dict({"shading": 1.0}, preset="portrait")[None])
    assert (shaded <= lines + 1e-6).all(), "shading only darkens"
    white = lines[:, :1] > 0.99
    assert white.float().mean() > 0.3
    # dark regions of the photo turn grey or black where the lines alone are white
    assert float((lines - shaded)[:, :1][white].mean()) > 0.1
    assert float(shaded.std()) > float(lines.std()) * 0.5

    masks = plain[:, :, None, None].expand(-1, -1, *photo.shape[-2:]).clone().requires_grad_()
    effect(photo, masks).mean().backward()
    shading_gradient = masks.grad[0, [s.name for s in effect.param_specs].index("shading")]
    assert float(shading_gradient[white[0, 0]].abs().mean()) > 0, "no gradient to darken flat white areas"


def test_the_reference_values_render_as_authored(effect, photo) -> None:
    """Fidelity is a property of the pipeline: the reference's values, passed explicitly,
    render its look (the reference's sketch fills dark regions with black)."""
    assert effect.params_to_dict(effect.preset("portrait")) == pytest.approx(REFERENCE_PORTRAIT)
    reference_sketch = effect.params_from_dict(REFERENCE_SKETCH)
    assert effect.params_to_dict(reference_sketch) == pytest.approx(REFERENCE_SKETCH)
    with torch.no_grad():
        drawing = effect(photo, reference_sketch[None])
    assert float((drawing < 0.5).float().mean()) > 0.2


def test_sketch_has_no_filled_black_regions(effect, astronaut) -> None:
    with torch.no_grad():
        drawing = effect(astronaut, effect.preset("sketch")[None])[:, :1]
    dark = (drawing < 0.5).float()
    assert float(dark.mean()) < 0.25
    assert float(F.avg_pool2d(dark, 32, stride=16).max()) < 0.9
    assert float(((drawing > 0.05) & (drawing < 0.95)).float().mean()) > 0.1  # light pencil tones
