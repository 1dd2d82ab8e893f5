import pytest
import torch
import torch.nn.functional as F

import wise
from wise.effects import create
from wise.metrics import ssim
from wise.params import resize_masks
from wise.render import enlarged, masks_for_box, reduced, render, rerender, tile_shape, tiles


def test_tiles_cover_the_picture_once() -> None:
    covered = torch.zeros(300, 250, dtype=torch.int32)
    for t in tiles(300, 250, 96, 10):
        covered[t.y0 : t.y1, t.x0 : t.x1] += 1
        assert t.py0 <= t.y0 and t.py1 >= t.y1 and t.px0 <= t.x0 and t.px1 >= t.x1
    assert torch.equal(covered, torch.ones_like(covered))


@pytest.mark.parametrize(("height", "width", "halo"), [(4096, 4096, 368), (3000, 5000, 176), (16000, 9000, 320)])
def test_tile_layout_respects_the_pixel_budget(height: int, width: int, halo: int) -> None:
    budget = 9_000_000
    shape = tile_shape(height, width, halo, budget)
    layout = list(tiles(height, width, shape, halo))
    padded = [(t.py1 - t.py0) * (t.px1 - t.px0) for t in layout]
    assert max(padded) <= budget
    assert sum((t.y1 - t.y0) * (t.x1 - t.x0) for t in layout) == height * width
    square = list(tiles(height, width, 2048, halo))
    assert sum(padded) <= sum((t.py1 - t.py0) * (t.px1 - t.px0) for t in square)


def test_mask_crops_match_resizing_the_whole_mask() -> None:
    masks = torch.rand(2, 5, 17, 23)
    whole = resize_masks(masks, (301, 203))
    crop = masks_for_box(masks, (301, 203), (40, 170, 11, 190))
    assert torch.allclose(crop, whole[..., 40:170, 11:190], atol=1e-5)


@pytest.mark.parametrize("name", wise.effects.available())
@pytest.mark.parametrize("local", [False, True])
def test_tiled_rendering_has_no_seams(name: str, local: bool, astronaut: torch.Tensor) -> None:
    image = F.interpolate(astronaut, size=(256, 192), mode="area")
    effect = wise.effects.create(name)
    params = effect.preset(next(iter(effect.presets)))[None]
    if local:
        torch.manual_seed(0)
        params = params[:, :, None, None] + 0.3 * (torch.rand(1, params.shape[1], 12, 9) - 0.5)
    with torch.no_grad():
        whole = effect(image, params)
    tiled = render(effect, image, params, tile=80, at_reference=False)
    difference = (tiled - whole).abs()
    # identical up to rounding; a hard threshold may flip an isolated pixel
    assert difference.mean() < 1e-3
    assert (difference > 0.05).float().mean() < 1e-3


def test_a_guide_made_in_tiles_equals_the_whole_pictures(astronaut: torch.Tensor, monkeypatch) -> None:
    import wise.render as R

    image = F.interpolate(astronaut, size=(136, 200), mode="area")
    effect = wise.effects.create("oilpaint")
    torch.manual_seed(0)
    params = effect.default_params()[None, :, None, None] + 0.2 * (torch.rand(1, len(effect.param_specs), 5, 7) - 0.5)
    with torch.no_grad():
        whole = effect.guide(image, params)
        monkeypatch.setattr(R, "tile_shape", lambda height, width, halo, budget: (64, 64))
        tiled = R._guide(effect, image, params, min(image.shape[-2:]) / 512, image.device)
    assert tiled.shape == (1, effect.guide_channels, 136, 200)
    difference = (tiled - whole).abs() / float(whole.abs().max())
    # equal up to float32 rounding, which the deviator's division by a weak anisotropy magnifies
    assert float(difference.mean()) < 1e-5
    assert float(difference.max()) < 1e-3


def test_a_large_pictures_guide_is_made_at_a_reduced_scale(astronaut: torch.Tensor, monkeypatch) -> None:
    """Above GUIDE_MAX_SCALE the flow comes from a reduced copy (its halo at 4096² would be
    thousands of pixels); it must point the strokes the same way as the full-size guide."""
    import wise.render as R
    from wise.filters import edge_tangent_flow

    image = F.interpolate(astronaut, size=(1024, 1024), mode="bicubic", align_corners=False).clamp(0, 1)
    effect = wise.effects.create("oilpaint")
    params = effect.preset("impasto")[None]
    monkeypatch.setattr(R, "GUIDE_MAX_SCALE", 1.0)
    with torch.no_grad():
        full = effect.guide(image, params)
        made = R._guide(effect, image, params, 2.0, image.device)
    assert made.shape == full.shape
    agreement = (edge_tangent_flow(made) * edge_tangent_flow(full)).sum(dim=1).square() * 2 - 1  # cos 2Δθ
    assert float(agreement.mean()) > 0.97, float(agreement.mean())  # 0.99; a copy at 1/8 scale: 0.71


def test_an_effect_with_a_guide_reads_less_around_its_tiles() -> None:
    effect = wise.effects.create("oilpaint")
    assert effect.halo(8.0) < effect.guide_halo(8.0) / 2


@pytest.mark.parametrize("name", wise.effects.available())
def test_rerendering_a_painted_region_equals_a_whole_render(name: str, astronaut: torch.Tensor) -> None:
    from wise.render import rerender

    image = F.interpolate(astronaut, size=(256, 320), mode="area")
    effect = wise.effects.create(name)
    before = effect.preset(next(iter(effect.presets)))[None, :, None, None].expand(1, -1, 128, 160).clone()
    after = before.clone()
    after[0, 0, 60:70, 20:34] += 0.3  # a stroke on the first parameter
    with torch.no_grad():
        rendered = render(effect, image, before, at_reference=False)
        whole = render(effect, image, after, at_reference=False)
    sizes = []
    original = effect.forward
    effect.forward = lambda crop, *a, **k: sizes.append(crop.shape[-2:]) or original(crop, *a, **k)
    updated = rerender(effect, image, after, before, rendered, at_reference=False)
    difference = (updated - whole).abs()
    assert difference.mean() < 1e-4
    assert (difference > 0.05).float().mean() < 1e-3
    assert len(sizes) == 1
    if not effect.guide_channels:  # oil paint's flow reaches across this small picture: it is drawn whole
        assert sizes[0][0] * sizes[0][1] < 0.5 * 256 * 320  # only a crop was rendered
    assert torch.equal(rerender(effect, image, after, after, updated, at_reference=False), updated)  # nothing drawn


def test_a_small_picture_looks_like_the_reference_render_reduced(astronaut: torch.Tensor) -> None:
    """Below the reference size every structure scale would fall under a pixel (a sketch of a few
    dashes); a small picture is rendered at the reference scale and reduced instead."""
    effect = create("xdog").eval()
    params = effect.preset("sketch")[None]
    small = F.interpolate(astronaut, size=(256, 256), mode="bilinear", antialias=True)
    reference = F.interpolate(render(effect, astronaut, params), size=(256, 256), mode="bilinear", antialias=True)
    rendered = render(effect, small, params)
    assert rendered.shape == small.shape
    ink, reference_ink = float((rendered < 0.5).float().mean()), float((reference < 0.5).float().mean())
    assert ink >= 0.6 * reference_ink
    assert ssim(rendered, reference) >= 0.6
    with torch.no_grad():
        own_scale = effect(small, params)
    assert float((own_scale < 0.5).float().mean()) < 0.6 * reference_ink  # what the enlargement avoids


def test_a_picture_at_the_reference_size_renders_at_its_own_scale(astronaut: torch.Tensor) -> None:
    effect = create("cartoon").eval()
    params = effect.preset("classic")[None]
    with torch.no_grad():
        assert torch.equal(render(effect, astronaut, params), effect(astronaut, params))


def test_rerendering_a_small_picture_equals_its_render(astronaut_small: torch.Tensor) -> None:
    effect = create("cartoon").eval()
    before = effect.preset("classic")[None, :, None, None].expand(1, -1, 8, 8).clone()
    after = before.clone()
    after[..., 2:4, 2:4] = 0.9
    drawn = render(effect, astronaut_small, before)
    assert torch.equal(rerender(effect, astronaut_small, after, before, drawn), render(effect, astronaut_small, after))


@pytest.mark.parametrize(("name", "preset"), [("oilpaint", "impasto"), ("watercolor", "dry")])
def test_a_small_pictures_medium_is_enlarged_with_it(name: str, preset: str, astronaut: torch.Tensor) -> None:
    """Enlarged, rendered and reduced, a 256-pixel picture gets its bristles, relief, pigment and
    paper grain enlarged as much, so that reduced they keep the pixel size of a 512-pixel render's
    instead of half of it; the washes, lines and flow stay at the picture's scale."""
    effect = create(name).eval()
    params = effect.preset(preset)[None]
    small = F.interpolate(astronaut, size=(256, 256), mode="area")
    with torch.no_grad():
        rendered = render(effect, small, params)
        medium_enlarged = reduced(effect(enlarged(small), params, medium=2.0), (256, 256))
        medium_at_reference = reduced(effect(enlarged(small), params), (256, 256))
    assert torch.allclose(rendered, medium_enlarged, atol=1e-5)
    changed = (rendered - medium_at_reference).abs()
    assert float(changed.mean()) > 2e-3  # the texture moved
    assert ssim(rendered, medium_at_reference) > 0.8  # the picture did not
