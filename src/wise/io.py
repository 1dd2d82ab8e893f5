"""Reading and writing images as ``(1, 3, H, W)`` float tensors in [0, 1].

Reading accepts PNG, JPEG, WebP and TIFF. The EXIF orientation is applied,
greyscale becomes RGB, and an alpha channel is composited over white (a
transparent pixel reads as white). 16-bit PNG and TIFF, greyscale or colour,
keep their precision (values are divided by 65535): Pillow reads 16-bit colour
PNG at 8 bits, so those are decoded with pypng and 16-bit colour TIFF with
tifffile.

Writing supports PNG and JPEG and is atomic: the image goes to a temporary
file in the target directory that then replaces the target, so a failure never
leaves a partial file behind.
"""

from __future__ import annotations

import contextlib
import logging
import os
import tempfile
import warnings
import zlib
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import torch
from PIL import Image, ImageOps, UnidentifiedImageError

from wise.errors import WiseError

PathLike = str | os.PathLike[str]

READ_FORMATS = {"PNG": "PNG", "JPEG": "JPEG", "WEBP": "WebP", "TIFF": "TIFF"}
WRITE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}

_SIXTEEN_BIT_MODES = {"I;16", "I;16L", "I;16B", "I;16N", "I"}
_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_PNG_COLOUR_TYPES = {2, 4, 6}  # RGB, greyscale + alpha, RGBA: Pillow reads these at 8 bits
_ORIENTATIONS: dict[int, Callable[[np.ndarray], np.ndarray]] = {
    2: lambda a: a[:, ::-1],
    3: lambda a: a[::-1, ::-1],
    4: lambda a: a[::-1],
    5: lambda a: a.swapaxes(0, 1),
    6: lambda a: np.rot90(a, -1),
    7: lambda a: np.rot90(a, 2).swapaxes(0, 1),
    8: lambda a: np.rot90(a, 1),
}


def _one_line(error: BaseException) -> str:
    text = str(error) or type(error).__name__
    return " ".join(text.split())


def _check_readable(path: Path) -> None:
    if not path.exists():
        raise WiseError(f"{path}: no such file")
    if path.is_dir():
        raise WiseError(f"{path}: is a directory, not an image file")
    if not path.is_file():
        raise WiseError(f"{path}: not a regular file")
    try:
        size = path.stat().st_size
    except OSError as e:
        raise WiseError(f"{path}: cannot read the file ({e.strerror or _one_line(e)})") from None
    if size == 0:
        raise WiseError(f"{path}: the file is empty")


def _is_tiff(path: Path) -> bool:
    with path.open("rb") as f:
        return f.read(4) in _TIFF_MAGIC


def _to_float(array: np.ndarray) -> np.ndarray:
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


def _to_rgb(array: np.ndarray) -> np.ndarray:
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


def _pillow_array(img: Image.Image) -> np.ndarray:
    """An oriented Pillow image as ``H x W x 3`` floats in [0, 1]."""
    img = ImageOps.exif_transpose(img)
    if img.mode in _SIXTEEN_BIT_MODES or img.mode == "F":
        return _to_rgb(_to_float(np.asarray(img)))
    if "transparency" in img.info or img.mode in ("RGBa", "La", "PA"):
        img = img.convert("RGBA")
    elif img.mode not in ("RGB", "L", "RGBA", "LA"):
        img = img.convert("RGB")
    return _to_rgb(_to_float(np.asarray(img)))


def _exif_orientation(path: Path) -> int:
    try:
        with Image.open(path) as img:
            return int(img.getexif().get(0x0112, 1))
    except (OSError, ValueError, SyntaxError):
        return 1


def _tifffile_array(path: Path) -> np.ndarray:
    """A TIFF that Pillow cannot read at full precision, via tifffile."""
    import tifffile

    logger = logging.getLogger("tifffile")
    was_disabled, logger.disabled = logger.disabled, True
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with tifffile.TiffFile(path) as tif:
                if not tif.pages:
                    raise ValueError("the TIFF file contains no images")
                page = tif.pages.first
                array = page.asarray()
                axes = page.axes
    finally:
        logger.disabled = was_disabled
    if array.size == 0:
        return np.zeros((0, 0, 3), np.float32)
    if array.ndim == 3 and axes.startswith("S"):
        array = np.moveaxis(array, 0, -1)
    if array.ndim not in (2, 3):
        raise ValueError(f"unexpected TIFF layout {axes} {array.shape}")
    array = _to_rgb(_to_float(array))
    orient = _ORIENTATIONS.get(_exif_orientation(path))
    return np.ascontiguousarray(orient(array) if orient else array)


def _needs_pypng(path: Path) -> bool:
    """Whether a file is a 16-bit PNG with colour or alpha (IHDR: bit depth, colour type)."""
    with path.open("rb") as f:
        header = f.read(26)
    return (
        len(header) == 26
        and header.startswith(_PNG_MAGIC)
        and header[12:16] == b"IHDR"
        and header[24] == 16
        and header[25] in _PNG_COLOUR_TYPES
    )


def _pypng_array(path: Path) -> np.ndarray:
    """A 16-bit colour PNG that Pillow would read at 8 bits, via pypng."""
    import png

    try:
        width, height, rows, info = png.Reader(filename=str(path)).asDirect()
        array = np.array([np.asarray(row, np.uint16) for row in rows], np.uint16)
    except (png.Error, zlib.error) as e:
        raise ValueError(_one_line(e)) from None
    planes, depth = info["planes"], info["bitdepth"]
    if array.shape != (height, width * planes):
        raise ValueError(f"expected {height} rows of {width * planes} samples, got shape {array.shape}")
    scaled = array.reshape(height, width, planes).astype(np.float32) / float(2**depth - 1)
    array = _to_rgb(np.clip(scaled, 0.0, 1.0))
    orient = _ORIENTATIONS.get(_exif_orientation(path))
    return np.ascontiguousarray(orient(array) if orient else array)


def _needs_tifffile(img: Image.Image) -> bool:
    """Whether Pillow would silently drop precision of a TIFF (e.g. 16-bit RGB)."""
    if img.format != "TIFF" or img.mode in _SIXTEEN_BIT_MODES or img.mode == "F":
        return False
    bits = img.tag_v2.get(258, (8,)) if hasattr(img, "tag_v2") else (8,)
    bits = bits if isinstance(bits, tuple) else (bits,)
    return any(int(b) > 8 for b in bits)


def read_image(path: PathLike) -> torch.Tensor:
    """Read an image file as a ``(1, 3, H, W)`` float32 tensor in [0, 1].

    Supports PNG, JPEG, WebP and TIFF. Applies the EXIF orientation, turns
    greyscale into RGB and composites alpha over white. Raises
    :class:`WiseError` naming the file when it is missing, a directory, not a
    supported image, corrupt or empty.
    """
    path = Path(path)
    _check_readable(path)
    try:
        try:
            with Image.open(path) as img:
                fmt = img.format or "unknown"
                if fmt not in READ_FORMATS:
                    supported = ", ".join(READ_FORMATS.values())
                    raise WiseError(f"{path}: unsupported image format {fmt}; supported: {supported}")
                if img.width == 0 or img.height == 0:
                    raise WiseError(f"{path}: the image is empty ({img.width}x{img.height} pixels)")
                if fmt == "PNG" and _needs_pypng(path):
                    array = _pypng_array(path)
                else:
                    img.load()
                    array = _tifffile_array(path) if _needs_tifffile(img) else _pillow_array(img)
        except UnidentifiedImageError:
            if not _is_tiff(path):
                supported = ", ".join(READ_FORMATS.values())
                raise WiseError(f"{path}: not an image in a supported format ({supported})") from None
            array = _tifffile_array(path)
    except WiseError:
        raise
    except PermissionError as e:
        raise WiseError(f"{path}: cannot read the file ({e.strerror or _one_line(e)})") from None
    except (OSError, ValueError, SyntaxError, EOFError, MemoryError, Image.DecompressionBombError) as e:
        raise WiseError(f"{path}: corrupt or unreadable image data ({_one_line(e)})") from None
    if array.shape[0] == 0 or array.shape[1] == 0:
        raise WiseError(f"{path}: the image is empty ({array.shape[1]}x{array.shape[0]} pixels)")
    return image_to_tensor(array)


def image_to_tensor(array: np.ndarray) -> torch.Tensor:
    """``H x W``, ``H x W x 1|2|3|4`` uint8, uint16 or float array to ``(1, 3, H, W)`` float32.

    uint8 is divided by 255, other integers by 65535, floats are taken as [0, 1];
    alpha is composited over white.
    """
    array = np.asarray(array)
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (1, 2, 3, 4)):
        raise WiseError(f"expected an H x W or H x W x C image array, got shape {array.shape}")
    rgb = _to_rgb(_to_float(array))
    return torch.from_numpy(np.ascontiguousarray(rgb, dtype=np.float32)).permute(2, 0, 1).unsqueeze(0).contiguous()


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
        raise WiseError(f"{target}: cannot write to {directory} ({e.strerror or _one_line(e)})") from None
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
        raise WiseError(f"{target}: cannot write the image ({e.strerror or _one_line(e)})") from None
