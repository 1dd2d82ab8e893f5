"""Decoded sample arrays to ``H x W x 3`` floats in [0, 1].

Greyscale becomes RGB and an alpha channel is composited over white (a
transparent pixel reads as white).
"""

from __future__ import annotations

import numpy as np


def to_float(array: np.ndarray) -> np.ndarray:
    """Integer samples scaled to [0, 1] by their bit depth; floats clipped to [0, 1]."""
    if array.dtype == np.uint8:
        out = array.astype(np.float32) / 255.0
    elif array.dtype.kind in "ui":
        out = array.astype(np.float32) / 65535.0
    elif array.dtype.kind == "f":
        out = np.nan_to_num(array.astype(np.float32), nan=0.0)
    elif array.dtype == np.bool_:
        out = array.astype(np.float32)
    else:
        raise ValueError(f"unsupported sample type {array.dtype}")
    return np.clip(out, 0.0, 1.0)


def to_rgb(array: np.ndarray) -> np.ndarray:
    """``H x W [x C]`` floats to ``H x W x 3``, compositing alpha over white."""
    if array.ndim == 2:
        array = array[:, :, None]
    channels = array.shape[2]
    if channels in (2, 4):
        color, alpha = array[:, :, :-1], array[:, :, -1:]
        array = color * alpha + (1.0 - alpha)
    elif channels not in (1, 3):
        array = array[:, :, :3]
    if array.shape[2] == 1:
        array = np.repeat(array, 3, axis=2)
    return array
