"""Writing ``(1, 3, H, W)`` float tensors in [0, 1] as 8-bit images.

Writing supports PNG and JPEG and is atomic: the image goes to a temporary
file in the target directory that then replaces the target, so a failure never
leaves a partial file behind.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np
import torch
from PIL import Image

from wise.errors import WiseError
from wise.io.common import WRITE_FORMATS, PathLike, one_line


def tensor_to_image(tensor: torch.Tensor) -> np.ndarray:
    """A ``(1, C, H, W)`` or ``(C, H, W)`` tensor in [0, 1] (C = 1 or 3) to ``H x W x C`` uint8."""
    if not isinstance(tensor, torch.Tensor):
        raise WiseError(f"expected an image tensor, got {type(tensor).__name__}")
    t = tensor.detach()
    if t.dim() == 4 and t.shape[0] == 1:
        t = t[0]
    if t.dim() != 3 or t.shape[0] not in (1, 3):
        raise WiseError(f"image must have shape (1, 3, H, W), (3, H, W) or (1, 1, H, W); got {tuple(tensor.shape)}")
    if min(t.shape[-2:]) == 0:
        raise WiseError(f"image is empty: shape {tuple(tensor.shape)}")
    t = t.to("cpu", torch.float32)
    if not torch.isfinite(t).all():
        raise WiseError("image contains NaN or infinite values")
    return (t.clamp(0.0, 1.0) * 255.0).round().to(torch.uint8).permute(1, 2, 0).numpy()


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` that replaces ``path`` on success.

    On any error the temporary file is removed and ``path`` stays untouched.
    Raises :class:`WiseError` when the directory is missing or not writable.
    """
    target = Path(path)
    directory = target.parent
    if target.is_dir():
        raise WiseError(f"{target}: is a directory")
    if not directory.is_dir():
        raise WiseError(f"{target}: the directory {directory} does not exist")
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    except OSError as e:
        raise WiseError(f"{target}: cannot write to {directory} ({e.strerror or one_line(e)})") from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_image(image: torch.Tensor, path: PathLike, quality: int = 95) -> None:
    """Write a ``(1, 3, H, W)``, ``(3, H, W)`` or ``(1, 1, H, W)`` tensor in [0, 1] as 8-bit PNG or JPEG.

    The format follows the extension (.png, .jpg, .jpeg); values are clamped and
    rounded. ``quality`` (1-100) applies to JPEG. The write is atomic.
    """
    target = Path(path)
    fmt = WRITE_FORMATS.get(target.suffix.lower())
    if fmt is None:
        raise WiseError(
            f"{target}: cannot write {target.suffix or 'files without an extension'}; "
            f"supported extensions: {', '.join(WRITE_FORMATS)}"
        )
    if not isinstance(quality, int) or not 1 <= quality <= 100:
        raise WiseError(f"JPEG quality must be an integer from 1 to 100, got {quality!r}")
    array = tensor_to_image(image)
    img = Image.fromarray(array[:, :, 0] if array.shape[2] == 1 else array)
    options: dict[str, object] = {"quality": quality} if fmt == "JPEG" else {}
    try:
        with atomic_path(target) as tmp:
            img.save(tmp, format=fmt, **options)
    except OSError as e:
        raise WiseError(f"{target}: cannot write the image ({e.strerror or one_line(e)})") from None


def write_together(writers: Sequence[tuple[PathLike, Callable[[Path], None]]]) -> None:
    """Write several files that belong together: each ``(path, write)`` in turn; on any error
    (Ctrl-C included) the files already written are removed again, so that all are there or
    none."""
    started: list[Path] = []
    try:
        for path, write in writers:
            started.append(Path(path))
            write(Path(path))
    except BaseException:
        for path in started:
            with contextlib.suppress(OSError):
                path.unlink()
        raise
