import math

import pytest
import torch
import torch.nn.functional as F

from wise import effects
from wise.effects.common import COLOUR_ADJUSTMENTS
from wise.filters.quantize import quantize
from wise.optimize import inversion
from wise.optimize.inversion import (
    colours_from_levels,
    comb_agreement,
    describe_estimates,
    fit_colours_to_levels,
    fit_quickly,
    inversion_between_levels,
    invert_steps,
    level_agreement,
    plateau_bins,
    read_after_descent,
    read_starts,
    read_steps,
    softness_from_agreement,
    staircase_fit,
    steps_from_rendering,
    unquantized_bounds,
    xdog_threshold_from_ink,
    xdog_tones_from_shading,
)
from wise.optimize.parametric import Settings, optimize_coarse_to_fine
from wise.train.procedural import dead_leaves


def _with(effect, params: torch.Tensor, **values: float) -> torch.Tensor:
    changed = params.clone()
    for name, value in values.items():
        changed[0, effect.param_names.index(name)] = effect.spec(name).to_normalized(value)
    return changed


def _real(effect, params: torch.Tensor, name: str) -> float:
    return effect.params_to_dict(params[0])[name]


def _example(astronaut: torch.Tensor, name: str, side: int, **truth: float):
    """The effect, the photo at ``side`` pixels, parameters with ``truth`` set and their rendering."""
    effect = effects.create(name).eval()
    content = F.interpolate(astronaut, size=(side, side), mode="area")
    params = _with(effect, effect.default_params().reshape(1, -1), **truth)
    with torch.no_grad():
        return effect, content, params, effect(content, params)


def test_the_comb_of_the_true_bin_count_agrees_and_others_do_not() -> None:
    x = torch.rand(20000, generator=torch.Generator().manual_seed(0))
    levels = quantize(x.view(1, 1, 1, -1), 6.0).flatten()
    agreement = comb_agreement(levels, torch.tensor([6.0, 5.0, 7.0, 4.0, 12.0]))
    assert float(agreement[0]) == pytest.approx(1.0, abs=1e-3)  # up to the histogram's bin width
    assert (agreement[1:] < 0.2).all()  # 12 bins: its centres miss every level of 6
    found, _ = plateau_bins(levels, 2.0, 16.0)
    assert found[0] == pytest.approx(6.0, abs=0.02)


def test_a_luminance_that_no_comb_fits_still_gives_one_candidate() -> None:
    found, agreements = plateau_bins(torch.zeros(100), 2.0, 16.0)  # black: every comb disagrees
    assert len(found) == 1 and agreements[0] < 0


def test_the_ramps_width_follows_from_how_sharply_the_plateaus_agree() -> None:
    x = torch.rand(40000, generator=torch.Generator().manual_seed(1))
    for low, span in ((0.0, 1.0), (0.2, 0.4)):  # every level occupied, or two of five
        for softness in (0.05, 0.3, 0.6):
            levels = quantize((low + span * x).view(1, 1, 1, -1), 5.0, softness).flatten()
            found = softness_from_agreement(level_agreement(levels, 5.0), 5.0, 0.0, 1.0)
            assert found == pytest.approx(softness, abs=0.05), (low, span, softness)


def test_the_staircase_is_fitted_from_the_luminance_before_and_after() -> None:
    x = torch.rand(5000, generator=torch.Generator().manual_seed(2))
    after = quantize(x.view(1, 1, 1, -1), 9.3, 0.4).flatten()
    bins, softness = staircase_fit(x, after, (2.0, 16.0), (0.0, 1.0))
    assert bins == pytest.approx(9.3, abs=0.03) and softness == pytest.approx(0.4, abs=0.01)


def test_the_quantizer_is_inverted_to_a_point_on_a_ramp_and_a_level_on_a_plateau() -> None:
    x = torch.rand(3000, generator=torch.Generator().manual_seed(4)) * 1.2 - 0.1  # some clamped
    for bins, softness in ((5.0, 0.0), (7.5, 0.4)):
        levels = quantize(x.clamp(0.0, 1.0).view(1, 1, 1, -1), bins, softness).flatten()
        low, high, known = unquantized_bounds(levels, bins, softness)
        assert known.all()
        assert ((low <= x + 1e-3) & (x - 1e-3 <= high)).all()  # the input lies within its bounds
        inner = (x > 1.0 / bins) & (x < (math.ceil(bins) - 1.0) / bins)  # the outer levels reach on
        width = (high - low)[inner]
        if softness == 0.0:  # a plateau: the level's width
            assert width.max() <= 1.0 / bins + 1e-3 and width.min() >= 1.0 / bins - 2e-3
        else:  # on the ramps the quantizer is invertible: mostly narrow
            assert float((width < 0.05).float().mean()) > 0.5
        assert torch.isinf(low[x < 0.0]).all() and torch.isinf(high[x > 1.0]).all()
    _, _, known = unquantized_bounds(torch.tensor([0.4, 0.5]), 5.0, 0.0)  # between two hard levels; a centre
    assert known.tolist() == [False, True]
    low, _, known = unquantized_bounds(
        torch.tensor([0.5], dtype=torch.float64), 5.0, 0.0
    )  # on the values' device and dtype
    assert known.all() and low.dtype == torch.float64 and float(low) == pytest.approx(0.4, abs=1e-3)


def test_the_colour_adjustments_are_fitted_to_the_examples_levels(
    astronaut: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    cartoon, content, truth, example = _example(
        astronaut, "cartoon", 96, bins=6.0, softness=0.05, brightness=0.15, contrast=1.6, saturation=0.5, tint=0.3
    )
    start = _with(cartoon, truth, brightness=-0.1, contrast=1.0, saturation=1.5, tint=0.0)
    monkeypatch.setattr(inversion, "FIT_ITERATIONS", 100)  # enough at 96 pixels
    fitted = fit_colours_to_levels(cartoon, content, example, start)
    with torch.no_grad():
        before, after = (float((cartoon(content, p) - example).square().mean()) for p in (start, fitted))
    assert after < 0.25 * before
    for name, tolerance in (("brightness", 0.08), ("saturation", 0.2), ("tint", 0.08)):
        assert _real(cartoon, fitted, name) == pytest.approx(_real(cartoon, truth, name), abs=tolerance), name
    untouched = [i for i, name in enumerate(cartoon.param_names) if name in ("bins", "softness", "details", "contour")]
    assert torch.equal(fitted[0, untouched], start[0, untouched])


def test_the_colour_adjustments_are_fitted_quickly_on_a_sample_of_the_levels(astronaut: torch.Tensor) -> None:
    cartoon, content, truth, example = _example(
        astronaut, "cartoon", 128, bins=6.0, softness=0.05, brightness=0.15, contrast=1.6, saturation=0.5, tint=0.3
    )
    start = _with(cartoon, truth, brightness=-0.1, contrast=1.0, saturation=1.5, tint=0.0)
    fitted = colours_from_levels(cartoon, content, example, start)
    with torch.no_grad():
        before, after = (float((cartoon(content, p) - example).square().mean()) for p in (start, fitted))
    assert after < 0.25 * before, (before, after)
    for name, tolerance in (("brightness", 0.08), ("contrast", 0.25), ("saturation", 0.2), ("tint", 0.08)):
        assert _real(cartoon, fitted, name) == pytest.approx(_real(cartoon, truth, name), abs=tolerance), name
    colours = [i for i, name in enumerate(cartoon.param_names) if name in COLOUR_ADJUSTMENTS]
    others = [i for i in range(len(cartoon.param_names)) if i not in colours]
    assert torch.equal(fitted[0, others], start[0, others])


def test_a_quick_fit_is_kept_only_where_it_renders_closer(
    astronaut: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    cartoon, content, truth, example = _example(astronaut, "cartoon", 96, bins=6.0, softness=0.05, saturation=0.5)
    start = _with(cartoon, truth, saturation=2.0)
    with torch.no_grad():
        fitted = fit_quickly(cartoon, content, example, start, side=96)
        assert float((cartoon(content, fitted) - example).square().mean()) < float(
            (cartoon(content, start) - example).square().mean()
        )
    worse = _with(cartoon, truth, saturation=3.0)
    monkeypatch.setitem(inversion._QUICK_FITS, "cartoon", lambda *args: worse.clone())
    assert torch.equal(fit_quickly(cartoon, content, example, truth, side=96), truth)
    xdog = effects.create("xdog")
    given = xdog.default_params().reshape(1, -1)
    assert fit_quickly(xdog, content, content, given) is given  # no fit for xdog


def test_the_count_and_ramps_are_swept_through_the_rendering(astronaut: torch.Tensor) -> None:
    """With the colours right, the rendering of every count tells the example's, clipped colours
    and outlines included, where the histogram's plateaus may not."""
    cartoon, content, truth, example = _example(
        astronaut, "cartoon", 128, bins=5.0, softness=0.2, saturation=2.5, contrast=1.8
    )
    wrong = _with(cartoon, truth, bins=11.0, softness=0.8)
    swept = steps_from_rendering(cartoon, content, example, wrong)
    assert _real(cartoon, swept, "bins") == pytest.approx(5.0, abs=0.1)
    assert _real(cartoon, swept, "softness") == pytest.approx(0.2, abs=0.1)
    others = [i for i, name in enumerate(cartoon.param_names) if name not in ("bins", "softness")]
    assert torch.equal(swept[0, others], wrong[0, others])
    assert torch.equal(steps_from_rendering(cartoon, content, example, truth), truth)  # nothing renders closer
    watercolor = effects.create("watercolor")
    given = watercolor.default_params().reshape(1, -1)
    assert read_after_descent(watercolor, content, content, given) == []  # no steps to read


def test_the_ink_threshold_comes_from_the_ink_share_and_the_response() -> None:
    generator = torch.Generator().manual_seed(3)
    flat = torch.rand(1, 1, 64, 64, generator=generator)
    edges = torch.randn(1, 1, 64, 64, generator=generator) * 0.01
    ink = flat + 1.5 * edges < 0.3
    contour, blackness, overlap = xdog_threshold_from_ink(ink, flat, edges, torch.linspace(0, 3, 31), (0.01, 0.5))
    assert contour == pytest.approx(1.5, abs=0.11) and blackness == pytest.approx(0.3, abs=0.01)
    assert overlap > 0.95


def test_cartoon_bins_and_softness_are_read_off_its_rendering(astronaut: torch.Tensor) -> None:
    cartoon, content, truth, example = _example(astronaut, "cartoon", 128, bins=4.0, softness=0.1)
    start = _with(cartoon, truth, bins=12.0, softness=0.8)  # far off, a staircase away
    found = invert_steps(cartoon, content, example, start)
    assert _real(cartoon, found, "bins") == pytest.approx(4.0, abs=0.15)
    assert _real(cartoon, found, "softness") == pytest.approx(0.1, abs=0.1)
    others = [i for i, name in enumerate(cartoon.param_names) if name not in ("bins", "softness")]
    assert torch.equal(found[0, others], start[0, others])


def test_xdog_threshold_and_shading_are_read_off_its_drawing(astronaut: torch.Tensor) -> None:
    xdog, content, truth, example = _example(astronaut, "xdog", 128, contour=2.0, blackness=0.3, shading=0.7)
    start = _with(xdog, truth, contour=0.5, blackness=0.05, shading=0.1)
    with torch.no_grad():
        assert float((xdog(content, start) - example).abs().mean()) > 0.05
    found = invert_steps(xdog, content, example, start)
    for name, value, tolerance in (("blackness", 0.3, 0.03), ("shading", 0.7, 0.05)):
        assert _real(xdog, found, name) == pytest.approx(value, abs=tolerance), name
    # at 128 pixels contours from about 1.5 up draw the same ink: any of them is an answer
    assert 1.2 <= _real(xdog, found, "contour") <= 2.2
    with torch.no_grad():
        assert float((xdog(content, found) - example).abs().mean()) < 0.002
    assert _real(xdog, invert_steps(xdog, content, example, truth), "contour") == pytest.approx(2.0, abs=0.05)


def test_xdog_tone_is_read_off_the_shading_between_its_lines(
    astronaut: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    truth_tone = {"brightness": 0.05, "contrast": 2.6, "saturation": 2.5, "shading": 0.6}
    xdog, content, truth, example = _example(astronaut, "xdog", 128, **truth_tone)
    start = xdog.default_params().reshape(1, -1)  # contrast 1.15, saturation 1.02, shading 0.5
    tone = xdog_tones_from_shading(xdog, content, example, start)[0]
    assert tone["shading"] == pytest.approx(0.6, abs=0.08)
    assert tone["contrast"] == pytest.approx(2.6, abs=0.4)
    assert tone["brightness"] == pytest.approx(0.05, abs=0.1)
    assert tone["saturation"] > 1.7  # strong saturation clips, so its exact value shows little
    found = invert_steps(xdog, content, example, start)
    assert _real(xdog, found, "contrast") == pytest.approx(tone["contrast"])
    monkeypatch.setattr(inversion, "xdog_tones_from_shading", lambda *args, **kwargs: [])
    lines_only = invert_steps(xdog, content, example, start)
    with torch.no_grad():
        error, error_lines_only = (float((xdog(content, p) - example).abs().mean()) for p in (found, lines_only))
    assert error < 0.5 * error_lines_only


def test_xdog_abstraction_is_read_with_the_tone(astronaut: torch.Tensor) -> None:
    xdog, content, _, example = _example(astronaut, "xdog", 128, details=3.0, contrast=2.0, shading=0.7)
    start = _with(xdog, xdog.default_params().reshape(1, -1), details=0.5)
    at_given, tone = xdog_tones_from_shading(xdog, content, example, start)
    assert tone["details"] >= 2.25
    assert "details" not in at_given


def test_several_readings_are_judged_at_the_examples_size(
    astronaut: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    xdog, content, _, example = _example(astronaut, "xdog", 192, contrast=2.0, shading=0.7)
    judged = []
    closest = inversion.closest

    def recording(effect, content, target, candidates, loss="l2", **options):
        judged.append((content.shape[-1], len(candidates)))
        return closest(effect, content, target, candidates, loss, **options)

    monkeypatch.setattr(inversion, "closest", recording)
    read_steps(xdog, content, example, xdog.default_params().reshape(1, -1), side=64)
    assert judged[-1] == (192, 4)  # the start, the lines read, the tone read at two abstractions


def test_lines_on_white_leave_no_tone_to_read(astronaut: torch.Tensor) -> None:
    xdog, content, _, example = _example(astronaut, "xdog", 96, shading=0.0, contour=2.0)
    assert xdog_tones_from_shading(xdog, content, example, xdog.default_params().reshape(1, -1)) == []


def test_an_estimate_that_fits_worse_is_not_taken(astronaut: torch.Tensor) -> None:
    cartoon = effects.create("cartoon").eval()
    content = F.interpolate(astronaut, size=(64, 64), mode="area")
    noise = torch.rand(1, 3, 64, 64, generator=torch.Generator().manual_seed(4))  # no plateaus at all
    start = cartoon.default_params().reshape(1, -1)
    found = invert_steps(cartoon, content, noise, start)
    with torch.no_grad():
        before = float((cartoon(content, start) - noise).square().mean())
        after = float((cartoon(content, found) - noise).square().mean())
    assert after <= before


def test_effects_without_estimates_are_left_alone(astronaut: torch.Tensor) -> None:
    oil = effects.create("oilpaint").eval()
    content = F.interpolate(astronaut, size=(32, 32), mode="area")
    start = oil.default_params().reshape(1, -1)
    assert invert_steps(oil, content, content, start) is start
    assert inversion_between_levels(oil, content, content) is None


def test_coarse_to_fine_reads_the_steps_again_between_levels(astronaut: torch.Tensor) -> None:
    cartoon = effects.create("cartoon").eval()
    content = F.interpolate(astronaut, size=(64, 64), mode="area")
    start = cartoon.default_params().reshape(1, -1)
    seen: list[torch.Tensor] = []

    def hook(params: torch.Tensor) -> torch.Tensor:
        seen.append(params)
        return _with(cartoon, params, bins=3.0)

    settings = Settings(mode="global", iterations=1, lr=0.01, loss="l2")
    with torch.no_grad():
        target = cartoon(content, start)
    outcome = optimize_coarse_to_fine(
        cartoon, content, target, start, ((2, settings), (1, settings)), between_levels=hook
    )
    assert len(seen) == 1 and seen[0].shape == (1, len(cartoon.param_names))
    assert math.isclose(_real(cartoon, outcome.params, "bins"), 3.0, abs_tol=0.2)  # one small step from 3


def test_descent_holds_the_parameters_read_off_the_example(astronaut: torch.Tensor) -> None:
    from wise.optimize.parametric import optimize

    cartoon = effects.create("cartoon").eval()
    content = F.interpolate(astronaut, size=(48, 48), mode="area")
    start = cartoon.default_params().reshape(1, -1)
    with torch.no_grad():
        target = cartoon(content, cartoon.preset("bold").reshape(1, -1))
    settings = Settings(mode="global", iterations=3, lr=0.1, loss="l2", held=("bins", "contour"))
    outcome = optimize(cartoon, content, target, start, settings)
    held = [cartoon.param_names.index(name) for name in ("bins", "contour")]
    assert torch.equal(outcome.params[0, held], start[0, held])
    assert not torch.equal(outcome.params, start)  # the rest moved


def test_a_brief_descent_settles_between_candidates(astronaut: torch.Tensor) -> None:
    from wise.optimize.inversion import best_after_brief_descent

    cartoon, content, truth, example = _example(astronaut, "cartoon", 64, bins=5.0, softness=0.1, saturation=2.0)
    # the right count with the colours off, and wrong counts with them right
    candidates = [_with(cartoon, truth, bins=b) for b in (2.0, 12.0)] + [_with(cartoon, truth, saturation=1.0)]
    best = best_after_brief_descent(cartoon, content, example, candidates)
    assert _real(cartoon, best, "bins") == pytest.approx(5.0)


def test_the_bin_count_alone_is_read_within_a_quarter_on_photos_and_generated_pictures() -> None:
    from skimage import data

    effect = effects.create("cartoon").eval()
    generator = torch.Generator().manual_seed(3)
    photos = [torch.from_numpy(data.coffee()), torch.from_numpy(data.chelsea())]
    photos = [photo.permute(2, 0, 1)[None].float() / 255.0 for photo in photos]
    photos = [F.interpolate(photo, scale_factor=160 / min(photo.shape[-2:]), mode="area") for photo in photos]
    bins_values = torch.linspace(2.0, 16.0, 12)[torch.randperm(12, generator=generator)]
    hits = []
    for trial, bins in enumerate(bins_values.tolist()):
        content = dead_leaves(160, generator) if trial % 3 == 2 else photos[trial % 3]
        softness = float(torch.rand(1, generator=generator))
        truth = _with(effect, effect.default_params().reshape(1, -1), bins=bins, softness=softness)
        with torch.no_grad():
            example = effect(content, truth)
        start = _with(effect, truth, bins=8.0, softness=0.3)
        read = _real(effect, invert_steps(effect, content, example, start), "bins")
        hits.append(abs(read - bins) <= 0.25)
    assert sum(hits) >= 11, f"bins read within 0.25 in {sum(hits)} of {len(hits)} examples"


def test_steps_read_clearly_bring_the_colours_fitted_to_them(
    astronaut: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    cartoon, content, truth, example = _example(
        astronaut, "cartoon", 96, bins=5.0, softness=0.05, brightness=0.2, contrast=1.5, saturation=0.6
    )
    start = _with(cartoon, truth, bins=9.0, softness=0.5, brightness=-0.1, contrast=1.0, saturation=1.5)
    monkeypatch.setattr(inversion, "FIT_ITERATIONS", 60)
    starts, held = read_starts(cartoon, content, example, start)
    assert held == ("bins",) and len(starts) == 2  # the reading, and the reading fitted: descent decides
    read, fitted = starts
    assert torch.equal(read, read_steps(cartoon, content, example, start, search=True)[0])
    assert _real(cartoon, fitted, "bins") == pytest.approx(5.0, abs=0.1)
    with torch.no_grad():
        plain, better = (float((cartoon(content, p) - example).square().mean()) for p in (read, fitted))
    assert better < 0.5 * plain


def test_what_was_read_or_fitted_is_said() -> None:
    cartoon = effects.create("cartoon")
    before = cartoon.default_params().reshape(1, -1)
    after = _with(cartoon, before, bins=4.0, brightness=0.1)
    assert describe_estimates(cartoon, before, after) == "bins 4.00, brightness 0.10"
    assert describe_estimates(cartoon, before, before) is None


def test_unclear_steps_leave_a_second_start_with_the_colours_fitted(
    astronaut: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    cartoon, content, truth, example = _example(
        astronaut, "cartoon", 96, bins=10.0, softness=0.9, brightness=0.2, contrast=1.5, saturation=0.6
    )
    start = cartoon.default_params().reshape(1, -1)
    monkeypatch.setattr(inversion, "FIT_ITERATIONS", 60)
    monkeypatch.setattr(inversion, "SEARCH_ITERATIONS", 2)
    starts, held = read_starts(cartoon, content, example, start)
    assert held == () and len(starts) == 2
    read, fitted = starts
    colours = [cartoon.param_names.index(name) for name in COLOUR_ADJUSTMENTS]
    steps = [cartoon.param_names.index(name) for name in ("bins", "softness", "details")]
    assert not torch.equal(read[0, colours], fitted[0, colours])
    assert torch.equal(read[0, steps], fitted[0, steps])


def test_a_reading_the_fit_leaves_as_it_is_or_effects_without_a_fit_leave_one_start(
    astronaut: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    cartoon, content, _, example = _example(astronaut, "cartoon", 96, bins=5.0, softness=0.05)
    start = cartoon.default_params().reshape(1, -1)
    monkeypatch.setattr(inversion, "_COLOUR_FITS", {"cartoon": lambda effect, content, example, params: params})
    starts, held = read_starts(cartoon, content, example, start)
    assert held == ("bins",) and len(starts) == 1
    xdog, content, _, example = _example(astronaut, "xdog", 96, contour=2.0)
    starts, held = read_starts(xdog, content, example, xdog.default_params().reshape(1, -1))
    assert held == () and len(starts) == 1


def test_the_outlines_width_is_read_off_the_ink(astronaut: torch.Tensor) -> None:
    cartoon, content, truth, example = _example(astronaut, "cartoon", 128, stroke_width=1.1, contour=2.0)
    start = _with(cartoon, truth, stroke_width=0.4, contour=1.0)
    with torch.no_grad():
        read = inversion._cartoon_outlines(cartoon, content, example, start)
    step = (cartoon.spec("stroke_width").max - cartoon.spec("stroke_width").min) / (inversion.STROKE_WIDTHS - 1)
    assert read["stroke_width"] == pytest.approx(1.1, abs=step + 1e-3)  # within one width of the grid
    with torch.no_grad():
        before, after = (
            float((cartoon(content, p) - example).square().mean())
            for p in (start, inversion._with(cartoon, start, **read))
        )
    assert after < 0.5 * before


def test_more_contour_and_a_higher_threshold_darken_more(astronaut: torch.Tensor) -> None:
    cartoon, content, params, _ = _example(astronaut, "cartoon", 96)
    light = inversion.outline_darkening(cartoon, content, _with(cartoon, params, contour=0.2, blackness=0.02))
    usual = inversion.outline_darkening(cartoon, content, params)
    heavy = inversion.outline_darkening(cartoon, content, _with(cartoon, params, contour=3.0, blackness=0.5))
    assert 0.0 <= light < usual < heavy <= 1.0


def test_masks_start_from_no_more_ink_and_no_harder_steps_than_the_start_as_given(astronaut: torch.Tensor) -> None:
    cartoon, content, given, _ = _example(astronaut, "cartoon", 96)
    inky = _with(cartoon, given, bins=12.0, softness=0.0, contour=3.0, blackness=0.5, stroke_width=1.2)
    light = _with(cartoon, given, bins=3.0, softness=0.6, contour=0.1, blackness=0.01)
    kept_inky, kept_light = inversion.undoable_starts(cartoon, content, [inky, light], given)
    # the outlines and the ramps go back to the given ones, the rest of the reading stays
    assert torch.equal(kept_inky, _with(cartoon, inky, softness=0.3, contour=1.0, blackness=0.2, stroke_width=0.6))
    assert _real(cartoon, kept_inky, "bins") == pytest.approx(12.0)
    assert kept_light is light
    xdog = effects.create("xdog")
    start = xdog.default_params().reshape(1, -1)
    assert inversion.undoable_starts(xdog, content, [start], start)[0] is start


def test_the_quick_colour_fit_stops_at_its_deadline(astronaut: torch.Tensor) -> None:
    import time

    cartoon, content, truth, example = _example(
        astronaut, "cartoon", 128, bins=6.0, softness=0.05, brightness=0.15, contrast=1.6, saturation=0.5
    )
    start = _with(cartoon, truth, brightness=-0.1, contrast=1.0, saturation=1.5)
    began = time.perf_counter()
    late = colours_from_levels(cartoon, content, example, start, deadline=began)  # already past: no step
    assert torch.equal(late, start)
    assert not torch.equal(colours_from_levels(cartoon, content, example, start), start)
