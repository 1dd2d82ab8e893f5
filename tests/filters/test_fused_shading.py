"""The fused bump mapping with Phong lighting against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.shading import bump_phong

pytestmark = needs_kernels

LIGHT = (0.0, -1.0, 1.5)


def test_bump_phong_with_maps_matches_torch_in_float64() -> None:
    color = rand(2, 3, 13, 17)
    height = rand(2, 1, 13, 17, seed=1, high=3.0)
    # steep relief: some normals face away from the light, some pixels clamp at 0 and 1
    strength = rand(2, 1, 13, 17, low=0.2, high=3.0, seed=2)
    ambient = rand(2, 1, 13, 17, low=0.2, high=0.6, seed=3)
    diffuse = rand(2, 1, 13, 17, low=0.3, high=1.0, seed=4)
    specular = rand(2, 1, 13, 17, high=1.0, seed=5)
    shininess = rand(2, 1, 13, 17, low=2.0, high=40.0, seed=6)

    def fn(color, height, strength, ambient, diffuse, specular, shininess):
        return bump_phong(color, height, strength, LIGHT, ambient, diffuse, specular, shininess, scale=2.0)

    assert_paths_agree(fn, [color, height, strength, ambient, diffuse, specular, shininess], rtol=1e-9)


def test_bump_phong_with_floats_and_a_broadcast_height_matches_torch() -> None:
    color = rand(2, 3, 9, 11)
    height = rand(1, 1, 9, 11, seed=1, high=2.0)
    assert_paths_agree(lambda c, h: bump_phong(c, h, 1.3), [color, height], rtol=1e-9)


def test_bump_phong_with_per_picture_parameters_matches_torch() -> None:
    color = rand(2, 3, 8, 10)
    height = rand(2, 1, 8, 10, seed=1)
    strength = rand(2, low=0.5, high=2.0, seed=2)
    specular = rand(2, low=0.1, high=0.6, seed=3)
    shininess = rand(2, low=4.0, high=20.0, seed=4)
    fn = lambda c, h, k, s, n: bump_phong(c, h, k, specular=s, shininess=n, scale=1.0)  # noqa: E731
    assert_paths_agree(fn, [color, height, strength, specular, shininess], rtol=1e-9)


@pytest.mark.parametrize("size", [(1, 6), (5, 1), (1, 1)])
def test_bump_phong_on_a_single_row_or_column_matches_torch(size: tuple[int, int]) -> None:
    color = rand(2, 3, *size)
    height = rand(2, 1, *size, seed=1, high=3.0)
    strength = rand(2, 1, *size, low=0.5, high=2.0, seed=2)
    assert_paths_agree(lambda c, h, k: bump_phong(c, h, k, scale=1.0), [color, height, strength], rtol=1e-9)


def test_bump_phong_matches_torch_in_float32() -> None:
    color = rand(2, 3, 40, 31).detach().float().requires_grad_()
    height = rand(2, 1, 40, 31, seed=1, high=2.0).detach().float().requires_grad_()
    strength = rand(2, 1, 40, 31, low=0.5, high=2.0, seed=2).detach().float().requires_grad_()
    shininess = rand(2, low=4.0, high=20.0, seed=3).detach().float().requires_grad_()
    fn = lambda c, h, k, n: bump_phong(c, h, k, LIGHT, specular=0.3, shininess=n, scale=1.0)  # noqa: E731
    assert_paths_agree(fn, [color, height, strength, shininess], rtol=1e-5)


def test_bump_phong_gradcheck() -> None:
    color = rand(2, 2, 5, 6, low=0.2, high=0.6)
    height = rand(2, 1, 5, 6, seed=1)
    strength = rand(2, 1, 5, 6, low=0.5, high=1.5, seed=2)
    ambient = rand(2, low=0.3, high=0.5, seed=3)
    shininess = rand(2, 1, 5, 6, low=2.0, high=10.0, seed=4)
    with kernels("fused"):
        assert gradcheck(
            lambda c, h, k, a, n: bump_phong(c, h, k, LIGHT, a, 0.4, 0.3, n, scale=1.0),
            (color, height, strength, ambient, shininess),
            eps=1e-6,
            atol=1e-6,
        )


def test_the_fused_bump_phong_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import shading as fused_shading

    calls = []
    original = fused_shading._shade_forward
    monkeypatch.setattr(fused_shading, "_shade_forward", lambda *a: calls.append(1) or original(*a))
    color, height = torch.rand(1, 3, 8, 8), torch.rand(1, 1, 8, 8)
    for path in ("fused", "torch"):
        with kernels(path):
            bump_phong(color, height)
    assert calls == [1]
