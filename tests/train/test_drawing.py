"""The synthetic artist of ``wise data drawing`` and its paired sets."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
import torch

from tests.images import astronaut_png
from wise.errors import WiseError
from wise.io import read_image
from wise.train.adaptive import load_photos
from wise.train.choices import DESCRIPTION_FILE
from wise.train.drawing import HATCH_INK, OUTLINE_INK, draw, hatch_lines
from wise.train.drawing_pairs import DrawingSettings, write_drawing_pairs


def _flat(value: float, size: int = 128) -> torch.Tensor:
    return torch.full((1, 3, size, size), value)


def test_bright_paper_stays_white_and_the_drawing_is_grey() -> None:
    drawing = draw(_flat(0.9))
    assert torch.equal(drawing, torch.ones_like(drawing))
    noisy = draw(torch.rand(2, 3, 64, 80))
    assert noisy.shape == (2, 3, 64, 80)
    assert torch.equal(noisy[:, 0], noisy[:, 1]) and torch.equal(noisy[:, 1], noisy[:, 2])


def test_darker_tones_get_more_directions_of_hatching() -> None:
    inked = [float((draw(_flat(tone)) < 1.0).float().mean()) for tone in (0.9, 0.4, 0.25, 0.05)]
    assert inked[0] == 0.0
    assert inked[0] < inked[1] < inked[2] < inked[3]
    dark = draw(_flat(0.05, size=512))
    assert float(dark.min()) == pytest.approx(HATCH_INK, abs=1e-4), "hatching ink, no outlines on a flat photo"
    lines = hatch_lines(128, 128, 45.0, 11.0, dark)[0, 0]
    assert torch.allclose(lines[:-1, 1:], lines[1:, :-1], atol=1e-4), "45° lines: constant along the diagonal"


def test_edges_are_drawn_as_thick_dark_outlines() -> None:
    photo = _flat(0.9)
    photo[..., 64:] = 0.6
    drawing = draw(photo)[0, 0]
    row = drawing[64]
    dark = (row <= OUTLINE_INK + 1e-4).nonzero().flatten()
    assert len(dark) >= 3, "a stroke several pixels wide"
    assert int(dark.min()) >= 56 and int(dark.max()) <= 71, "at the edge"
    assert float(drawing[:, :40].min()) == 1.0, "and nothing on the flat bright part"


def test_drawing_pairs_are_split_by_photo_and_described(tmp_path: Path) -> None:
    photos_dir = tmp_path / "photos"
    photos_dir.mkdir()
    for index in range(3):
        astronaut_png(photos_dir / f"p{index}.png", 96 + 8 * index, 80)
    photos, _ = load_photos(photos_dir, 32)
    settings = DrawingSettings(count=9, size=32, test_share=0.34, seed=3)
    summary = write_drawing_pairs(tmp_path / "pairs", settings, photos, out=io.StringIO())
    description = json.loads((tmp_path / "pairs" / DESCRIPTION_FILE).read_text())
    assert summary["pairs"] == description["pairs"] and sum(description["pairs"].values()) == 9
    assert not set(description["train_photos"]) & set(description["test_photos"])
    for split in ("train", "test"):
        names_a = sorted(p.name for p in (tmp_path / "pairs" / split / "A").iterdir())
        names_b = sorted(p.name for p in (tmp_path / "pairs" / split / "B").iterdir())
        assert names_a == names_b and len(names_a) == description["pairs"][split]
    name = names_a[0]
    photo, drawing = (read_image(tmp_path / "pairs" / "test" / f / name) for f in ("A", "B"))
    assert photo.shape == drawing.shape == (1, 3, 32, 32)
    assert torch.allclose(drawing, draw(photo), atol=1 / 255 + 1e-6), "the target is the artist's drawing"
    again = write_drawing_pairs(tmp_path / "again", settings, photos, out=io.StringIO())
    assert again["pairs"] == summary["pairs"]
    assert (tmp_path / "again" / "test" / "A" / name).read_bytes() == (
        tmp_path / "pairs" / "test" / "A" / name
    ).read_bytes(), "the same seed makes the same crops"


def test_drawing_settings_are_checked() -> None:
    with pytest.raises(WiseError, match="test share"):
        DrawingSettings(test_share=1.0).check()
    with pytest.raises(WiseError, match="count must be a whole number of at least 2"):
        DrawingSettings(count=1).check()
