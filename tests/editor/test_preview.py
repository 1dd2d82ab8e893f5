"""Previews after a stroke redraw only what the stroke reaches, and equal a preview drawn whole."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from skimage import data

from wise.editor import session as session_module
from wise.editor.session import EditorSession


def _png(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="PNG")
    return buffer.getvalue()


def _decode(content: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(content))).astype(np.int16)


@pytest.mark.parametrize(("effect", "param"), [("xdog", "shading"), ("watercolor", "contour")])
def test_a_stroke_redraws_part_of_the_preview_and_matches_a_whole_one(
    effect: str, param: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # at the reference size: a smaller preview is rendered whole, at the reference scale
    photo = _png(np.asarray(Image.fromarray(data.astronaut()).resize((640, 512), Image.BICUBIC)))
    session = EditorSession()
    session.choose_effect(effect)
    session.open_image(photo, "astronaut.png")
    session.render_preview(session.snapshot())
    session.stroke(param, [[0.15, 0.25], [0.2, 0.3]], radius=0.03, hardness=0.5, mode="increase", amount=0.5)

    drawn_sizes = []
    original = session_module.rerender

    def spy(effect, image, params, before, rendered):
        out = original(effect, image, params, before, rendered)
        drawn_sizes.append(int((out != rendered).any(dim=1).sum()))
        return out

    monkeypatch.setattr(session_module, "rerender", spy)
    snapshot = session.snapshot()
    updated = _decode(session.render_preview(snapshot))
    assert session.render_preview(snapshot) is session.render_preview(session.snapshot())  # the same state: no redraw

    fresh = session.copy()
    whole = _decode(fresh.render_preview(fresh.snapshot()))
    difference = np.abs(updated - whole)
    assert difference.mean() < 0.05 and (difference > 12).mean() < 1e-3
    assert len(drawn_sizes) == 1 and 0 < drawn_sizes[0] < 0.5 * 512 * 640
