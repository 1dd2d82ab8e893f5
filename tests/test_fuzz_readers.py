"""Fuzzing the readers: random and mutated files give a WiseError or a result, never another exception or a warning."""

from __future__ import annotations

import io
import logging
import struct
import tempfile
import warnings
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import pytest
import tifffile
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image
from skimage import data as samples

from wise import effects
from wise.errors import WiseError
from wise.io import decode_image_bytes, read_image
from wise.paramfile import load_params, save_params


def fuzz(examples: int) -> settings:
    """Deterministic Hypothesis settings for CI: derandomized, no example database, no deadline."""
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    )


MAX_PIXELS = 1_000_000
"""Keeps decoding of mutated sizes fast; the limit itself is tested in test_io."""
HEADER_BYTES = 64
"""Mutations land in the first bytes (headers, where the sizes are) half of the time."""


def _photo() -> np.ndarray:
    return np.asarray(Image.fromarray(samples.astronaut()).resize((24, 16), Image.Resampling.BILINEAR))


def _encoded(array: np.ndarray, **options: object) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, **options)
    return buffer.getvalue()


def _png16() -> bytes:
    import png

    rgba = (np.arange(16 * 24 * 4, dtype=np.uint32).reshape(16, 24 * 4) * 677 % 65536).astype(np.uint16)
    buffer = io.BytesIO()
    png.Writer(24, 16, bitdepth=16, greyscale=False, alpha=True).write(buffer, rgba.tolist())
    return buffer.getvalue()


def _tiff(array: np.ndarray, **options: object) -> bytes:
    buffer = io.BytesIO()
    tifffile.imwrite(buffer, array, **options)
    return buffer.getvalue()


PHOTO = _photo()
IMAGES = {
    "png": _encoded(PHOTO, format="PNG"),
    "jpeg": _encoded(PHOTO, format="JPEG", quality=80),
    "webp": _encoded(PHOTO, format="WEBP", lossless=True),
    "tiff": _encoded(PHOTO, format="TIFF"),
    "png16": _png16(),
    "tiff16": _tiff((PHOTO.astype(np.uint16) * 257), photometric="rgb", compression="zlib"),
    "tiff-float": _tiff(PHOTO.astype(np.float32) / 255, photometric="rgb"),
}


def _params() -> dict[str, bytes]:
    xdog = effects.create("xdog")
    files = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, params in (("global", xdog.preset("portrait")), ("local", torch.rand(len(xdog.param_specs), 3, 2))):
            path = Path(folder) / f"{name}.safetensors"
            save_params(path, xdog, params, space="real" if name == "local" else "normalized")
            files[name] = path.read_bytes()
    return files


PARAMS = _params()


@pytest.fixture(scope="module")
def folder() -> Iterator[Path]:
    with tempfile.TemporaryDirectory() as name:
        yield Path(name)


class Records(logging.Handler):
    """Collects log records (a decoder logging an error would print it)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


def only_wise_errors(call: Callable[[], object]) -> None:
    """``call`` succeeds or raises WiseError (one line), and neither warns nor logs anything."""
    logs = Records()
    root = logging.getLogger()
    root.addHandler(logs)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                call()
            except WiseError as e:
                assert "\n" not in str(e)
    finally:
        root.removeHandler(logs)
    assert [f"{w.category.__name__}: {w.message}" for w in caught] == []
    assert [f"{r.name}: {r.getMessage()}" for r in logs.records if r.levelno >= logging.WARNING] == []


position = st.one_of(st.integers(0, HEADER_BYTES - 1), st.integers(0, 1 << 20))
operation = st.tuples(st.sampled_from(["flip", "insert", "delete", "truncate"]), position, st.integers(1, 255))


def mutate(data: bytes, operations: list[tuple[str, int, int]]) -> bytes:
    """``data`` with bytes flipped, inserted, deleted or cut off at the given positions."""
    out = bytearray(data)
    for kind, where, value in operations:
        at = where % (len(out) + 1)
        if kind == "flip" and at < len(out):
            out[at] ^= value
        elif kind == "insert":
            out[at:at] = bytes([value]) * (value % 7 + 1)
        elif kind == "delete":
            del out[at : at + value % 16 + 1]
        elif kind == "truncate":
            del out[at:]
    return bytes(out)


def check_image(folder: Path, data: bytes) -> None:
    path = folder / "fuzz.img"
    path.write_bytes(data)
    only_wise_errors(lambda: read_image(path, max_pixels=MAX_PIXELS))
    only_wise_errors(lambda: decode_image_bytes(data, "upload", max_pixels=MAX_PIXELS))


def check_params(folder: Path, data: bytes) -> None:
    path = folder / "fuzz.safetensors"
    path.write_bytes(data)
    only_wise_errors(lambda: load_params(path, effects.create("xdog"), notes=[]))


def test_the_seed_files_are_read(folder: Path) -> None:
    for data in IMAGES.values():
        assert decode_image_bytes(data, "seed").shape == (1, 3, 16, 24)
    for data in PARAMS.values():
        check_params(folder, data)


@fuzz(300)
@given(data=st.binary(max_size=512))
def test_random_bytes_as_images(folder: Path, capfd: pytest.CaptureFixture[str], data: bytes) -> None:
    check_image(folder, data)
    assert capfd.readouterr() == ("", "")


@fuzz(1500)
@given(kind=st.sampled_from(sorted(IMAGES)), operations=st.lists(operation, min_size=1, max_size=6))
def test_mutated_images(
    folder: Path, capfd: pytest.CaptureFixture[str], kind: str, operations: list[tuple[str, int, int]]
) -> None:
    check_image(folder, mutate(IMAGES[kind], operations))
    assert capfd.readouterr() == ("", "")  # nothing printed, not even by the C libraries


@fuzz(300)
@given(length=st.integers(0, 600), rest=st.binary(max_size=600))
def test_random_bytes_as_params(folder: Path, length: int, rest: bytes) -> None:
    check_params(folder, struct.pack("<Q", length) + rest)


@fuzz(800)
@given(kind=st.sampled_from(sorted(PARAMS)), operations=st.lists(operation, min_size=1, max_size=6))
def test_mutated_params(folder: Path, kind: str, operations: list[tuple[str, int, int]]) -> None:
    check_params(folder, mutate(PARAMS[kind], operations))
