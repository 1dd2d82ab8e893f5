"""Refinement from a prediction within a time budget."""

from __future__ import annotations

import pytest
import torch
from skimage import data

import wise
from wise import metrics
from wise.errors import WiseError
from wise.optimize.parametric import Outcome
from wise.optimize.refine import GLOBAL_LEVELS, _levels, answers, refine
from wise.optimize.trials import content_at
from wise.render import render


@pytest.fixture(scope="module")
def photo() -> torch.Tensor:
    return content_at(torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255, 96)


def test_refinement_moves_a_distant_start_towards_the_example_within_its_budget(photo: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    truth = effect.preset("lines")
    example = render(effect, photo, truth[None])  # as `wise apply` draws it, the look refine fits
    start = effect.default_params()
    before = metrics.ssim(render(effect, photo, start[None]), example)
    outcome = refine(effect, photo, example, start, budget=5.0)
    after = metrics.ssim(render(effect, photo, outcome.params), example)
    # the losses per iteration are of the smoothed look at first, so the renders are compared,
    # by the refinement's loss for global parameters (L1)
    distances = [float((render(effect, photo, p) - example).abs().mean()) for p in (start[None], outcome.params)]
    assert outcome.seconds <= 5.0 + 0.3 and len(outcome.losses) > 20
    assert after > before + 0.03, (before, after)
    assert distances[1] < 0.5 * distances[0], distances


def test_refinement_iterations_can_be_capped_and_the_budget_must_be_positive(photo: torch.Tensor) -> None:
    effect = wise.effects.create("cartoon")
    start = effect.default_params()
    outcome = refine(effect, photo, photo, start, budget=30.0, max_iterations=4)
    assert len(outcome.losses) == 4 and outcome.seconds < 30.0
    with pytest.raises(WiseError, match="budget"):
        refine(effect, photo, photo, start, budget=0.0)


class _Slow(torch.nn.Module):
    """An effect whose renders take ``delay`` seconds per 256² pixels, and twice that every fourth
    time, as on a busy machine."""

    def __init__(self, effect: torch.nn.Module, delay: float) -> None:
        super().__init__()
        self.effect, self.delay, self.calls = effect, delay, 0
        self.param_specs = effect.param_specs

    def forward(self, image: torch.Tensor, params: torch.Tensor, **where: object) -> torch.Tensor:
        import time

        self.calls += 1
        time.sleep(self.delay * (2 if self.calls % 4 == 0 else 1) * image.shape[-2] * image.shape[-1] / 256**2)
        return self.effect(image, params, **where)


def test_refinement_of_a_slow_case_stays_within_its_budget(photo: torch.Tensor) -> None:
    """`wise predict` with --budget 8 must not spend more than 8.8 s: no iteration starts, nor a
    level, that could end after the budget, the final renders included (the average iteration
    and no render gave 3.2 s here)."""
    effect = _Slow(wise.effects.create("xdog"), delay=0.15)
    large = torch.nn.functional.interpolate(photo, size=(512, 512), mode="area")
    start = effect.effect.default_params()
    outcome = refine(effect, large, large, start, budget=2.0)
    assert outcome.seconds <= 2.0 * 1.1, outcome.seconds
    assert len(outcome.losses) >= 2


def test_refinement_starts_from_the_number_of_levels_of_a_cartoon_example(photo: torch.Tensor) -> None:
    effect = wise.effects.create("cartoon")
    truth = effect.params_from_dict({"bins": 4.0, "softness": 0.1})[None]
    with torch.no_grad():
        example = effect(photo, truth)
    start = effect.params_from_dict({"bins": 12.0, "softness": 0.8})[None]
    outcome = refine(effect, photo, example, start, budget=30.0, max_iterations=1)
    found = effect.params_to_dict(outcome.params[0])
    assert found["bins"] == pytest.approx(4.0, abs=0.3) and found["softness"] < 0.3


def test_refinement_holds_a_count_read_where_the_example_leaves_it_open(
    photo: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Within seconds, descent from a network's start drifts a count read rightly towards a few
    soft levels: the count the reading changed is held, clear or not."""
    import wise.optimize.refine as refinement

    effect = wise.effects.create("cartoon")
    truth = effect.params_from_dict({"bins": 6.0, "softness": 0.3})[None]
    with torch.no_grad():
        example = effect(photo, truth)
    start = effect.params_from_dict({"bins": 3.0, "softness": 0.8, "contrast": 1.5})[None]
    read = effect.params_from_dict({"bins": 6.0, "softness": 0.8, "contrast": 1.5})[None]
    monkeypatch.setattr(refinement, "read_steps", lambda *args, **kwargs: (read.clone(), ()))  # left open
    monkeypatch.setattr(refinement, "readable_after_descent", lambda effect: False)  # the count as descent left it
    outcome = refine(effect, photo, example, start, budget=30.0, max_iterations=30)
    bins = effect.param_names.index("bins")
    assert outcome.read is not None and outcome.read[0, bins] == read[0, bins]
    assert outcome.params[0, bins] == read[0, bins]
    moved = outcome.params[0] != outcome.read[0]
    assert moved.any(), "the other parameters descend"


def test_a_count_descent_cannot_reach_is_read_after_it_and_judged_beside_it(
    photo: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    import wise.optimize.refine as refinement

    effect = wise.effects.create("cartoon")
    truth = effect.params_from_dict({"bins": 5.0, "softness": 0.2})[None]
    with torch.no_grad():
        example = effect(photo, truth)
    start = effect.params_from_dict({"bins": 11.0, "softness": 0.2})[None]
    monkeypatch.setattr(refinement, "read_steps", lambda effect, content, target, given, **kwargs: (given, ()))
    monkeypatch.setattr(refinement, "fit_quickly", lambda effect, content, target, given, **kwargs: given)
    outcome = refine(effect, photo, example, start, budget=30.0, max_iterations=4)
    assert effect.params_to_dict(outcome.params[0])["bins"] > 9.0  # descent alone stays on its step
    assert outcome.settled, "the count is read again after descent"
    assert effect.params_to_dict(outcome.settled[0][0])["bins"] == pytest.approx(5.0, abs=0.25)
    listed = answers(outcome)
    assert listed[0] == ("descent", outcome.params)
    assert any(name == "read after descent" and answer is outcome.settled[0] for name, answer in listed)
    oilpaint = wise.effects.create("oilpaint")
    outcome = refine(oilpaint, photo, photo, oilpaint.default_params()[None], budget=30.0, max_iterations=2)
    assert outcome.settled == ()  # no steps to read after descent


def test_the_answers_list_each_candidate_once_in_order() -> None:
    descended, reading, other = torch.zeros(1, 3), torch.ones(1, 3), torch.full((1, 3), 0.5)
    outcome = Outcome(params=descended, settled=(reading.clone(), descended.clone(), other), read=reading.clone())
    listed = answers(outcome)
    assert len(listed) == 3, "a reading equal to an earlier answer is not judged again"
    assert [name for name, _ in listed] == ["read", "descent", "read after descent"], "simplest first"
    assert torch.equal(listed[0][1], reading) and listed[1][1] is descended and listed[2][1] is other


def test_global_refinement_descends_on_crops_of_a_large_copy_and_of_a_small_one_drawn_enlarged() -> None:
    large, small = torch.zeros(1, 3, 768, 1024), torch.zeros(1, 3, 200, 300)
    (level,) = _levels(large, "global")
    assert level.side == 512 and level.crop == GLOBAL_LEVELS[0].crop
    # a small photo is drawn at the reference size, as `wise apply` draws it: crops of that render
    (level,) = _levels(small, "global")
    assert level.side == 200 and level.crop == GLOBAL_LEVELS[0].crop and level.share == 1.0
    assert all(level.crop is None for level in _levels(large, "local"))
    assert [level.side for level in _levels(small, "local")] == [200]


def test_local_refinement_paints_masks_on_whole_copies(photo: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    with torch.no_grad():
        example = effect(photo, effect.preset("lines")[None])
    outcome = refine(effect, photo, example, effect.default_params()[None], budget=30.0, mode="local", max_iterations=4)
    assert outcome.params.shape == (1, len(effect.param_names), *photo.shape[-2:])
    assert len(outcome.losses) == 4 and outcome.result is not None


def test_a_slow_reading_leaves_the_colour_fit_out_and_descent_its_time(
    photo: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a busy machine the readings slow down as much as descent: a fit planned from the reading's
    own time that would take most of the budget is left out, said so, and descent still runs."""
    import time

    from wise.optimize import refine as module

    effect = wise.effects.create("cartoon")
    start = effect.default_params()
    fitted: list[bool] = []

    def reading(delay: float):
        def read(effect, content, target, given, side, **options):  # noqa: ANN001, ANN003, ANN202 (read_steps')
            time.sleep(delay)
            return given, ()

        return read

    def fit(effect, content, target, params, side, deadline, **options):  # noqa: ANN001, ANN003, ANN202 (fit_quickly's)
        fitted.append(True)
        return params

    monkeypatch.setattr(module, "fit_quickly", fit)
    monkeypatch.setattr(module, "read_after_descent", lambda *args: [])
    monkeypatch.setattr(module, "read_steps", reading(0.0))
    quick = refine(effect, photo, photo, start, budget=3.0, max_iterations=3)
    assert fitted == [True] and quick.left_out == ()
    monkeypatch.setattr(module, "read_steps", reading(0.4))  # 0.4 s x (1 + 5) > half of 3 s
    slow = refine(effect, photo, photo, start, budget=3.0, max_iterations=3)
    assert fitted == [True] and slow.left_out == ("the colour fit",)
    assert len(slow.losses) == 3 and slow.seconds <= 3.0 + 0.5
