"""Weight files written for tests: the real key names and shapes, no real weights."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import torch

from wise.files import DTYPE_BYTES


def sparse_weights(path: Path, shapes: dict[str, tuple[int, ...]], dtype: str = "F32") -> Path:
    """A safetensors file with these tensor shapes whose data is a hole (written without the bytes)."""
    header, offset = {}, 0
    for key, shape in shapes.items():
        size = DTYPE_BYTES[dtype] * int(torch.Size(shape).numel())
        header[key] = {"dtype": dtype, "shape": list(shape), "data_offsets": [offset, offset + size]}
        offset += size
    text = json.dumps(header).encode()
    with path.open("wb") as f:
        f.write(struct.pack("<Q", len(text)) + text)
        f.truncate(8 + len(text) + offset)
    return path
