import pytest
import torch

from wise.editor.brush import paint, stroke_weights
from wise.errors import WiseError


def test_a_hard_stroke_covers_its_radius_around_the_polyline() -> None:
    weights = stroke_weights((100, 200), [(0.25, 0.5), (0.75, 0.5)], radius=0.1, hardness=1.0)
    assert weights.shape == (100, 200)
    assert weights[50, 50:150].min() == 1.0  # along the segment
    assert weights[41:59, 100].min() == 1.0  # within 10 px (0.1 of the short side) across
    assert weights[:38, :].max() == 0.0 and weights[62:, :].max() == 0.0
    assert weights[:, :38].max() == 0.0 and weights[:, 162:].max() == 0.0  # round caps end at the radius


def test_a_soft_brush_falls_off_smoothly() -> None:
    weights = stroke_weights((101, 101), [(0.5, 0.5)], radius=0.2, hardness=0.0)
    profile = weights[50, 50:75]
    assert profile[0] == pytest.approx(1.0, abs=1e-3)
    assert torch.all(profile[1:] <= profile[:-1])
    assert 0.3 < float(profile[10]) < 0.7
    assert float(profile[21]) == 0.0


def test_going_over_a_spot_twice_in_one_stroke_paints_it_once() -> None:
    once = stroke_weights((64, 64), [(0.2, 0.5), (0.8, 0.5)], 0.1, 0.5)
    back_and_forth = stroke_weights((64, 64), [(0.2, 0.5), (0.8, 0.5), (0.2, 0.5)], 0.1, 0.5)
    assert torch.equal(once, back_and_forth)


def test_the_same_stroke_lands_on_the_same_place_at_any_mask_resolution() -> None:
    small = stroke_weights((64, 80), [(0.3, 0.4), (0.6, 0.7)], 0.08, 0.7)
    large = stroke_weights((256, 320), [(0.3, 0.4), (0.6, 0.7)], 0.08, 0.7)
    reduced = torch.nn.functional.avg_pool2d(large[None, None], 4)[0, 0]
    assert (reduced - small).abs().mean() < 0.02


def test_paint_modes_and_clamping() -> None:
    mask = torch.full((8, 8), 0.3)
    mask[0, 0] = 0.7  # outside the declared range, e.g. from a preset: kept where not painted
    weights = torch.zeros(8, 8)
    weights[4:, :] = 1.0
    weights[2, :] = 0.5
    raised = paint(mask, weights, "increase", 0.4)
    assert raised[5, 5] == pytest.approx(0.5) and raised[2, 5] == pytest.approx(0.5)  # clamped at the top
    assert raised[0, 0] == pytest.approx(0.7) and raised[1, 1] == pytest.approx(0.3)
    lowered = paint(mask, weights, "decrease", 0.2)
    assert lowered[5, 5] == pytest.approx(0.1) and lowered[2, 5] == pytest.approx(0.2)
    set_to = paint(mask, weights, "set", -0.1)
    assert set_to[5, 5] == pytest.approx(-0.1) and set_to[2, 5] == pytest.approx(0.1)


@pytest.mark.parametrize(
    "points, radius, hardness, message",
    [
        ([], 0.1, 0.5, "1 to"),
        ([(0.5,)], 0.1, 0.5, "(x, y) pair"),
        ([(5.0, 0.5)], 0.1, 0.5, "(x, y) pair"),
        ([(0.5, 0.5)], 0.0, 0.5, "radius"),
        ([(0.5, 0.5)], 0.1, 1.5, "hardness"),
    ],
)
def test_bad_strokes_are_refused(points, radius, hardness, message) -> None:  # noqa: ANN001
    with pytest.raises(WiseError, match=message.replace("(", r"\(").replace(")", r"\)")):
        stroke_weights((16, 16), points, radius, hardness)


def test_unknown_mode_is_refused() -> None:
    with pytest.raises(WiseError, match="brush mode"):
        paint(torch.zeros(4, 4), torch.ones(4, 4), "smudge", 0.1)


def test_painting_does_not_pull_a_value_outside_the_range_back_in_one_jump() -> None:
    mask = torch.tensor([[-1.5, 0.9, 0.0]])  # e.g. colour offsets fitted to a reference
    weights = torch.ones(1, 3)
    raised = paint(mask, weights, "increase", 0.2)
    assert raised[0].tolist() == pytest.approx([-1.3, 0.9, 0.2])  # towards the range, never further out
    lowered = paint(mask, weights, "decrease", 0.2)
    assert lowered[0].tolist() == pytest.approx([-1.5, 0.7, -0.2])
