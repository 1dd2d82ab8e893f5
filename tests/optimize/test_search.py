import pytest
import torch
import torch.nn.functional as F

from wise import effects
from wise.errors import WiseError
from wise.optimize.search import coordinate_search


def test_search_finds_a_parameter_whose_gradient_vanishes_at_the_start(astronaut: torch.Tensor) -> None:
    watercolor = effects.create("watercolor").eval()
    content = F.interpolate(astronaut, size=(96, 96), mode="area")
    index = watercolor.param_names.index("bleeding")
    truth = watercolor.default_params().reshape(1, -1).clone()
    truth[0, index] = 0.25
    with torch.no_grad():
        target = watercolor(content, truth)
    start = truth.clone()
    start[0, index] = -0.5  # no bleeding: the bound where descent stops
    start.requires_grad_(True)
    (watercolor(content, start) - target).square().mean().backward()
    assert abs(float(start.grad[0, index])) < 1e-7  # a symmetric blur of reach 0: no gradient
    found, loss = coordinate_search(watercolor, content, target, start.detach(), ("bleeding",), values=5, passes=1)
    assert float(found[0, index]) == pytest.approx(0.25)
    assert loss < 1e-10
    others = torch.cat((found[0, :index], found[0, index + 1 :]))
    assert torch.equal(others, torch.cat((truth[0, :index], truth[0, index + 1 :])))


def test_search_keeps_the_start_when_no_grid_value_is_better(astronaut: torch.Tensor) -> None:
    xdog = effects.create("xdog").eval()
    content = F.interpolate(astronaut, size=(48, 48), mode="area")
    start = xdog.default_params().reshape(1, -1)
    with torch.no_grad():
        target = xdog(content, start)
    found, loss = coordinate_search(xdog, content, target, start, ("contour",), values=4, passes=1)
    assert torch.equal(found, start) and loss == 0.0


def test_search_refuses_what_it_cannot_do(astronaut: torch.Tensor) -> None:
    xdog = effects.create("xdog")
    content = F.interpolate(astronaut, size=(32, 32), mode="area")
    start = xdog.default_params().reshape(1, -1)
    with pytest.raises(WiseError, match="xdog has no parameter bleeding; use"):
        coordinate_search(xdog, content, content, start, ("bleeding",))
    with pytest.raises(WiseError, match="at least 2 values"):
        coordinate_search(xdog, content, content, start, ("contour",), values=1)
    with pytest.raises(WiseError, match="differ in size"):
        coordinate_search(xdog, content, content[..., :16], start, ("contour",))


def test_watercolor_names_the_parameters_the_gradient_misses() -> None:
    watercolor = effects.create("watercolor")
    assert set(watercolor.searched_params) <= set(watercolor.param_names)
    assert "bleeding" in watercolor.searched_params
