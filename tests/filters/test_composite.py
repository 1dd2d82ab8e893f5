import pytest
import torch
from torch.autograd import gradcheck

from wise.errors import WiseError
from wise.filters.composite import BLEND_MODES, OPERATORS, blend, composite

DOUBLE = torch.float64
SOURCE = (0.8, 0.2, 0.4)
DESTINATION = (0.1, 0.6, 0.9)
ALPHA_S = 0.6
ALPHA_D = 0.5


def _pixel(rgb: tuple[float, float, float]) -> torch.Tensor:
    return torch.tensor(rgb, dtype=DOUBLE).view(1, 3, 1, 1)


def _rand(*shape: int, low: float = 0.0, high: float = 1.0, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(*shape, generator=g, dtype=DOUBLE) * (high - low) + low).requires_grad_()


# (F_A, F_B) of Porter & Duff 1984 at alpha_s = 0.6, alpha_d = 0.5
_FACTORS = {
    "clear": (0.0, 0.0),
    "source": (1.0, 0.0),
    "destination": (0.0, 1.0),
    "over": (1.0, 0.4),
    "destination_over": (0.5, 1.0),
    "in": (0.5, 0.0),
    "destination_in": (0.0, 0.6),
    "out": (0.5, 0.0),
    "destination_out": (0.0, 0.4),
    "atop": (0.5, 0.4),
    "destination_atop": (0.5, 0.6),
    "xor": (0.5, 0.4),
}


def test_every_operator_is_covered() -> None:
    assert set(_FACTORS) == set(OPERATORS)


@pytest.mark.parametrize("operator", OPERATORS)
def test_operator_known_values(operator: str) -> None:
    factor_s, factor_d = _FACTORS[operator]
    alpha = factor_s * ALPHA_S + factor_d * ALPHA_D
    premultiplied = [factor_s * ALPHA_S * s + factor_d * ALPHA_D * d for s, d in zip(SOURCE, DESTINATION)]
    expected = [p / alpha if alpha > 0 else 0.0 for p in premultiplied]
    colour, result_alpha = composite(_pixel(SOURCE), _pixel(DESTINATION), operator, ALPHA_S, ALPHA_D, return_alpha=True)
    assert torch.allclose(colour.flatten(), torch.tensor(expected, dtype=DOUBLE))
    assert result_alpha.item() == pytest.approx(alpha)


def test_opaque_limits() -> None:
    source, destination = _pixel(SOURCE), _pixel(DESTINATION)
    for operator in ("over", "source", "in", "atop"):
        assert torch.allclose(composite(source, destination, operator), source)
    for operator in ("destination", "destination_over", "destination_in", "destination_atop"):
        assert torch.allclose(composite(source, destination, operator), destination)
    for operator in ("clear", "out", "destination_out", "xor"):
        colour, alpha = composite(source, destination, operator, return_alpha=True)
        assert colour.abs().max() == 0.0 and alpha.item() == 0.0


def test_transparent_source_limits() -> None:
    source, destination = _pixel(SOURCE), _pixel(DESTINATION)
    for operator in ("over", "destination_over", "atop", "destination_out", "xor"):
        assert torch.allclose(composite(source, destination, operator, source_alpha=0.0), destination)
    colour, alpha = composite(source, destination, "in", source_alpha=0.0, return_alpha=True)
    assert alpha.item() == 0.0 and colour.abs().max() == 0.0


def test_over_with_alpha_map_mixes_linearly_over_opaque_destination() -> None:
    source = torch.rand(2, 3, 4, 5, dtype=DOUBLE)
    destination = torch.rand(1, 3, 4, 5, dtype=DOUBLE)
    alpha = torch.rand(2, 1, 4, 5, dtype=DOUBLE)
    expected = alpha * source + (1 - alpha) * destination
    assert torch.allclose(composite(source, destination, "over", alpha), expected)


@pytest.mark.parametrize("operator", ["over", "atop", "xor", "destination_over", "in"])
def test_composite_gradcheck(operator: str) -> None:
    source = _rand(2, 3, 4, 5, seed=1)
    destination = _rand(2, 3, 4, 5, seed=2)
    alpha_s = _rand(2, 1, 4, 5, low=0.2, high=0.8, seed=3)
    alpha_d = _rand(2, low=0.3, high=0.9, seed=4)

    def fn(s, d, a_s, a_d):
        return composite(s, d, operator, a_s, a_d, return_alpha=True)

    assert gradcheck(fn, (source, destination, alpha_s, alpha_d), eps=1e-6, atol=1e-5, rtol=1e-3)


@pytest.mark.parametrize(
    ("mode", "expected"),
    [
        ("multiply", (0.08, 0.3, 0.0)),
        ("screen", (0.82, 0.8, 1.0)),
        ("overlay", (0.16, 0.6, 1.0)),
        ("darken", (0.1, 0.5, 0.0)),
        ("lighten", (0.8, 0.6, 1.0)),
    ],
)
def test_blend_known_values(mode: str, expected: tuple[float, float, float]) -> None:
    base, layer = _pixel((0.1, 0.5, 1.0)), _pixel((0.8, 0.6, 0.0))
    assert torch.allclose(blend(base, layer, mode).flatten(), torch.tensor(expected, dtype=DOUBLE))
    assert torch.allclose(blend(base, layer, mode, opacity=0.0), base)
    half = blend(base, layer, mode, opacity=0.5).flatten()
    assert torch.allclose(half, 0.5 * (base.flatten() + torch.tensor(expected, dtype=DOUBLE)))


def test_multiply_with_white_and_screen_with_black_keep_the_base() -> None:
    base = torch.rand(1, 3, 4, 4, dtype=DOUBLE)
    assert torch.allclose(blend(base, torch.ones_like(base), "multiply"), base)
    assert torch.allclose(blend(base, torch.zeros_like(base), "screen"), base)


@pytest.mark.parametrize("mode", BLEND_MODES)
def test_blend_gradcheck(mode: str) -> None:
    base = _rand(2, 3, 4, 5, seed=5)
    # keep away from the kinks: overlay's split at 0.5 and min/max ties
    with torch.no_grad():
        base[(base - 0.5).abs() < 0.05] += 0.1
    layer = (base.detach() + 0.3 * torch.sign(_rand(2, 3, 4, 5, seed=6).detach() - 0.5)).requires_grad_()
    opacity = _rand(2, 1, 4, 5, low=0.2, high=0.9, seed=7)
    assert gradcheck(lambda b, top, o: blend(b, top, mode, o), (base, layer, opacity), eps=1e-6, atol=1e-5, rtol=1e-3)


def test_unknown_names_and_bad_shapes() -> None:
    image = torch.rand(1, 3, 4, 4)
    with pytest.raises(WiseError, match="over"):
        composite(image, image, "plus")
    with pytest.raises(WiseError, match="multiply"):
        blend(image, image, "dodge")
    with pytest.raises(WiseError):
        composite(image, torch.rand(1, 3, 4, 5))
    with pytest.raises(WiseError):
        blend(image, image, "screen", torch.rand(1, 1, 2, 2))
