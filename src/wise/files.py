"""Checks shared by every file we read: a regular file of bounded size, safetensors checked before allocation.

Nothing is opened before :func:`regular_file` has seen with ``os.stat`` that the path is a regular file
of at most ``max_bytes``: a FIFO, ``/dev/zero`` or a socket would otherwise block or never end. Files
are then opened without blocking and checked once more, in case the path changed in between.

A safetensors file is read header first: the 8-byte header length, the JSON header and every tensor's
dtype, shape and byte range are checked before any tensor data is read, so a crafted header cannot make
us allocate more than the file holds.
"""

from __future__ import annotations

import errno
import json
import math
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, Collection

from wise.errors import WiseError

if TYPE_CHECKING:
    import torch

PathLike = str | os.PathLike[str]

MAX_PARAMS_BYTES = 256 * 1000**2
"""Largest parameter file: a local mask of 16 parameters at 2000x2000 is 256 MB."""
PARAMS_WHAT = "parameter file"
"""How messages name a parameter file."""
MAX_MODEL_BYTES = 2 * 1000**3
"""Largest model file (torchvision's VGG-19 is about 550 MB)."""
MAX_HEADER_BYTES = 1000**2
"""Largest safetensors JSON header we read; ours are a few kB (VGG-19 has 38 tensors)."""
HEADER_LENGTH_BYTES = 8
"""A safetensors file starts with its header length, a little-endian unsigned 64-bit integer."""
DTYPE_BYTES = {
    "BOOL": 1,
    "U8": 1,
    "I8": 1,
    "F8_E4M3": 1,
    "F8_E4M3FNUZ": 1,
    "F8_E5M2": 1,
    "F8_E5M2FNUZ": 1,
    "I16": 2,
    "U16": 2,
    "F16": 2,
    "BF16": 2,
    "I32": 4,
    "U32": 4,
    "F32": 4,
    "I64": 8,
    "U64": 8,
    "F64": 8,
    "C64": 8,
}
"""Bytes per element of the safetensors dtypes we decode."""

_METADATA_KEY = "__metadata__"
_ENTRY_KEYS = frozenset({"dtype", "shape", "data_offsets"})
_NAME_CHARS = 60
# O_NONBLOCK: should the path have become a FIFO since the check, opening it must not wait for a writer.
_OPEN_FLAGS = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_BINARY", 0)
_SPECIAL_KINDS = (
    (stat.S_ISFIFO, "a named pipe (FIFO)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


@dataclass(frozen=True)
class TensorEntry:
    """One tensor of a safetensors header: dtype name, shape and byte range in the data section."""

    dtype: str
    shape: tuple[int, ...]
    begin: int
    end: int


class _Invalid(ValueError):
    """A reason why a file is not a valid safetensors file."""


def _a(what: str) -> str:
    """``what`` with its indefinite article ("an image", "a parameter file", "VGG-19 weights")."""
    if what.endswith("s"):
        return what
    return ("an " if what[:1].lower() in "aeiou" else "a ") + what


def _one_line(error: BaseException) -> str:
    return " ".join((str(error) or type(error).__name__).split())


def check_size(size: int, name: str, what: str, max_bytes: int) -> None:
    """Refuse an empty file or one above ``max_bytes``; ``name`` is how the messages show the file."""
    if size == 0:
        raise WiseError(f"{name}: the file is empty; pass {_a(what)} with content")
    if size > max_bytes:
        raise WiseError(
            f"{name}: {size / 1e6:.1f} MB is more than the limit of {max_bytes / 1e6:g} MB for {_a(what)}; "
            "use a smaller file"
        )


def _stat(path: Path, what: str) -> os.stat_result:
    try:
        return os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        broken = " (a broken symbolic link)" if os.path.islink(path) else ""
        raise WiseError(f"{path}: no such file{broken}; check the path of the {what}") from None
    except PermissionError:
        raise WiseError(
            f"{path}: cannot read the file (permission denied); check the permissions of the file and its folders"
        ) from None
    except ValueError:  # a NUL character in the path
        raise WiseError(f"{str(path)!r}: not a valid path; check the path of the {what}") from None
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise WiseError(
                f"{path}: a loop of symbolic links; point the link at {_a(what)} or pass the file itself"
            ) from None
        raise WiseError(f"{path}: cannot read the file ({e.strerror or _one_line(e)}); check the path") from None


def _check_kind(status: os.stat_result, path: Path, what: str, max_bytes: int) -> None:
    if stat.S_ISDIR(status.st_mode):
        raise WiseError(f"{path}: is a directory, not {_a(what)}; pass the path of a file")
    if not stat.S_ISREG(status.st_mode):
        kind = next((text for test, text in _SPECIAL_KINDS if test(status.st_mode)), "a special file")
        raise WiseError(f"{path}: is {kind}, not a regular file; pass {_a(what)} stored in a regular file")
    check_size(status.st_size, str(path), what, max_bytes)


def regular_file(path: PathLike, what: str, max_bytes: int) -> Path:
    """``path`` as a :class:`Path` once it is known to be a readable, non-empty regular file of at most ``max_bytes``.

    ``what`` names the file in messages ("image", "parameter file"). Raises :class:`WiseError` with one
    line naming the file, what is wrong and what to do. The file is not opened.
    """
    path = Path(path)
    _check_kind(_stat(path, what), path, what, max_bytes)
    if not os.access(path, os.R_OK):
        raise WiseError(f"{path}: cannot read the file (permission denied); check its permissions, e.g. chmod u+r")
    return path


def _open_checked(path: PathLike, what: str, max_bytes: int) -> tuple[BinaryIO, int]:
    path = regular_file(path, what, max_bytes)
    try:
        f = open(path, "rb", opener=lambda name, flags: os.open(name, _OPEN_FLAGS))
    except OSError as e:
        raise WiseError(f"{path}: cannot read the file ({e.strerror or _one_line(e)}); check its permissions") from None
    try:
        status = os.fstat(f.fileno())
        _check_kind(status, path, what, max_bytes)  # the path may point elsewhere since the check
        return f, status.st_size
    except BaseException:
        f.close()
        raise


def open_regular(path: PathLike, what: str, max_bytes: int) -> BinaryIO:
    """Open a file for reading after :func:`regular_file`; what was opened is checked again."""
    return _open_checked(path, what, max_bytes)[0]


def _not_safetensors(path: Path, what: str, reason: str) -> WiseError:
    return WiseError(f"{path}: not a safetensors file ({reason}); check that it is {_a(what)} saved as safetensors")


def _read_exactly(f: BinaryIO, count: int, path: Path) -> bytes:
    try:
        data = f.read(count)
    except OSError as e:
        raise WiseError(f"{path}: cannot read the file ({e.strerror or _one_line(e)})") from None
    if len(data) != count:
        raise _Invalid("the file is truncated or changed while being read")
    return data


def _name(name: str) -> str:
    return repr(name if len(name) <= _NAME_CHARS else name[:_NAME_CHARS] + "...")


def _is_count(value: object) -> bool:
    return type(value) is int and value >= 0


def _entry(name: str, info: object, data_bytes: int) -> TensorEntry:
    if not isinstance(info, dict) or not _ENTRY_KEYS <= set(info):
        raise _Invalid(f"tensor {_name(name)} is not described by dtype, shape and data_offsets")
    dtype, shape, offsets = info["dtype"], info["shape"], info["data_offsets"]
    if not isinstance(dtype, str) or dtype not in DTYPE_BYTES:
        raise _Invalid(f"tensor {_name(name)} has the unknown dtype {_name(str(dtype))}")
    if not isinstance(shape, list) or not all(_is_count(d) for d in shape):
        raise _Invalid(f"tensor {_name(name)} has a shape that is not a list of non-negative integers")
    if not isinstance(offsets, list) or len(offsets) != 2 or not all(_is_count(o) for o in offsets):
        raise _Invalid(f"tensor {_name(name)} has data_offsets that are not two non-negative integers")
    begin, end = offsets
    if not begin <= end <= data_bytes:
        raise _Invalid(f"tensor {_name(name)} has data_offsets outside the {data_bytes} bytes of data")
    expected = math.prod(shape) * DTYPE_BYTES[dtype]
    if end - begin != expected:
        raise _Invalid(
            f"tensor {_name(name)} has {end - begin} bytes of data; its shape {shape} of {dtype} needs {expected}"
        )
    return TensorEntry(dtype, tuple(shape), begin, end)


def _check_layout(entries: dict[str, TensorEntry], data_bytes: int) -> None:
    """The tensors must cover the data section exactly, without overlaps or gaps (as safetensors requires)."""
    end = 0
    for entry in sorted(entries.values(), key=lambda e: (e.begin, e.end)):
        if entry.begin != end:
            raise _Invalid("the tensors' data_offsets overlap or leave gaps")
        end = entry.end
    if end != data_bytes:
        raise _Invalid(f"{data_bytes - end} bytes of data belong to no tensor")


def _parse_header(
    f: BinaryIO, path: Path, size: int, max_header_bytes: int
) -> tuple[int, dict[str, TensorEntry], dict[str, str]]:
    """(start of the data section, tensor entries, metadata), reading nothing beyond the header."""
    if size < HEADER_LENGTH_BYTES:
        raise _Invalid(f"{size} bytes is shorter than the {HEADER_LENGTH_BYTES}-byte header length")
    length = int.from_bytes(_read_exactly(f, HEADER_LENGTH_BYTES, path), "little")
    if length == 0:
        raise _Invalid("the header length is 0")
    if length > size - HEADER_LENGTH_BYTES:
        raise _Invalid(f"the header length {length} is more than the {size - HEADER_LENGTH_BYTES} bytes after it")
    if length > max_header_bytes:
        raise _Invalid(f"a header of {length} bytes is more than the limit of {max_header_bytes}")
    raw = _read_exactly(f, length, path)
    try:
        header = json.loads(raw.decode("utf-8"))
    except (ValueError, RecursionError):  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise _Invalid("the header is not valid JSON") from None
    if not isinstance(header, dict):
        raise _Invalid("the header is not a JSON object")
    metadata = header.pop(_METADATA_KEY, {})
    if not isinstance(metadata, dict) or not all(isinstance(v, str) for v in metadata.values()):
        raise _Invalid(f"{_METADATA_KEY} is not a map of strings to strings")
    data_bytes = size - HEADER_LENGTH_BYTES - length
    entries = {name: _entry(name, info, data_bytes) for name, info in header.items()}
    _check_layout(entries, data_bytes)
    return HEADER_LENGTH_BYTES + length, entries, metadata


def safetensors_path(path: PathLike, what: str) -> Path:
    """``path`` when it names a ``.safetensors`` file; pickled files (``.pth``, ``.pt``) can run code
    and are never loaded."""
    path = Path(path)
    if path.suffix != ".safetensors":
        raise WiseError(f"{path}: {what} must be a .safetensors file (pickled .pth files are not loaded)")
    return path


def read_safetensors_header(path: PathLike, what: str, max_bytes: int) -> tuple[dict[str, TensorEntry], dict[str, str]]:
    """The checked tensor entries and metadata of a safetensors file, without reading any tensor data."""
    path = Path(path)
    f, size = _open_checked(path, what, max_bytes)
    with f:
        try:
            _, entries, metadata = _parse_header(f, path, size, MAX_HEADER_BYTES)
        except _Invalid as e:
            raise _not_safetensors(path, what, str(e)) from None
    return entries, metadata


def _subset(f: BinaryIO, path: Path, start: int, entries: dict[str, TensorEntry], keys: Collection[str]) -> bytes:
    """A safetensors buffer of the tensors ``keys`` (those present), reading only their bytes."""
    chosen = sorted((name for name in set(keys) if name in entries), key=lambda name: entries[name].begin)
    header: dict[str, object] = {}
    chunks: list[bytes] = []
    offset = 0
    for name in chosen:
        entry = entries[name]
        f.seek(start + entry.begin)
        chunks.append(_read_exactly(f, entry.end - entry.begin, path))
        end = offset + len(chunks[-1])
        header[name] = {"dtype": entry.dtype, "shape": list(entry.shape), "data_offsets": [offset, end]}
        offset = end
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-len(text) % HEADER_LENGTH_BYTES)
    return len(text).to_bytes(HEADER_LENGTH_BYTES, "little") + text + b"".join(chunks)


def _st_load(data: bytes) -> dict[str, torch.Tensor]:
    from safetensors.torch import load  # with PyTorch: loaded when a file's tensors are read

    return load(data)


def read_safetensors(
    path: PathLike, what: str, max_bytes: int, keys: Collection[str] | None = None
) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """The tensors and metadata of a safetensors file whose header was checked before reading the data.

    With ``keys``, only those tensors (of the ones present) are read. Raises :class:`WiseError`
    ("FILE: not a safetensors file (...)") for anything malformed.
    """
    path = Path(path)
    f, size = _open_checked(path, what, max_bytes)
    try:
        with f:
            start, entries, metadata = _parse_header(f, path, size, MAX_HEADER_BYTES)
            if keys is None:
                f.seek(0)
                data = _read_exactly(f, size, path)
            else:
                data = _subset(f, path, start, entries, keys)
        tensors = _st_load(data)
    except _Invalid as e:
        raise _not_safetensors(path, what, str(e)) from None
    except MemoryError:
        raise WiseError(f"{path}: not enough memory to read {size / 1e6:.1f} MB; free memory and try again") from None
    except WiseError:
        raise
    except Exception as e:  # SafetensorError or whatever else the decoder raises on a malformed file
        raise _not_safetensors(path, what, _one_line(e)) from None
    return tensors, metadata


__all__ = [
    "MAX_HEADER_BYTES",
    "MAX_MODEL_BYTES",
    "MAX_PARAMS_BYTES",
    "TensorEntry",
    "check_size",
    "open_regular",
    "read_safetensors",
    "read_safetensors_header",
    "regular_file",
]
