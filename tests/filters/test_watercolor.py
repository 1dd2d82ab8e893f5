"""Watercolor filters: gradients against finite differences and behaviour on known images."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand, unit, unit_field
from wise.errors import WiseError
from wise.filters.watercolor import (
    edge_darkening,
    feature_accents,
    gaps_overlaps,
    pigment_density,
    wash_lightness,
    wet_in_wet,
    wobble,
)
from wise.filters import adjust_color


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    """Tiny tensors: on a busy 2-core machine, thread hand-offs cost far more than the work."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _check(fn, *inputs: torch.Tensor) -> None:
    assert gradcheck(fn, inputs, eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


def _field(x: float, y: float, h: int, w: int) -> torch.Tensor:
    return torch.tensor([x, y]).view(1, 2, 1, 1).expand(1, 2, h, w).contiguous()


def _step(h: int = 16, w: int = 40, at: int = 20, left: float = 0.8, right: float = 0.3) -> torch.Tensor:
    """A vertical edge: ``left`` for columns < ``at``, ``right`` from there on, three channels."""
    image = torch.full((1, 3, h, w), left)
    image[..., at:] = right
    return image


# --- gradients ---------------------------------------------------------------------------


def test_pigment_density_gradients() -> None:
    image = rand(2, 3, 5, 6, low=0.1, high=0.9)
    _check(pigment_density, image, rand(2, 1, 5, 6, low=0.5, high=1.5, seed=2))
    _check(pigment_density, image, rand(2, low=0.5, high=1.5, seed=3))


def test_edge_darkening_gradients() -> None:
    image = rand(2, 3, 7, 8, low=0.1, high=0.9)
    amount = rand(2, low=0.5, high=2.0, seed=2)
    sigma = rand(2, 1, 7, 8, low=0.7, high=1.2, seed=3)
    _check(lambda i, a, s: edge_darkening(i, a, s, scale=1.0), image, amount, sigma)


def test_wobble_gradients() -> None:
    image = rand(2, 3, 7, 8)
    texture = rand(2, 1, 7, 8, seed=2)
    amount = rand(2, 1, 7, 8, low=0.5, high=1.5, seed=3)
    _check(lambda i, t, a: wobble(i, t, a, scale=1.0), image, texture, amount)


@pytest.mark.parametrize("low, high", [(0.2, 0.9), (-0.9, -0.2)])
def test_gaps_overlaps_gradients(low: float, high: float) -> None:
    image = rand(2, 3, 7, 8, low=0.1, high=0.9)
    edges = rand(2, 1, 7, 8, seed=2)
    direction = unit_field(2, 7, 8, seed=3)
    amount = rand(2, low=low, high=high, seed=4)
    noise = rand(2, 1, 7, 8, seed=5)
    _check(
        lambda i, e, d, a, n: gaps_overlaps(i, e, unit(d), a, n, scale=1.3),
        image,
        edges,
        direction,
        amount,
        noise,
    )


def test_wet_in_wet_gradients() -> None:
    image = rand(2, 3, 7, 8)
    direction = unit_field(2, 7, 8, seed=2)
    edges = rand(2, 1, 7, 8, seed=3)
    amount = rand(2, low=1.5, high=2.5, seed=4)
    noise = rand(2, 1, 7, 8, seed=5)
    _check(
        lambda i, d, e, a, n: wet_in_wet(i, unit(d), e, a, n, scale=1.0, samples=3),
        image,
        direction,
        edges,
        amount,
        noise,
    )


# --- behaviour ---------------------------------------------------------------------------


def test_amount_zero_is_the_identity() -> None:
    image = torch.rand(2, 3, 20, 24, generator=torch.Generator().manual_seed(0))
    texture = torch.rand(2, 1, 20, 24)
    direction = _field(0.6, 0.8, 20, 24)
    edges, noise = torch.rand(2, 1, 20, 24), torch.rand(2, 1, 20, 24)
    for out in (
        wobble(image, texture, 0.0, scale=1.0),
        gaps_overlaps(image, edges, direction, 0.0, noise, scale=1.0),
        wet_in_wet(image, direction, edges, 0.0, noise, scale=1.0),
        edge_darkening(image, 0.0, scale=1.0),
    ):
        assert torch.allclose(out, image, atol=1e-6)


def test_pigment_density() -> None:
    colours = torch.linspace(0.0, 1.0, 11).view(1, 1, 1, 11).expand(1, 3, 2, 11)
    inside = (colours > 0) & (colours < 1)
    assert torch.equal(pigment_density(colours, 1.0), colours)
    darker, lighter = pigment_density(colours, 1.5), pigment_density(colours, 0.5)
    assert (darker[inside] < colours[inside]).all()
    assert (lighter[inside] > colours[inside]).all()
    for out in (darker, lighter):
        assert torch.equal(out[..., -1], colours[..., -1])  # white stays white
        assert torch.equal(out[..., 0], colours[..., 0])  # and black black
    per_pixel = pigment_density(colours, torch.full((1, 1, 2, 11), 1.5))
    assert torch.allclose(per_pixel, darker)
    assert (pigment_density(colours, 2.0) >= 0).all() and (pigment_density(colours, 0.0) <= 1).all()


@pytest.mark.parametrize("scale, shift", [(1.0, 3.0), (1.0, 2.5), (2.0, 6.0)])
def test_wobble_moves_a_step_by_the_texture_slope(scale: float, shift: float) -> None:
    image = _step(8, 48, at=24, left=0.0, right=1.0)
    # a linear ramp whose slope is 0.01 per reference pixel at every resolution
    slope = 0.01
    columns = torch.arange(48, dtype=torch.float32) * (slope / scale)
    texture = columns.view(1, 1, 1, 48).expand(1, 1, 8, 48)
    amount = shift / scale / slope  # displacement ``shift`` pixels, ``shift / scale`` reference pixels
    out = wobble(image, texture, amount, scale=scale)[0, 0, 4]
    # out(x) = image(x + shift): the step moves left by ``shift`` pixels
    expected = (torch.arange(48, dtype=torch.float32) + shift - 23.0).clamp(0.0, 1.0)
    assert torch.allclose(out[2:-8], expected[2:-8], atol=1e-5)


def test_bad_maps_are_rejected() -> None:
    with pytest.raises(WiseError):
        wobble(_step(), torch.rand(1, 2, 16, 40), 1.0)
    with pytest.raises(WiseError):
        wobble(_step(), torch.rand(1, 1, 8, 40), 1.0)
    with pytest.raises(WiseError):
        wet_in_wet(_step(), _field(1.0, 0.0, 16, 40), torch.rand(1, 1, 8, 40), 1.0, 0.5)
    with pytest.raises(WiseError):
        wet_in_wet(_step(), _field(1.0, 0.0, 16, 40), 1.0, 1.0, 0.5, samples=0)


def test_gaps_lighten_and_overlaps_darken_at_the_edge() -> None:
    image = _step()
    edges = torch.zeros(1, 1, 16, 40)
    edges[..., 18:22] = 1.0
    direction = _field(1.0, 0.0, 16, 40)
    noise = torch.ones(1, 1, 16, 40)
    gaps = gaps_overlaps(image, edges, direction, -1.0, noise, scale=1.0)
    overlaps = gaps_overlaps(image, edges, direction, 0.8, noise, scale=1.0)
    band, outside = edges[0, 0, 0] > 0, edges[0, 0, 0] == 0
    assert torch.allclose(gaps[..., band], torch.ones(()))  # full gaps show the white paper
    assert (overlaps[..., band] < image[..., band] - 0.02).all()
    # the overlap on the light side takes on the dark wash: about 0.8 * 0.3, blended by 0.8
    assert overlaps[0, 0, 8, 19] == pytest.approx(0.8 + 0.8 * (0.8 * 0.3 - 0.8), abs=0.01)
    for out in (gaps, overlaps):
        assert torch.equal(out[..., outside], image[..., outside])
    # the noise breaks the band up
    holes = noise.clone()
    holes[..., ::2, :] = 0.0
    broken = gaps_overlaps(image, edges, direction, -1.0, holes, scale=1.0)
    assert torch.equal(broken[..., ::2, :], image[..., ::2, :])
    # the direction's sign does not matter
    flipped = gaps_overlaps(image, edges, -direction, 0.8, noise, scale=1.0)
    assert torch.allclose(flipped, overlaps, atol=1e-6)


def test_wet_in_wet_bleeds_only_at_edges() -> None:
    image = _step(16, 60, at=30)
    direction = _field(1.0, 0.0, 16, 60)
    edges = torch.zeros(1, 1, 16, 60)
    edges[..., 24:36] = 1.0
    noise = torch.full((1, 1, 16, 60), 0.5)
    out = wet_in_wet(image, direction, edges, 4.0, noise, scale=1.0)
    assert torch.equal(out[..., :24], image[..., :24]) and torch.equal(out[..., 36:], image[..., 36:])
    assert (out[..., 29] < image[..., 29] - 0.05).all()  # the dark wash bleeds into the light one
    assert (out[..., 30] > image[..., 30] + 0.05).all()
    # where the paint is wet everywhere, flat areas beyond the reach stay unchanged
    wet = wet_in_wet(image, direction, 1.0, 4.0, noise, scale=1.0)
    assert torch.allclose(wet[..., :24], image[..., :24], atol=1e-6)
    assert torch.allclose(wet[..., 36:], image[..., 36:], atol=1e-6)


def test_wet_in_wet_follows_direction_and_noise() -> None:
    image = _step(16, 60, at=30)
    noise = torch.zeros(1, 1, 16, 60)
    noise[..., 8:, :] = 1.0
    across = wet_in_wet(image, _field(1.0, 0.0, 16, 60), 1.0, 4.0, noise, scale=1.0)
    along = wet_in_wet(image, _field(0.0, 1.0, 16, 60), 1.0, 4.0, noise, scale=1.0)
    assert torch.allclose(along, image, atol=1e-6)  # blurring along the edge changes nothing
    changed = (across - image).abs()[0, 0]
    # noise 1 reaches 1.5 x the amount, noise 0 half of it: the bleeding is irregular
    assert changed[12, 26] > 0.01 and changed[2, 26] < 1e-6


def test_wet_in_wet_scales_with_resolution() -> None:
    def bled_columns(size: int) -> int:
        image = _step(4, size, at=size // 2)
        out = wet_in_wet(image, _field(1.0, 0.0, 4, size), 1.0, 6.0, 0.5, scale=size / 64)
        return int(((out - image).abs()[0, 0, 2] > 1e-4).sum())

    assert bled_columns(128) == pytest.approx(2 * bled_columns(64), abs=2)


def test_edge_darkening_darkens_edges_only() -> None:
    image = _step(16, 40)
    out = edge_darkening(image, 2.0, scale=1.0)
    assert torch.allclose(out[..., :12], image[..., :12], atol=1e-6)
    assert torch.allclose(out[..., 28:], image[..., 28:], atol=1e-6)
    assert (out[..., 18:22] < image[..., 18:22]).all()
    stronger = edge_darkening(image, 4.0, scale=1.0)
    assert (stronger[..., 18:22] < out[..., 18:22]).all()


def test_edge_darkening_is_resolution_independent() -> None:
    small = _step(16, 40)
    large = torch.nn.functional.interpolate(small, scale_factor=2, mode="nearest")
    darkest_small = float((edge_darkening(small, 2.0, sigma=2.0, scale=1.0) - small).min())
    darkest_large = float((edge_darkening(large, 2.0, sigma=2.0, scale=2.0) - large).min())
    assert darkest_large == pytest.approx(darkest_small, rel=0.15)


def test_feature_accents_give_back_a_small_dark_feature_the_washes_lost() -> None:
    photo = torch.full((1, 3, 64, 64), 0.7)
    photo[..., 30:34, 30:34] = 0.1  # an eye
    washes = torch.full_like(photo, 0.75)  # the eye wiped out, the tone lifted a little
    out = feature_accents(washes, photo, 1.0, scale=1.0)
    assert out[0, 0, 31, 31] < 0.3  # the feature is dark again
    assert torch.allclose(out[..., :16, :16], washes[..., :16, :16])  # the lifted tone is kept
    assert torch.equal(feature_accents(washes, photo, 0.0, scale=1.0), washes)


def test_feature_accents_leave_a_large_dark_area_and_the_hue() -> None:
    photo = torch.full((1, 3, 64, 64), 0.8)
    photo[..., :, :32] = 0.1  # hair beside skin
    washes = photo * torch.tensor([1.0, 0.8, 0.6]).view(1, 3, 1, 1)
    out = feature_accents(washes, photo, 1.0, scale=1.0)
    assert torch.allclose(out, washes, atol=1e-6)
    tinted = torch.full_like(photo, 0.7) * torch.tensor([1.0, 0.8, 0.6]).view(1, 3, 1, 1)
    dot = torch.full_like(photo, 0.7)
    dot[..., 30:34, 30:34] = 0.1
    accented = feature_accents(tinted, dot, 1.0, scale=1.0)[0, :, 31, 31]
    assert torch.allclose(accented / accented[0], torch.tensor([1.0, 0.8, 0.6]), atol=1e-5)


def test_feature_accents_gradcheck() -> None:
    photo = torch.rand(1, 3, 12, 12, dtype=torch.float64) * 0.5
    washes = (torch.rand(1, 3, 12, 12, dtype=torch.float64) * 0.3 + 0.6).requires_grad_()
    strength = torch.full((1, 1, 12, 12), 0.7, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda w, s: feature_accents(w, photo, s, scale=1.0), (washes, strength), nondet_tol=1e-12
    )


def test_a_strong_rim_darkens_to_at_most_the_colour_squared() -> None:
    """Pigment pools into a darker rim, never into black specks (a density beyond 2 turns
    colours negative, clipped to black)."""
    image = torch.full((1, 3, 32, 32), 0.55)
    image[..., :, :16] = 0.08  # dark hair beside skin
    out = edge_darkening(image, 3.0, scale=1.0)
    assert bool((out >= image * image - 1e-6).all())
    assert float(out[0, 0, 16, 16]) < 0.45  # still a visible rim on the skin's side


def test_wash_lightness_keeps_the_hue_of_highlights_that_a_brightness_clips() -> None:
    # a skin's highlight and the skin around it, as in the astronaut photo
    skin = torch.tensor([[0.97, 0.85, 0.81], [0.83, 0.70, 0.62]]).reshape(1, 2, 3).permute(0, 2, 1)[..., None]
    clipped = adjust_color(skin, brightness=0.08)
    assert float(clipped[0, 0, 0, 0]) == 1.0  # the highlight's red clips: it turns whiter than the skin
    for amount in (0.08, 0.3, 1.0):
        lighter = wash_lightness(skin, amount)
        assert float(lighter.max()) < 1.0 and bool((lighter > skin).all())
        # every colour's distance to white shrinks by one factor: the hue and the skin's ratios stay
        ratio = (1.0 - lighter) / (1.0 - skin)
        assert torch.allclose(ratio, ratio[0, 0, 0, 0].expand_as(ratio), atol=1e-6)
    mid_grey = torch.full((1, 3, 1, 1), 0.5)
    assert float(wash_lightness(mid_grey, 0.02)[0, 0]) == pytest.approx(0.52, abs=1e-3)  # as a brightness of 0.02
    darker = wash_lightness(skin, -0.3)
    assert torch.allclose(darker / skin, (darker / skin)[0, 0, 0, 0].expand_as(skin), atol=1e-6)
    assert bool((darker < skin).all()) and torch.equal(wash_lightness(skin, 0.0), skin)


def test_wash_lightness_gradients() -> None:
    image = rand(1, 3, 4, 5, low=0.05, high=0.95)
    amount = (torch.rand(1, 1, 4, 5, dtype=torch.float64) - 0.5).requires_grad_(True)
    _check(wash_lightness, image, amount)
