"""Seeded procedural noise and paper texture: determinism, tiles, resolution, range."""

import pytest
import torch
import torch.nn.functional as F

from tests.filters.paths import kernels
from wise.errors import WiseError
from wise.filters import noise
from wise.filters.noise import paper_texture, value_noise

FBM = dict(cell_size=6.0, octaves=3)


def _like(h: int, w: int, b: int = 1, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    return torch.zeros(b, 3, h, w, dtype=dtype)


def _correlation(a: torch.Tensor, b: torch.Tensor) -> float:
    a, b = a.flatten() - a.mean(), b.flatten() - b.mean()
    return float((a * b).sum() / (a.norm() * b.norm()))


def test_same_seed_and_position_give_identical_values() -> None:
    like = _like(48, 40)
    made = [value_noise(like, seed=7, scale=0.5, **FBM), paper_texture(like, seed=7, scale=0.5)]
    noise._remembered.clear()  # made again, not copied
    assert torch.equal(made[0], value_noise(like, seed=7, scale=0.5, **FBM))
    assert torch.equal(made[1], paper_texture(like, seed=7, scale=0.5))
    assert made[1].shape == (1, 1, 48, 40)


@pytest.mark.parametrize("path", ["torch", "fused"])
def test_a_texture_asked_for_again_is_a_copy_of_the_first(path: str, monkeypatch: pytest.MonkeyPatch) -> None:
    made = []
    for name in ("_fbm", "_fused_noise"):
        original = getattr(noise, name)
        monkeypatch.setattr(noise, name, lambda *a, _original=original, **k: made.append(1) or _original(*a, **k))
    noise._remembered.clear()
    like = _like(36, 52, b=2)
    with kernels(path):
        first = value_noise(like, seed=3, scale=1.0, **FBM)
        count = len(made)
        first_paper = paper_texture(like, seed=3, scale=1.0)
        count_paper = len(made)
        first.mul_(0.0)  # a caller's copy: changing it changes no later result
        again = value_noise(like, seed=3, scale=1.0, **FBM)
        assert paper_texture(like, seed=3, scale=1.0).equal(first_paper)
        assert len(made) == count_paper  # nothing made again
        noise._remembered.clear()
        assert again.equal(value_noise(like, seed=3, scale=1.0, **FBM)) and again.abs().sum() > 0
    assert count >= 1


def test_textures_of_other_arguments_are_not_confused() -> None:
    like = _like(40, 40)
    base = value_noise(like, seed=1, scale=1.0, **FBM)
    others = [
        value_noise(like, seed=2, scale=1.0, **FBM),
        value_noise(like, seed=1, scale=1.5, **FBM),
        value_noise(like, seed=1, scale=1.0, origin=(8, 0), **FBM),
        value_noise(like, seed=1, scale=1.0, cell_size=5.0, octaves=3),
        value_noise(like, seed=1, scale=1.0, cell_size=6.0, octaves=2),
        paper_texture(like, seed=1, scale=1.0),
    ]
    for other in others:
        assert not torch.equal(other, base)
    wider = value_noise(_like(40, 48), seed=1, scale=1.0, **FBM)  # the same pattern, more of it
    assert wider.shape[-1] == 48 and torch.equal(wider[..., :40], base)
    assert value_noise(_like(40, 40, dtype=torch.float64), seed=1, scale=1.0, **FBM).dtype == torch.float64


def test_large_textures_are_made_each_time(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(noise, "REMEMBERED_MAX_PIXELS", 100)
    noise._remembered.clear()
    value_noise(_like(12, 12), seed=1, scale=1.0, **FBM)
    assert not noise._remembered


def test_seeds_give_independent_noise() -> None:
    like = _like(64, 64)
    a = value_noise(like, seed=1, **FBM, scale=1.0)
    b = value_noise(like, seed=2, **FBM, scale=1.0)
    assert (a - b).abs().mean() > 0.05
    assert abs(_correlation(a, b)) < 0.3
    pa, pb = paper_texture(like, seed=1, scale=1.0), paper_texture(like, seed=2, scale=1.0)
    assert abs(_correlation(pa, pb)) < 0.3


@pytest.mark.parametrize("kind", ["value", "paper"])
def test_tiles_match_the_full_render(kind: str) -> None:
    scale = 0.4

    def render(h: int, w: int, origin: tuple[int, int]) -> torch.Tensor:
        if kind == "value":
            return value_noise(_like(h, w), origin=origin, scale=scale, seed=3, **FBM)
        return paper_texture(_like(h, w), seed=3, origin=origin, scale=scale)

    full = render(70, 90, (0, 0))
    for top, left in ((0, 0), (17, 23), (41, 60)):
        tile = render(25, 30, (top, left))
        assert torch.allclose(tile, full[..., top : top + 25, left : left + 30], atol=1e-6, rtol=0.0)
    # origins may also lie outside, e.g. left of the image
    shifted = render(20, 30, (5, -10))
    assert torch.allclose(shifted[..., 10:], full[..., 5:25, :20], atol=1e-6, rtol=0.0)


@pytest.mark.parametrize(
    "render",
    [
        lambda like: value_noise(like, 5.0, seed=4, scale=1.0),
        lambda like: value_noise(like, seed=4, scale=1.0, **FBM),
        lambda like: paper_texture(like, seed=4, scale=1.0),
    ],
)
def test_range_and_mean(render) -> None:
    noise = render(_like(256, 256))
    assert noise.min() >= 0.0 and noise.max() <= 1.0
    assert abs(float(noise.mean()) - 0.5) < 0.05
    assert noise.std() > 0.08


def test_batch_dtype_and_shape_follow_like() -> None:
    noise = value_noise(_like(20, 30, b=3, dtype=torch.float64), 4.0, scale=1.0)
    assert noise.shape == (3, 1, 20, 30) and noise.dtype == torch.float64
    assert torch.equal(noise[0], noise[2])
    single = value_noise(_like(20, 30, dtype=torch.float32), 4.0, scale=1.0)
    assert torch.allclose(single[0].double(), noise[0], atol=1e-6)
    assert not noise.requires_grad


@pytest.mark.parametrize("kind", ["value", "paper"])
def test_double_resolution_is_the_same_pattern(kind: str) -> None:
    def render(size: int, scale: float) -> torch.Tensor:
        like = _like(size, size)
        if kind == "value":
            return value_noise(like, seed=5, scale=scale, **FBM)
        return paper_texture(like, seed=5, scale=scale)

    low = render(96, 0.75)
    high = render(192, 1.5)
    assert _correlation(F.avg_pool2d(high, 2), low) > 0.98
    # the default scale follows the image size
    assert torch.equal(value_noise(_like(96, 128), 6.0), value_noise(_like(96, 128), 6.0, scale=96 / 512))


def test_smooth_with_the_given_cell_size() -> None:
    like = _like(128, 128)
    coarse = value_noise(like, 16.0, scale=1.0)
    fine = value_noise(like, 4.0, scale=1.0)

    def roughness(x: torch.Tensor) -> float:
        return float((x[..., :, 1:] - x[..., :, :-1]).abs().mean())

    assert roughness(coarse) < 0.5 * roughness(fine)
    assert roughness(coarse) < 0.05
    more_octaves = value_noise(like, 16.0, octaves=4, scale=1.0)
    # finer octaves add detail: more slope relative to the overall contrast
    assert roughness(more_octaves) / float(more_octaves.std()) > 1.5 * roughness(coarse) / float(coarse.std())


def test_bad_arguments() -> None:
    like = _like(8, 8)
    with pytest.raises(WiseError):
        value_noise(like, 0.0)
    with pytest.raises(WiseError):
        value_noise(like, 4.0, octaves=0)
    with pytest.raises(WiseError):
        paper_texture(like, grain=-1.0)
    with pytest.raises(WiseError):
        value_noise(torch.zeros(8, 8), 4.0)
