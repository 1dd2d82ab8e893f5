"""Shared file checks: regular files of bounded size, safetensors headers checked before any data is read."""

from __future__ import annotations

import json
import os
import struct
import time
from pathlib import Path
from typing import Callable

import pytest
import torch
from safetensors.torch import save, save_file

from wise.errors import WiseError
from wise.files import (
    MAX_HEADER_BYTES,
    check_size,
    open_regular,
    read_safetensors,
    read_safetensors_header,
    regular_file,
)

LIMIT = 1000
FAST_SECONDS = 1.0


def refused(call: Callable[[], object], path: Path | str, *words: str) -> str:
    """The one-line message of the WiseError that ``call`` raises, fast, naming ``path`` and ``words``."""
    start = time.perf_counter()
    with pytest.raises(WiseError) as info:
        call()
    assert time.perf_counter() - start < FAST_SECONDS
    message = str(info.value)
    assert "\n" not in message and str(path) in message and ";" in message, message
    for word in words:
        assert word in message, message
    return message


def test_a_regular_file_passes(tmp_path: Path) -> None:
    path = tmp_path / "a.bin"
    path.write_bytes(b"x" * LIMIT)
    assert regular_file(str(path), "parameter file", LIMIT) == path
    with open_regular(path, "parameter file", LIMIT) as f:
        assert f.read() == b"x" * LIMIT


def test_missing_directory_and_loops(tmp_path: Path) -> None:
    refused(lambda: regular_file(tmp_path / "none", "image", LIMIT), tmp_path / "none", "no such file", "image")
    refused(lambda: regular_file(tmp_path, "parameter file", LIMIT), tmp_path, "is a directory", "a parameter file")
    (tmp_path / "dangling").symlink_to(tmp_path / "gone")
    refused(lambda: regular_file(tmp_path / "dangling", "image", LIMIT), tmp_path / "dangling", "broken symbolic link")
    (tmp_path / "one").symlink_to(tmp_path / "two")
    (tmp_path / "two").symlink_to(tmp_path / "one")
    refused(lambda: regular_file(tmp_path / "one", "model file", LIMIT), tmp_path / "one", "loop of symbolic links")
    (tmp_path / "file").write_bytes(b"x")
    refused(lambda: regular_file(tmp_path / "file" / "x", "image", LIMIT), tmp_path / "file" / "x", "no such file")


def test_special_files_are_refused_without_opening(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for call in (regular_file, open_regular, read_safetensors, read_safetensors_header):
        refused(lambda: call(fifo, "parameter file", LIMIT), fifo, "named pipe (FIFO)", "not a regular file")
        refused(lambda: call("/dev/zero", "model file", LIMIT), "/dev/zero", "character device", "not a regular file")


def test_empty_large_and_unreadable_files(tmp_path: Path) -> None:
    (tmp_path / "empty").write_bytes(b"")
    refused(lambda: regular_file(tmp_path / "empty", "image", LIMIT), tmp_path / "empty", "empty")
    (tmp_path / "big").write_bytes(b"x" * 2_500_001)
    refused(lambda: regular_file(tmp_path / "big", "image", 2_000_000), tmp_path / "big", "2.5 MB", "limit of 2 MB")
    with pytest.raises(WiseError, match="upload.png: the file is empty"):
        check_size(0, "upload.png", "image", LIMIT)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files regardless of their permissions")
def test_unreadable_file(tmp_path: Path) -> None:
    locked = tmp_path / "locked"
    locked.write_bytes(b"x")
    locked.chmod(0)
    refused(lambda: regular_file(locked, "image", LIMIT), locked, "permission denied")


def header_file(path: Path, header: bytes, data: bytes = b"", length: int | None = None) -> Path:
    """A file of a header length, a header and data, written byte by byte."""
    path.write_bytes(struct.pack("<Q", len(header) if length is None else length) + header + data)
    return path


def not_safetensors(path: Path, *words: str) -> None:
    for call in (read_safetensors, read_safetensors_header):
        refused(lambda: call(path, "parameter file", 10**9), path, "not a safetensors file", *words)


def test_header_length_checked_before_reading(tmp_path: Path) -> None:
    (tmp_path / "short").write_bytes(b"\x01\x02\x03")
    not_safetensors(tmp_path / "short", "shorter than the 8-byte header length")
    not_safetensors(header_file(tmp_path / "zero", b"{}", length=0), "header length is 0")
    not_safetensors(header_file(tmp_path / "long", b"{}", length=3), "more than the 2 bytes after it")
    not_safetensors(header_file(tmp_path / "huge", b"{}", length=2**63), "header length 9223372036854775808")
    not_safetensors(header_file(tmp_path / "max", b"{}", length=2**64 - 1), "header length")
    big = b"{" + b" " * MAX_HEADER_BYTES + b"}"
    not_safetensors(header_file(tmp_path / "cap", big), "limit of")


def entry(dtype: str = "F32", shape: object = (2,), offsets: object = (0, 8)) -> dict[str, object]:
    return {"dtype": dtype, "shape": list(shape) if isinstance(shape, tuple) else shape, "data_offsets": offsets}


@pytest.mark.parametrize(
    "header, data, words",
    [
        (b"not json", b"", ("not valid JSON",)),
        (b"\xff\xfe{}", b"", ("not valid JSON",)),
        (b"[" * 5000 + b"]" * 5000, b"", ("not valid JSON",)),
        (b"[1, 2]", b"", ("not a JSON object",)),
        (json.dumps({"__metadata__": {"a": 1}}).encode(), b"", ("__metadata__",)),
        (json.dumps({"__metadata__": ["a"]}).encode(), b"", ("__metadata__",)),
        (json.dumps({"t": [1]}).encode(), b"", ("'t'", "dtype, shape and data_offsets")),
        (json.dumps({"t": entry(dtype="F128")}).encode(), bytes(8), ("unknown dtype 'F128'",)),
        (json.dumps({"t": entry(shape=[-2])}).encode(), bytes(8), ("shape",)),
        (json.dumps({"t": entry(shape=[2.0])}).encode(), bytes(8), ("shape",)),
        (json.dumps({"t": entry(shape="2")}).encode(), bytes(8), ("shape",)),
        (json.dumps({"t": entry(offsets=[0])}).encode(), bytes(8), ("data_offsets",)),
        (json.dumps({"t": entry(offsets=[0, 2**70])}).encode(), bytes(8), ("outside the 8 bytes",)),
        (json.dumps({"t": entry(offsets=[8, 0])}).encode(), bytes(8), ("outside",)),
        (json.dumps({"t": entry(shape=[10**9, 10**9])}).encode(), bytes(8), ("shape [1000000000, 1000000000]",)),
        (json.dumps({"t": entry(), "u": entry(offsets=[4, 12])}).encode(), bytes(12), ("overlap or leave gaps",)),
        (json.dumps({"t": entry()}).encode(), bytes(12), ("4 bytes of data belong to no tensor",)),
    ],
)
def test_bad_headers_are_refused(tmp_path: Path, header: bytes, data: bytes, words: tuple[str, ...]) -> None:
    not_safetensors(header_file(tmp_path / "bad.safetensors", header, data), *words)


def test_read_and_header_of_a_valid_file(tmp_path: Path) -> None:
    path = tmp_path / "ok.safetensors"
    tensors = {"a": torch.arange(6, dtype=torch.float32).view(2, 3), "b": torch.zeros(0), "c": torch.ones(4, 1)}
    save_file(tensors, str(path), metadata={"format": "test"})
    entries, metadata = read_safetensors_header(path, "model file", 10**6)
    assert metadata == {"format": "test"}
    assert {k: (e.dtype, e.shape, e.end - e.begin) for k, e in entries.items()} == {
        "a": ("F32", (2, 3), 24),
        "b": ("F32", (0,), 0),
        "c": ("F32", (4, 1), 16),
    }
    loaded, metadata = read_safetensors(path, "model file", 10**6)
    assert metadata == {"format": "test"} and set(loaded) == set(tensors)
    assert all(torch.equal(loaded[k], v) for k, v in tensors.items())
    subset, _ = read_safetensors(path, "model file", 10**6, keys=["c", "missing"])
    assert set(subset) == {"c"} and torch.equal(subset["c"], tensors["c"])
    assert read_safetensors(path, "model file", 10**6, keys=[])[0] == {}
    no_metadata = tmp_path / "plain.safetensors"
    no_metadata.write_bytes(save({"x": torch.zeros(2)}))
    assert read_safetensors(no_metadata, "model file", 10**6)[1] == {}


def test_a_truncated_file_is_refused(tmp_path: Path) -> None:
    data = save({"x": torch.arange(16, dtype=torch.float32)})
    (tmp_path / "cut.safetensors").write_bytes(data[:-5])
    not_safetensors(tmp_path / "cut.safetensors", "tensor 'x'")
