import pytest
import torch

from wise import params as P
from wise.errors import WiseError
from wise.params import ParamSpec

SPECS = (ParamSpec("a", 0.0, 2.0, 0.5), ParamSpec("b", -1.0, 1.0, 0.0), ParamSpec("c", 10.0, 20.0, 12.0))


def test_normalized_space_maps_ranges_linearly() -> None:
    real = torch.tensor([[0.0, -1.0, 10.0], [2.0, 1.0, 20.0], [1.0, 0.0, 15.0]])
    normalized = P.to_normalized(real, SPECS)
    assert torch.allclose(normalized[0], torch.full((3,), -0.5))
    assert torch.allclose(normalized[1], torch.full((3,), 0.5))
    assert torch.allclose(normalized[2], torch.zeros(3))
    assert torch.allclose(P.to_real(normalized, SPECS), real)


def test_masks_convert_per_pixel() -> None:
    masks = torch.rand(2, 3, 4, 5) - 0.5
    assert torch.allclose(P.to_normalized(P.to_real(masks, SPECS), SPECS), masks, atol=1e-6)


def test_dict_round_trip_and_defaults() -> None:
    tensor = P.from_dict(SPECS, {"b": 0.5})
    values = P.to_dict(SPECS, tensor)
    assert values == pytest.approx({"a": 0.5, "b": 0.5, "c": 12.0})
    with pytest.raises(WiseError, match="unknown parameter"):
        P.from_dict(SPECS, {"nope": 1.0})


def test_values_outside_the_range_extrapolate() -> None:
    spec = SPECS[0]
    assert spec.to_normalized(3.0) == pytest.approx(1.0)
    assert not spec.in_range(3.0)


def test_check_params_shapes() -> None:
    assert P.check_params(torch.zeros(3), SPECS, 2).shape == (2, 3)
    assert P.check_params(torch.zeros(1, 3, 4, 4), SPECS, 2).shape == (2, 3, 4, 4)
    for bad in (torch.zeros(2, 4), torch.zeros(2, 3, 4), torch.zeros(3, 3)):
        with pytest.raises(WiseError):
            P.check_params(bad, SPECS, 2)


def test_masks_resize_to_the_image() -> None:
    masks = torch.rand(1, 3, 8, 8) - 0.5
    maps = P.real_maps(masks, SPECS, (32, 32))
    assert maps["a"].shape == (1, 1, 32, 32)
    global_maps = P.real_maps(torch.zeros(1, 3), SPECS, (32, 32))
    assert global_maps["c"].shape == (1, 1, 1, 1) and float(global_maps["c"]) == pytest.approx(15.0)


def test_mask_bounds_widen_to_each_reach_and_clamp_in_place() -> None:
    specs = (ParamSpec("a", 0.0, 2.0, 0.5, reach=(-2.0, 4.0)), ParamSpec("b", -1.0, 1.0, 0.0))
    low, high = P.mask_bounds(specs, torch.zeros(()))
    assert low.flatten().tolist() == pytest.approx([-1.5, -0.5]) and high.flatten().tolist() == pytest.approx(
        [1.5, 0.5]
    )
    masks = torch.tensor([-3.0, 3.0, -3.0, 3.0]).view(1, 2, 1, 2)
    assert P.clamp_masks(masks, specs) is masks
    assert masks.flatten().tolist() == pytest.approx([-1.5, 1.5, -0.5, 0.5])


def test_a_reach_must_contain_the_range() -> None:
    with pytest.raises(ValueError, match="reach"):
        ParamSpec("a", 0.0, 2.0, 0.5, reach=(0.5, 4.0))


def test_an_edit_moves_a_value_outside_the_range_back_towards_it_but_never_further_out() -> None:
    before = torch.tensor([-1.2, -1.2, 0.3, 0.3, 0.8])
    edited = torch.tensor([-1.5, -0.9, 0.7, -0.7, 0.6])
    assert P.clamp_edit(edited, before).tolist() == pytest.approx([-1.2, -0.9, 0.5, -0.5, 0.6])
