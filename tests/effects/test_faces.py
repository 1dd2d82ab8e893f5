"""Faces keep their light and their features in every oil paint and watercolor preset
(the measures of benchmarks/bench_faces.py, on the astronaut's face)."""

import pytest
import torch
from skimage import data

import wise
from wise.io import image_to_tensor, tensor_to_image
from wise.metrics import face_measures
from wise.render import render

ASTRONAUT_FACE = (40, 175, 165, 285)


@pytest.fixture(scope="module")
def photo() -> torch.Tensor:
    return image_to_tensor(data.astronaut())


def _measures(name: str, preset: str, photo: torch.Tensor) -> dict[str, float]:
    effect = wise.effects.create(name).eval()
    rendered = tensor_to_image(render(effect, photo, effect.preset(preset)[None]))
    return face_measures(rendered, tensor_to_image(photo), ASTRONAUT_FACE)


@pytest.mark.parametrize("preset", ["impasto", "glaze", "knife"])
def test_oil_paint_shades_a_face_without_bleaching_it(preset: str, photo: torch.Tensor) -> None:
    measured = _measures("oilpaint", preset, photo)
    assert measured["blown"] <= 0.02
    assert abs(measured["shift"]) <= 5.0
    assert measured["contrast"] >= 0.85


@pytest.mark.parametrize("preset", ["wet", "dry", "pale"])
def test_watercolor_keeps_the_features_of_a_face(preset: str, photo: torch.Tensor) -> None:
    assert _measures("watercolor", preset, photo)["contrast"] >= 0.85


def test_face_measures_see_a_washed_out_face() -> None:
    photo = tensor_to_image(image_to_tensor(data.astronaut()))
    washed = (photo.astype(float) * 0.3 + 255 * 0.7).astype("uint8")
    measured = face_measures(washed, photo, ASTRONAUT_FACE)
    assert measured["blown"] > 0.05 and measured["shift"] > 15 and measured["contrast"] < 0.5
    assert face_measures(photo, photo, ASTRONAUT_FACE) == {"blown": 0.0, "shift": 0.0, "contrast": 1.0}
