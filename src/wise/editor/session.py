"""The state of one editing session: a content image, an effect and its parameter masks.

Masks are edited in the normalized parameter space at their own resolution (that of an
opened parameter file, else the preview's), so a saved file holds exactly what was painted
and ``wise apply --params`` renders it at any resolution. Every edit bumps ``version``; a
preview is rendered from a snapshot of the state, so edits never wait for a render.
Each session remembers when it was last edited, which decides whether the server may drop it
to make room for another browser (see :class:`wise.editor.app.SessionStore`).
"""

from __future__ import annotations

import contextlib
import functools
import io
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

from wise import effects
from wise.editor.brush import paint, stroke_weights
from wise.effects.base import Effect
from wise.errors import WiseError
from wise.io import decode_image_bytes, pixel_limit, tensor_to_image, write_image
from wise.paramfile import effect_of, load_params, save_params
from wise.params import clamp_edit, resize_masks, to_real
from wise.ppn.predictor import LocalPredictor
from wise.render import render, rerender

PREVIEW_SHORT_SIDE = 512
"""Short side of the preview and of the masks made for an image without a parameter file."""
QUICK_SHORT_SIDE = 192
"""Short side of the quick preview shown while the full preview of a stroke renders: a seventh
of its pixels, rendered at its own scale (the finest strokes and lines thin out), so that a
stroke shows within a fraction of a second."""
MIN_IMAGE_SIDE = 8
MAX_HISTORY = 100
"""Most undo steps kept per session (each holds one parameter's mask)."""
DEFAULT_EFFECT = "watercolor"
OVERLAY_MIN_ALPHA = 0.3
"""Opacity of the mask overlay at the middle of a parameter's range."""


class NoContent(WiseError):
    """An output was asked for before any image was opened."""


@dataclass
class Content:
    """A content image at full resolution and its preview-size copy."""

    name: str
    image: torch.Tensor
    preview: torch.Tensor

    @property
    def size(self) -> tuple[int, int]:
        return int(self.image.shape[-2]), int(self.image.shape[-1])


@dataclass
class _Change:
    """One undoable edit: a parameter's mask before and after it."""

    index: int
    before: torch.Tensor
    after: torch.Tensor


@dataclass
class Snapshot:
    """What a render needs, copied out of the session."""

    version: int
    effect: Effect
    masks: torch.Tensor
    content: Content | None


@dataclass
class _Drawn:
    """The last preview drawn: what it was drawn from, so that the next one redraws only what changed."""

    version: int
    effect: Effect
    content: Content
    masks: torch.Tensor
    result: torch.Tensor
    png: bytes


@contextlib.contextmanager
def _as_file(data: bytes, file_name: str, shown_as: str) -> Iterator[Path]:
    """``data`` as a file in a private temporary folder, for the readers that take paths (so an
    upload is read exactly as ``wise apply`` reads a file); their errors name it ``shown_as``."""
    with tempfile.TemporaryDirectory(prefix="wise-edit-") as folder:
        path = Path(folder) / file_name
        path.write_bytes(data)
        try:
            yield path
        except WiseError as e:
            raise WiseError(str(e).replace(str(path), shown_as)) from None


def _written_bytes(file_name: str, write: Callable[[Path], None]) -> bytes:
    """The bytes that ``write`` puts into a file (the writers that take paths)."""
    with tempfile.TemporaryDirectory(prefix="wise-edit-") as folder:
        path = Path(folder) / file_name
        write(path)
        return path.read_bytes()


def preview_size(size: tuple[int, int], short_side: int = PREVIEW_SHORT_SIDE) -> tuple[int, int]:
    """(rows, columns) of an image of ``size`` reduced to ``short_side`` (never enlarged)."""
    height, width = size
    factor = min(1.0, short_side / min(height, width))
    return max(1, round(height * factor)), max(1, round(width * factor))


def decode_image(data: bytes, name: str = "image") -> Content:
    """Decode uploaded image bytes (PNG, JPEG, WebP or TIFF) exactly as ``wise apply`` reads a file."""
    if not data:
        raise WiseError("the image upload is empty; choose a PNG, JPEG, WebP or TIFF file")
    image = decode_image_bytes(data, name, pixel_limit())
    height, width = image.shape[-2:]
    if min(height, width) < MIN_IMAGE_SIDE:
        raise WiseError(f"{name}: {width}x{height} pixels is too small; use at least {MIN_IMAGE_SIDE} on each side")
    small = preview_size((height, width))
    preview = image if small == (height, width) else F.interpolate(image, size=small, mode="area")
    return Content(name=name, image=image, preview=preview)


@functools.cache
def presets_by_effect() -> dict[str, list[str]]:
    """Every effect's preset names."""
    return {name: sorted(effects.create(name).presets) for name in effects.available()}


def png_bytes(image: torch.Tensor) -> bytes:
    """A ``(1, 3, H, W)`` tensor in [0, 1] as PNG bytes, written exactly as :func:`write_image` writes."""
    return _written_bytes("image.png", lambda path: write_image(image, path))


def preview_png(image: torch.Tensor) -> bytes:
    """A ``(1, 3, H, W)`` tensor in [0, 1] as PNG bytes with the fastest compression: the same
    8-bit pixels as :func:`png_bytes`, in about half the time, for previews sent every edit."""
    buffer = io.BytesIO()
    Image.fromarray(tensor_to_image(image)).save(buffer, format="PNG", compress_level=1)
    return buffer.getvalue()


def heat_map(values: torch.Tensor) -> bytes:
    """A mask ``(h, w)`` in [0, 1] as an RGBA PNG: blue (low) through white to red (high), more
    opaque towards either end of the range so that the result stays visible beneath."""
    t = values.clamp(0.0, 1.0).numpy()
    red = np.clip(2.0 * t, 0.0, 1.0)
    blue = np.clip(2.0 - 2.0 * t, 0.0, 1.0)
    green = 1.0 - np.abs(2.0 * t - 1.0)
    alpha = OVERLAY_MIN_ALPHA + (1.0 - OVERLAY_MIN_ALPHA) * np.abs(2.0 * t - 1.0)
    rgba = (np.stack([red, green, blue, alpha], axis=-1) * 255.0).round().astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(rgba).save(buffer, format="PNG")
    return buffer.getvalue()


@dataclass
class EditorSession:
    """One browser session's editing state; thread-safe."""

    effect: Effect = field(default_factory=lambda: effects.create(DEFAULT_EFFECT))
    preset: str | None = None
    content: Content | None = None
    masks: torch.Tensor = field(default_factory=lambda: torch.zeros(0))
    opened: torch.Tensor = field(default_factory=lambda: torch.zeros(0))
    masks_from_file: bool = False
    version: int = 0
    last_edit: float | None = None
    """``time.monotonic()`` of the last change made in this session; None while it is as it started."""
    notice: str | None = None
    """A message for the page about the last file opened (e.g. values clamped), sent once."""
    translator: LocalPredictor | None = None
    """A model with a CNN after the effect (``wise edit --model``): the result is the CNN's
    drawing of the effect's output, at the model's working size, while its effect is chosen."""
    _undo: list[_Change] = field(default_factory=list)
    _redo: list[_Change] = field(default_factory=list)
    _lock: threading.RLock = field(default_factory=threading.RLock)
    _drawn: _Drawn | None = None

    def __post_init__(self) -> None:
        if self.masks.numel() == 0:
            self._open_masks(self._preset_values())
            self.last_edit = None  # a new session's own start is no edit

    def copy(self) -> EditorSession:
        """A new session in this one's state, with its own effect, masks and empty history."""
        with self._lock:
            return EditorSession(
                effect=effects.create(self.effect.name),
                preset=self.preset,
                content=self.content,
                masks=self.masks.clone(),
                opened=self.opened.clone(),
                masks_from_file=self.masks_from_file,
                notice=self.notice,
                translator=self.translator,
            )

    def use_translator(self, translator: LocalPredictor) -> None:
        """Render through ``translator``'s CNN (refused for a model of another effect or without a CNN)."""
        if not translator.translates or translator.network.post is None:
            raise WiseError(f"{translator.info.source}: not a model with a CNN after the effect; leave out --model")
        if translator.info.effect != self.effect.name:
            raise WiseError(
                f"{translator.info.source}: a model of {translator.info.effect!r}, the masks are of "
                f"{self.effect.name!r}; open its own masks (from 'wise predict') with --params"
            )
        self.translator = translator

    def _stylize(self, effect: Effect, image: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        """The effect's rendering of ``image``, or with a translator of this effect, its drawing."""
        if self.translator is not None and self.translator.info.effect == effect.name:
            return self.translator.finish(image, masks).result
        return render(effect.eval(), image, masks)

    # ----- opening -------------------------------------------------------------------------

    def _mask_size(self) -> tuple[int, int]:
        if self.content is not None:
            return preview_size(self.content.size)
        return (PREVIEW_SHORT_SIDE, PREVIEW_SHORT_SIDE)

    def _preset_values(self) -> torch.Tensor:
        if self.preset is None:
            return self.effect.default_params()
        return self.effect.preset(self.preset)

    def _open_masks(self, params: torch.Tensor) -> None:
        """Start editing ``params`` ((P,) global or (1, P, h, w) masks): history cleared."""
        if params.dim() == 1:
            params = params.view(1, -1, 1, 1).expand(1, -1, *self._mask_size())
        self.masks = params.detach().to(torch.float32).clone().contiguous()
        self.opened = self.masks.clone()
        self._undo.clear()
        self._redo.clear()
        self._changed()

    def _changed(self) -> None:
        self.version += 1
        self.last_edit = time.monotonic()

    def has_edits(self, since: float = float("-inf")) -> bool:
        """Whether this session was changed (opened a file, painted, ...) at ``since`` or later."""
        with self._lock:
            return self.last_edit is not None and self.last_edit >= since

    def open_image(self, data: bytes, name: str = "image") -> None:
        """Open a content image. Masks from a parameter file stay as they are (a render resizes
        them); others are resized to the new preview size, which clears the history."""
        content = decode_image(data, name)
        with self._lock:
            self.content = content
            if not self.masks_from_file and tuple(self.masks.shape[-2:]) != self._mask_size():
                opened = resize_masks(self.opened, self._mask_size())
                self._open_masks(resize_masks(self.masks, self._mask_size()))
                self.opened = opened
            else:
                self._changed()

    def open_params(self, data: bytes, name: str = "params") -> None:
        """Open a parameter file (as written by ``wise optimize`` or this editor) for its effect;
        what the reader noted about it (e.g. clamped values) becomes the :attr:`notice`."""
        if not data:
            raise WiseError("the parameter file upload is empty; choose a .safetensors file from wise optimize")
        notes: list[str] = []
        with _as_file(data, "params.safetensors", name) as path:
            effect = effects.create(effect_of(path))
            params = load_params(path, effect, notes)
            notice = " ".join(note.replace(str(path), name) for note in notes) or None
        with self._lock:
            self.effect, self.preset = effect, None
            self._open_masks(params[0] if params.dim() == 2 else params)
            self.masks_from_file = params.dim() == 4
            self.notice = notice

    def choose_effect(self, name: str, preset: str | None = None) -> None:
        """Switch to an effect (and preset): global values in fresh masks."""
        effect = effects.create(name)
        if preset is not None:
            effect.preset(preset)  # unknown names fail before anything changes
        with self._lock:
            self.effect, self.preset = effect, preset
            self.masks_from_file = False
            self._open_masks(self._preset_values())

    # ----- edits -----------------------------------------------------------------------------

    def _index(self, param: str) -> int:
        self.effect.spec(param)
        return self.effect.param_names.index(param)

    def _commit(self, index: int, after: torch.Tensor) -> None:
        before = self.masks[0, index].clone()
        if torch.equal(before, after):
            return
        self.masks[0, index] = after
        self._undo.append(_Change(index, before, after.clone()))
        del self._undo[:-MAX_HISTORY]
        self._redo.clear()
        self._changed()

    def set_global(self, param: str, value: float) -> None:
        """Offset a parameter's whole mask so that its mean is ``value`` (real units)."""
        with self._lock:
            index = self._index(param)
            spec = self.effect.param_specs[index]
            if not spec.in_range(value):
                raise WiseError(f"{param}: {value} is outside its range [{spec.min:g}, {spec.max:g}]")
            mask = self.masks[0, index]
            shifted = mask + (spec.to_normalized(value) - float(mask.mean()))
            self._commit(index, clamp_edit(shifted, mask))

    def stroke(
        self,
        param: str,
        points: Sequence[Sequence[float]],
        radius: float,
        hardness: float,
        mode: str,
        amount: float = 0.25,
        value: float | None = None,
    ) -> None:
        """Paint a stroke on a parameter's mask.

        ``increase`` / ``decrease`` change it by ``amount`` (fraction of the range) at the
        stroke's centre; ``set`` paints ``value`` (real units).
        """
        with self._lock:
            index = self._index(param)
            spec = self.effect.param_specs[index]
            if mode == "set":
                if value is None or not spec.in_range(value):
                    raise WiseError(f"{param}: 'set' needs a value in [{spec.min:g}, {spec.max:g}], got {value}")
                target = spec.to_normalized(value)
            else:
                if not 0.0 < amount <= 1.0:
                    raise WiseError(f"brush amount must be above 0 and at most 1 (the whole range), got {amount}")
                target = amount
            weights = stroke_weights(tuple(self.masks.shape[-2:]), points, radius, hardness)
            self._commit(index, paint(self.masks[0, index], weights, mode, target))

    def reset(self, param: str) -> None:
        """A parameter back to its values when the image, effect or file was opened."""
        with self._lock:
            index = self._index(param)
            self._commit(index, self.opened[0, index].clone())

    def undo(self) -> None:
        with self._lock:
            change = self._move(self._undo, self._redo, "undo")
            self.masks[0, change.index] = change.before

    def redo(self) -> None:
        with self._lock:
            change = self._move(self._redo, self._undo, "redo")
            self.masks[0, change.index] = change.after

    def _move(self, source: list[_Change], target: list[_Change], what: str) -> _Change:
        if not source:
            raise WiseError(f"nothing to {what}")
        target.append(source.pop())
        self._changed()
        return target[-1]

    # ----- output ----------------------------------------------------------------------------

    def snapshot(self) -> Snapshot:
        with self._lock:
            return Snapshot(self.version, self.effect, self.masks.clone(), self.content)

    def _require_content(self, snapshot: Snapshot) -> Content:
        if snapshot.content is None:
            raise NoContent("no image is open yet: open an image first")
        return snapshot.content

    def render_preview(self, snapshot: Snapshot) -> bytes:
        """The stylized preview of a snapshot as PNG.

        After a stroke only the part of the last preview that the painted region reaches is
        drawn again (:func:`wise.render.rerender`); a snapshot of the state last drawn is not
        drawn again. Callers render one preview at a time (the server's render lock).
        """
        content = self._require_content(snapshot)
        drawn = self._drawn
        if drawn is not None and (drawn.version, drawn.effect, drawn.content) == (
            snapshot.version,
            snapshot.effect,
            content,
        ):
            return drawn.png
        if self.translator is not None and self.translator.info.effect == snapshot.effect.name:
            made = self._stylize(snapshot.effect, content.preview, snapshot.masks)
            if made.shape[-2:] != content.preview.shape[-2:]:
                made = F.interpolate(made, size=content.preview.shape[-2:], mode="bilinear", align_corners=False)
            return preview_png(made.clamp(0.0, 1.0))
        effect = snapshot.effect.eval()
        if drawn is not None and drawn.effect is snapshot.effect and drawn.content is content:
            made = rerender(effect, content.preview, snapshot.masks, drawn.masks, drawn.result)
        else:
            made = render(effect, content.preview, snapshot.masks)
        png = preview_png(made.clamp(0.0, 1.0))
        self._drawn = _Drawn(snapshot.version, snapshot.effect, content, snapshot.masks, made, png)
        return png

    def render_quick(self, snapshot: Snapshot) -> bytes:
        """A quick, reduced preview of a snapshot as PNG (:data:`QUICK_SHORT_SIDE`): the look of
        the full preview at a glance, while that one renders; the full preview is drawn as
        before. A translator's preview is drawn in full."""
        content = self._require_content(snapshot)
        if self.translator is not None and self.translator.info.effect == snapshot.effect.name:
            return self.render_preview(snapshot)
        small = preview_size(tuple(content.preview.shape[-2:]), QUICK_SHORT_SIDE)
        image = (
            content.preview
            if small == tuple(content.preview.shape[-2:])
            else F.interpolate(content.preview, size=small, mode="area")
        )
        made = render(snapshot.effect.eval(), image, snapshot.masks, at_reference=False)
        return preview_png(made.clamp(0.0, 1.0))

    def content_preview(self) -> bytes:
        content = self._require_content(self.snapshot())
        return preview_png(content.preview)

    def render_full(self, snapshot: Snapshot) -> bytes:
        """The result at the content's full resolution as PNG: the pixels ``wise apply --params`` writes
        (with a translator, at its model's working size: those of ``wise apply --params --model``)."""
        content = self._require_content(snapshot)
        return png_bytes(self._stylize(snapshot.effect, content.image, snapshot.masks))

    def params_file(self) -> bytes:
        """The masks as a parameter file (safetensors bytes)."""
        snapshot = self.snapshot()
        return _written_bytes("params.safetensors", lambda path: save_params(path, snapshot.effect, snapshot.masks))

    def mask_image(self, param: str) -> bytes:
        """A parameter's mask as a heat map over its declared range (PNG)."""
        with self._lock:
            mask = self.masks[0, self._index(param)].clone()
        return heat_map(mask + 0.5)

    def describe(self) -> dict[str, object]:
        """The state as JSON-ready data for the page."""
        with self._lock:
            real = to_real(self.masks, self.effect.param_specs)[0]
            params = [
                {
                    "name": spec.name,
                    "description": spec.description,
                    "min": spec.min,
                    "max": spec.max,
                    "default": spec.default,
                    "mean": float(real[i].mean()),
                    "low": float(real[i].min()),
                    "high": float(real[i].max()),
                }
                for i, spec in enumerate(self.effect.param_specs)
            ]
            content = None
            if self.content is not None:
                height, width = self.content.size
                preview_h, preview_w = self.content.preview.shape[-2:]
                content = {"name": self.content.name, "width": width, "height": height}
                content.update({"preview_width": int(preview_w), "preview_height": int(preview_h)})
            notice, self.notice = self.notice, None
            return {
                "version": self.version,
                "effect": self.effect.name,
                "preset": self.preset,
                "effects": presets_by_effect(),
                "content": content,
                "mask_size": list(self.masks.shape[-2:]),
                "params": params,
                "can_undo": bool(self._undo),
                "can_redo": bool(self._redo),
                "notice": notice,
            }
