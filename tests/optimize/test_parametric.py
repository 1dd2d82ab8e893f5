import contextlib
from dataclasses import replace

import pytest
import torch
import torch.nn.functional as F

import wise
import wise.optimize.parametric as parametric
from wise import metrics
from wise.errors import WiseError
from wise.filters.smoothing import step_temperature
from wise.optimize import Settings, optimize
from wise.optimize.adam import Adam
from wise.optimize.parametric import PYRAMIDS, optimize_coarse_to_fine, optimize_on_crops, pyramid
from wise.optimize.settings import MASK_SOFT_GRADIENTS
from wise.params import mask_bounds


@pytest.fixture(scope="module")
def content(astronaut: torch.Tensor) -> torch.Tensor:
    return F.interpolate(astronaut, size=(64, 64), mode="area")


@pytest.mark.parametrize("mode", ["global", "local"])
def test_loss_falls_towards_a_reference_of_the_same_effect(content: torch.Tensor, mode: str) -> None:
    effect = wise.effects.create("cartoon")
    target_params = effect.params_from_dict({"saturation": 0.3, "contrast": 1.6, "brightness": -0.1})
    with torch.no_grad():
        target = effect(content, target_params[None])
    outcome = optimize(effect, content, target, effect.default_params(), Settings(mode=mode, iterations=25))
    assert len(outcome.losses) == 25 and not outcome.interrupted
    assert min(outcome.losses[-5:]) < 0.7 * outcome.losses[0]
    expected_shape = (1, len(effect.param_specs)) + ((64, 64) if mode == "local" else ())
    assert outcome.params.shape == expected_shape
    if mode == "global":
        assert outcome.params.min() >= -0.5 and outcome.params.max() <= 0.5
    else:
        low, high = mask_bounds(effect.param_specs, outcome.params)
        assert bool((outcome.params >= low).all()) and bool((outcome.params <= high).all())


def _saturated_start_run(content: torch.Tensor, mode: str) -> tuple[torch.Tensor, torch.Tensor, list[float]]:
    effect = wise.effects.create("cartoon")
    with torch.no_grad():
        target = effect(content, effect.default_params()[None])
    start = effect.params_from_dict({"brightness": 0.3, "contrast": 2.0})  # light half turns white
    outcome = optimize(effect, content, target, start, Settings(mode=mode, iterations=40, levels=1))
    assert outcome.result is not None
    return outcome.result, target, outcome.losses


def _wrongly_white(result: torch.Tensor, target: torch.Tensor) -> float:
    return float(((result >= 0.999).all(1) & ~(target >= 0.999).all(1)).float().mean())


def _plain_clamp(monkeypatch: pytest.MonkeyPatch) -> None:
    """Run the optimization without the clamp's gradient back into range."""
    monkeypatch.setattr(parametric, "inward_gradients", lambda enabled=True: contextlib.nullcontext())


def test_masks_bring_a_region_saturated_to_white_back(content: torch.Tensor, monkeypatch: pytest.MonkeyPatch) -> None:
    result, target, losses = _saturated_start_run(content, "local")
    assert _wrongly_white(result, target) < 0.02
    assert min(losses[-5:]) < 0.35 * losses[0]
    # with a plain clamp the white region's mask pixels have no gradient and stay white
    _plain_clamp(monkeypatch)
    stuck, _, _ = _saturated_start_run(content, "local")
    assert _wrongly_white(stuck, target) > 0.1


def test_global_parameters_keep_the_plain_clamp(content: torch.Tensor, monkeypatch: pytest.MonkeyPatch) -> None:
    # on one thread: the kernels' sums over several threads round differently from run to run, and
    # the cartoon's steps turn such differences into other runs
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        result, _, losses = _saturated_start_run(content, "global")
        _plain_clamp(monkeypatch)
        plain, _, plain_losses = _saturated_start_run(content, "global")
    finally:
        torch.set_num_threads(threads)
    assert losses == plain_losses and torch.equal(result, plain)


def test_interrupt_keeps_the_state_reached(content: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    target = torch.ones_like(content)

    def stop_after_three(iteration: int, loss: float, output: torch.Tensor) -> None:
        if iteration == 3:
            raise KeyboardInterrupt

    outcome = optimize(effect, content, target, effect.default_params(), Settings(iterations=50), stop_after_three)
    assert outcome.interrupted and len(outcome.losses) == 3
    assert outcome.result is not None and outcome.result.shape == content.shape


def test_bad_settings_are_refused() -> None:
    bads = ({"mode": "x"}, {"loss": "x"}, {"iterations": 0}, {"lr": 0.0}, {"tv_weight": -1.0}, {"levels": 9})
    limits = ({"anneal": 1.5}, {"time_limit": 0.0}, {"final_lr": 0.0}, {"final_lr": 1.5})
    for bad in (*bads, *limits):
        with pytest.raises(WiseError):
            Settings(**bad)


def test_coarse_to_fine_carries_the_parameters_up_the_pyramid(content: torch.Tensor) -> None:
    effect = wise.effects.create("cartoon")
    target_params = effect.params_from_dict({"saturation": 0.3, "contrast": 1.6, "brightness": -0.1})
    with torch.no_grad():
        target = effect(content, target_params[None])
    levels = ((4, Settings(mode="global", iterations=20)), (1, Settings(mode="global", iterations=5, lr=0.02)))
    outcome = optimize_coarse_to_fine(effect, content, target, effect.default_params(), levels)
    assert len(outcome.losses) == 25 and outcome.result is not None and outcome.result.shape == content.shape
    start_error = float((effect(content, effect.default_params()[None]) - target).abs().mean())
    assert float((outcome.result - target).abs().mean()) < 0.5 * start_error


@pytest.mark.parametrize("levels", sorted(PYRAMIDS))
@pytest.mark.parametrize("iterations", [1, 2, 7, 300])
def test_pyramid_spends_exactly_the_iterations_and_ends_at_full_size(levels: int, iterations: int) -> None:
    settings = Settings(iterations=iterations, lr=0.2, levels=levels, mode="global", loss="l2")
    plan = pyramid(settings)
    assert sum(s.iterations for _, s in plan) == iterations
    assert plan[-1][0] == 1 and all(s.iterations >= 1 for _, s in plan)
    reductions = [r for r, _ in plan]
    assert reductions == sorted(reductions, reverse=True)
    assert all(s.mode == "global" and s.loss == "l2" and s.lr <= 0.2 for _, s in plan)
    if iterations == 300:
        assert len(plan) == levels and plan[0][1].lr == pytest.approx(0.2)


def test_coarse_to_fine_counts_iterations_over_all_levels(content: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    seen: list[tuple[int, tuple[int, ...]]] = []
    levels = pyramid(Settings(mode="global", iterations=6, levels=2))
    optimize_coarse_to_fine(
        effect,
        content,
        torch.ones_like(content),
        effect.default_params(),
        levels,
        lambda i, loss, output: seen.append((i, tuple(output.shape[-2:]))),
    )
    assert [i for i, _ in seen] == [1, 2, 3, 4, 5, 6]
    assert seen[0][1] == (32, 32) and seen[-1][1] == (64, 64)


def test_coarse_to_fine_interrupted_on_a_coarse_level_returns_full_size_masks(content: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")

    def stop_after_two(iteration: int, loss: float, output: torch.Tensor) -> None:
        if iteration == 2:
            raise KeyboardInterrupt

    levels = ((2, Settings(iterations=10)), (1, Settings(iterations=10)))
    outcome = optimize_coarse_to_fine(
        effect, content, torch.ones_like(content), effect.default_params(), levels, stop_after_two
    )
    assert outcome.interrupted and len(outcome.losses) == 2
    assert outcome.params.shape[-2:] == content.shape[-2:]
    assert outcome.result is not None and outcome.result.shape == content.shape


@pytest.mark.parametrize("name", ["watercolor"])
def test_masks_optimized_small_render_the_same_picture_four_times_larger(astronaut: torch.Tensor, name: str) -> None:
    from wise import metrics
    from wise.render import render

    effect = wise.effects.create(name)
    # 128 px: an eighth of the reference resolution (64 px) leaves the paper grain below a pixel
    small = F.interpolate(astronaut, size=(128, 128), mode="area")
    target = F.interpolate(astronaut.flip(1), size=(128, 128), mode="area")  # colours the effect must paint
    outcome = optimize(effect, small, target, effect.default_params(), Settings(iterations=30))
    assert outcome.result is not None
    large = render(effect, F.interpolate(astronaut, size=(512, 512), mode="area"), outcome.params)
    reduced = F.interpolate(large, size=(128, 128), mode="area")
    assert metrics.l1(reduced, outcome.result) < 0.35 * metrics.l1(small, target)
    assert metrics.ssim(reduced, outcome.result) > 0.8


def test_crops_recover_a_parameter_at_full_resolution(astronaut: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    content = F.interpolate(astronaut, size=(96, 112), mode="area")
    truth = effect.default_params()[None].clone()
    index = effect.param_names.index("brightness")
    truth[0, index] = 0.35
    with torch.no_grad():
        target = effect(content, truth)
    settings = Settings(mode="global", iterations=60, lr=0.05, loss="l2")
    outcome = optimize_on_crops(effect, content, target, effect.default_params(), settings, crop=48)
    assert len(outcome.losses) == 60 and outcome.result.shape == content.shape
    start_error = abs(float(effect.default_params()[index]) - 0.35)
    assert abs(float(outcome.params[0, index]) - 0.35) < 0.3 * start_error
    with torch.no_grad():
        start = effect(content, effect.default_params()[None])
    assert float((outcome.result - target).square().mean()) < 0.5 * float((start - target).square().mean())


def test_crops_end_within_their_time_limit_and_can_skip_the_whole_render(astronaut: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    content = F.interpolate(astronaut, size=(192, 256), mode="area")
    settings = Settings(mode="global", iterations=10_000, lr=0.05, loss="l2", time_limit=1.0, anneal=0.3)
    warm_up = replace(settings, iterations=1, time_limit=None)  # the kernels' first use in this process
    optimize_on_crops(effect, content, content, effect.default_params(), warm_up, crop=48, render=False)
    outcome = optimize_on_crops(effect, content, content, effect.default_params(), settings, crop=48, render=False)
    assert 5 < len(outcome.losses) < 10_000 and outcome.result is None
    assert outcome.seconds < 1.0 + 0.3
    rendered = optimize_on_crops(effect, content, content, effect.default_params(), settings, crop=48)
    assert rendered.result is not None and rendered.result.shape == content.shape
    assert rendered.seconds < 1.0 + 0.3  # the estimated whole render counted in the limit


@pytest.mark.parametrize("on_crops", [True, False])
def test_the_learning_rate_falls_to_its_final_share_along_a_cosine(
    content: torch.Tensor, monkeypatch: pytest.MonkeyPatch, on_crops: bool
) -> None:
    rates: list[float] = []
    step = Adam.step

    def recording(self: Adam) -> None:
        rates.append(self.param_groups[0]["lr"])
        step(self)

    monkeypatch.setattr(Adam, "step", recording)
    effect = wise.effects.create("xdog")
    settings = Settings(mode="global", iterations=40, lr=0.04, loss="l2", levels=1, final_lr=0.1)

    def run(settings: Settings) -> None:
        if on_crops:
            optimize_on_crops(effect, content, content, effect.default_params(), settings, crop=32, render=False)
        else:
            optimize(effect, content, content, effect.default_params(), settings)

    run(settings)
    assert rates[0] == pytest.approx(0.04, rel=0.01)
    assert rates[20] == pytest.approx(0.04 * 0.55, rel=0.05)  # half way: half way down
    assert rates[-1] == pytest.approx(0.04 * 0.1, rel=0.05)
    assert all(later <= earlier for earlier, later in zip(rates, rates[1:]))
    rates.clear()
    run(replace(settings, final_lr=None, iterations=60))
    assert rates[-1] == pytest.approx(0.04 * parametric.DECAY**2, rel=1e-6)  # the paper's: x 0.98 at 50 and 55


def test_crops_take_global_parameters_and_image_losses_only(content: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    for settings in (Settings(mode="local", iterations=2), Settings(mode="global", iterations=2, loss="nst")):
        with pytest.raises(WiseError, match="global|l1, l1-lab or l2"):
            optimize_on_crops(effect, content, content, effect.default_params(), settings)


def test_a_time_limit_ends_the_iterations_before_it_is_spent(content: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    settings = Settings(mode="global", iterations=10_000, time_limit=1.0)
    outcome = optimize(effect, content, content, effect.default_params(), settings)
    assert 5 < len(outcome.losses) < 10_000 and not outcome.interrupted
    assert outcome.seconds < 1.0 + 0.5  # the last iteration starts only when it should end in time


def test_annealing_smooths_the_first_iterations_and_ends_on_the_look_itself(
    content: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    temperatures = []
    effect = wise.effects.create("xdog")
    render = effect.render

    def recording(*args, **kwargs):
        temperatures.append(step_temperature())
        return render(*args, **kwargs)

    monkeypatch.setattr(effect, "render", recording)
    optimize(effect, content, content, effect.default_params(), Settings(mode="global", iterations=12, anneal=0.4))
    assert temperatures[0] == 0.4 and temperatures[-1] == 0.0 and temperatures[-3:] == [0.0] * 3
    assert all(a >= b for a, b in zip(temperatures, temperatures[1:]))
    levels = pyramid(Settings(iterations=30, anneal=0.4))
    assert [level.anneal for _, level in levels] == [0.4, 0.0, 0.0]


def test_masks_reach_a_reference_colour_beyond_the_declared_colour_ranges() -> None:
    # a white wall that the reference paints dark red: brightness must go below its range's -0.2
    effect = wise.effects.create("oilpaint")
    content = torch.ones(1, 3, 32, 32)
    target = torch.tensor([0.45, 0.08, 0.06]).view(1, 3, 1, 1).expand(1, 3, 32, 32)
    settings = Settings(mode="local", iterations=120, levels=1)
    outcome = optimize(effect, content, target, effect.default_params(), settings)
    assert outcome.result is not None
    assert float((outcome.result - target).abs().mean()) < 0.05
    brightness = effect.spec("brightness").to_real(
        float(outcome.params[0, effect.param_names.index("brightness")].mean())
    )
    assert brightness < effect.spec("brightness").min - 0.2
    contrast = outcome.params[0, effect.param_names.index("contrast")]
    assert contrast.min() >= -0.5 and contrast.max() <= 0.5  # parameters without a reach keep their range


def test_in_lab_a_saturated_colour_does_not_stand_in_for_a_tone() -> None:
    from wise.optimize.parametric import image_distance

    target = torch.full((1, 3, 4, 4), 0.3)
    target[:, 2] = 0.45  # a dark grey-blue
    darker = target - 0.1  # the right hue, a level too dark
    purple = darker.clone()
    purple[:, 0] += 0.2  # red and blue raised to make up the tone channel by channel
    purple[:, 2] += 0.2
    # in RGB the saturated purple is as close as the dark grey-blue, in Lab it is farther
    assert float(image_distance("l1", purple, target)) <= float(image_distance("l1", darker, target)) + 1e-6
    assert float(image_distance("l1-lab", purple, target)) > float(image_distance("l1-lab", darker, target))
    assert float(image_distance("l1-lab", target, target)) == 0.0


def test_masks_take_away_ink_the_target_lacks_through_soft_gradients() -> None:
    # a dark photo below the cartoon's ink threshold is inked black all over: every pixel on
    # the flat end of the threshold, where its exact gradient is zero
    effect = wise.effects.create("cartoon")
    content = 0.08 + 0.02 * torch.rand(1, 3, 32, 32, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        target = effect(content, effect.params_from_dict({"brightness": 0.3, "gamma": 2.0, "blackness": 0.01})[None])
        assert float(effect(content, effect.default_params()[None]).max()) < 0.01 < 0.5 < float(target.mean())
    exact, soft = (
        optimize(effect, content, target, effect.default_params(), Settings(iterations=30, levels=1, soft_gradients=s))
        for s in (0.0, 0.5)
    )
    assert float(exact.result.max()) < 0.01  # no gradient ever reached the masks
    assert float((soft.result - target).abs().mean()) < 0.1


def test_soft_gradients_default_to_per_pixel_descent() -> None:
    assert Settings(mode="local").soft_gradients == MASK_SOFT_GRADIENTS > 0.0
    assert Settings(mode="global").soft_gradients == 0.0
    with pytest.raises(WiseError, match="gradient softness"):
        Settings(soft_gradients=1.5)


@pytest.mark.parametrize("size", [(512, 512), (300, 700), (200, 256)])
def test_the_crops_of_masks_cover_every_pixel_each_pass_in_windows_of_one_size(size: tuple[int, int]) -> None:
    generator = torch.Generator().manual_seed(1)
    for passes in range(2):
        covered = torch.zeros(size, dtype=torch.int32)
        crop = min(256, *size)  # as optimize_masks_on_crops takes it
        windows = parametric._covering_windows(size, crop, 24, passes, generator)
        for (top, y0, y1), (left, x0, x1) in windows:
            assert y1 - y0 == min(size[0], crop + 48) and x1 - x0 == min(size[1], crop + 48)
            assert y0 <= top and top + crop <= y1 and x0 <= left and left + crop <= x1
            covered[top : top + crop, left : left + crop] += 1
        assert int(covered.min()) >= 1


def test_masks_fitted_at_the_size_of_the_result_leave_no_lines_the_target_lacks(astronaut: torch.Tensor) -> None:
    # at a working size of half the result's, the watercolor's pencil contours fall under a pixel:
    # masks fitted there keep the contours' start opacity, and the result shows lines where the
    # target has none (a target rendered without contours)
    effect = wise.effects.create("watercolor")
    full = F.interpolate(astronaut, size=(256, 256), mode="area")
    working = F.interpolate(full, size=(128, 128), mode="area")
    start = effect.params_from_dict({"contour": 0.6})
    with torch.no_grad():
        target = effect(full, effect.params_from_dict({"contour": 0.0})[None])
    settings = Settings(mode="local", iterations=30, lr=0.1, loss="l1-lab", levels=1)
    reduced_target = F.interpolate(target, size=(128, 128), mode="area")
    at_working_size = optimize(effect, working, reduced_target, start, settings)
    start_masks = start[None, :, None, None].expand(1, -1, 128, 128)
    on_crops = parametric.optimize_masks_on_crops(effect, full, target, start_masks, settings, crop=128)
    assert on_crops.params.shape == at_working_size.params.shape and on_crops.result.shape == working.shape

    def marks_at_full_size(params: torch.Tensor) -> float:
        with torch.no_grad():
            return metrics.marks(effect(full, F.interpolate(params, size=(256, 256), mode="bilinear")), target)[0]

    before, after = marks_at_full_size(at_working_size.params), marks_at_full_size(on_crops.params)
    assert before > 0.02 and after < 0.6 * before
