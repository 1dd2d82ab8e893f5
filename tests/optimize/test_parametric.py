import pytest
import torch
import torch.nn.functional as F

import wise
from wise.errors import WiseError
from wise.optimize import Settings, optimize


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
    assert outcome.params.min() >= -0.5 and outcome.params.max() <= 0.5


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
    for bad in ({"mode": "x"}, {"loss": "x"}, {"iterations": 0}, {"lr": 0.0}, {"tv_weight": -1.0}):
        with pytest.raises(WiseError):
            Settings(**bad)
