"""Reading and writing images: formats, bit depths, orientation, refusals, atomic writes."""

from __future__ import annotations

import io
import os
import struct
import sys
import tempfile
import time
import warnings
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
import tifffile
import torch
from PIL import Image
from skimage import data

import wise.io as wio
from wise.errors import WiseError
from wise.io import decode_image_bytes, formats, image_to_tensor, read_image, tensor_to_image, write_image
from wise.io import read as io_read
from wise.io import write as io_write


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    """A 64x48 (W x H) RGB uint8 photo."""
    return np.asarray(Image.fromarray(data.astronaut()).resize((64, 48), Image.Resampling.BILINEAR))


def ramp16(h: int = 32, w: int = 40) -> np.ndarray:
    """16-bit values that 8 bits cannot represent."""
    return (np.arange(h * w, dtype=np.uint32).reshape(h, w) * 37 + 11).astype(np.uint16)


def test_tensor_layout(photo: np.ndarray) -> None:
    t = image_to_tensor(photo)
    assert t.shape == (1, 3, 48, 64) and t.dtype == torch.float32
    assert 0.0 <= float(t.min()) and float(t.max()) <= 1.0
    np.testing.assert_array_equal(tensor_to_image(t), photo)


def test_png_round_trip_is_exact(tmp_path: Path, photo: np.ndarray) -> None:
    path = tmp_path / "a.png"
    write_image(image_to_tensor(photo), path)
    t = read_image(path)
    assert t.shape == (1, 3, 48, 64) and t.dtype == torch.float32
    np.testing.assert_array_equal(tensor_to_image(t), photo)


@pytest.mark.parametrize("name", ["a.jpg", "a.JPEG"])
def test_jpeg_round_trip(tmp_path: Path, photo: np.ndarray, name: str) -> None:
    path = tmp_path / name
    write_image(image_to_tensor(photo)[0], path, quality=95)
    assert Image.open(path).format == "JPEG"
    diff = (read_image(path) - image_to_tensor(photo)).abs().mean()
    assert float(diff) < 0.03


def test_webp_and_tiff_read(tmp_path: Path, photo: np.ndarray) -> None:
    Image.fromarray(photo).save(tmp_path / "a.webp", lossless=True)
    Image.fromarray(photo).save(tmp_path / "a.tif")
    Image.fromarray(photo).save(tmp_path / "lossy.webp", quality=90)
    for name in ("a.webp", "a.tif"):
        np.testing.assert_array_equal(tensor_to_image(read_image(tmp_path / name)), photo)
    assert float((read_image(tmp_path / "lossy.webp") - image_to_tensor(photo)).abs().mean()) < 0.05


def test_write_greyscale(tmp_path: Path) -> None:
    grey = torch.linspace(0, 1, 16 * 16).reshape(1, 1, 16, 16)
    write_image(grey, tmp_path / "g.png")
    assert Image.open(tmp_path / "g.png").mode == "L"
    t = read_image(tmp_path / "g.png")
    assert t.shape == (1, 3, 16, 16)
    assert torch.equal(t[:, 0], t[:, 1]) and torch.equal(t[:, 1], t[:, 2])
    assert float((t[:, :1] - grey).abs().max()) <= 0.5 / 255 + 1e-6


def test_write_clamps_and_rounds(tmp_path: Path) -> None:
    t = torch.tensor([-1.0, 0.2, 2.0]).view(1, 3, 1, 1).expand(1, 3, 4, 4)
    write_image(t, tmp_path / "c.png")
    assert np.asarray(Image.open(tmp_path / "c.png"))[0, 0].tolist() == [0, 51, 255]


def test_16bit_png_keeps_precision(tmp_path: Path) -> None:
    values = ramp16()
    Image.fromarray(values).save(tmp_path / "g16.png")
    t = read_image(tmp_path / "g16.png")
    assert t.shape == (1, 3, 32, 40)
    expected = torch.from_numpy(values.astype(np.float32) / 65535)
    assert float((t[0, 1] - expected).abs().max()) < 1e-6


def write_png16(path: Path, samples: np.ndarray, exif: bytes | None = None) -> None:
    """Write an ``H x W x C`` uint16 array (C = 2, 3 or 4) as a 16-bit PNG with pypng."""
    import png

    h, w, c = samples.shape
    writer = png.Writer(w, h, bitdepth=16, greyscale=c < 3, alpha=c in (2, 4))
    with path.open("wb") as f:
        writer.write(f, samples.reshape(h, w * c).tolist())
    if exif is not None:
        chunks = list(png.Reader(filename=str(path)).chunks())
        chunks.insert(1, (b"eXIf", exif))
        with path.open("wb") as f:
            png.write_chunks(f, chunks)


def colour16(channels: int) -> np.ndarray:
    """Planes of 16-bit values 8 bits cannot hold, alpha spanning 0..65535."""
    grey = ramp16()
    planes = [grey, grey[::-1], 65535 - grey][: 1 if channels == 2 else 3]
    if channels in (2, 4):
        planes.append(np.linspace(0, 65535, grey.size).round().astype(np.uint16).reshape(grey.shape) | 1)
    return np.stack(planes, axis=-1)


def over_white(samples: np.ndarray) -> np.ndarray:
    """Expected ``3 x H x W`` reading: values / 65535, alpha composited over white."""
    v = samples.astype(np.float64) / 65535
    if v.shape[2] in (2, 4):
        v = v[..., :-1] * v[..., -1:] + (1 - v[..., -1:])
    return np.repeat(v, 3, axis=2).transpose(2, 0, 1) if v.shape[2] == 1 else v.transpose(2, 0, 1)


@pytest.mark.parametrize("channels", [3, 4, 2], ids=["rgb", "rgba", "grey-alpha"])
def test_16bit_colour_png_keeps_precision(tmp_path: Path, channels: int) -> None:
    samples = colour16(channels)
    write_png16(tmp_path / "c16.png", samples)
    expected = over_white(samples)
    eight_bit = over_white((samples / 257).round().astype(np.uint16) * 257)
    assert np.abs(eight_bit - expected).max() > 1e-4  # the test would catch an 8-bit read
    t = read_image(tmp_path / "c16.png")
    assert t.shape == (1, 3, 32, 40) and t.dtype == torch.float32
    assert float(np.abs(t[0].numpy() - expected).max()) < 1e-6


def test_16bit_colour_png_orientation(tmp_path: Path) -> None:
    samples = colour16(3)
    exif = Image.Exif()
    exif[0x0112] = 6
    write_png16(tmp_path / "o.png", samples, exif=exif.tobytes()[6:])
    assert Image.open(tmp_path / "o.png").getexif().get(0x0112) == 6
    t = read_image(tmp_path / "o.png")
    assert t.shape == (1, 3, 40, 32)
    expected = np.rot90(over_white(samples), -1, axes=(1, 2))
    assert float(np.abs(t[0].numpy() - expected).max()) < 1e-6


def test_corrupt_16bit_colour_png_refused(tmp_path: Path) -> None:
    write_png16(tmp_path / "good.png", colour16(4))
    data = (tmp_path / "good.png").read_bytes()
    bad = tmp_path / "bad.png"
    bad.write_bytes(data[: len(data) // 2])
    assert formats.needs_pypng(bad.read_bytes())
    expect_error(bad, "corrupt")
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0xFF
    bad.write_bytes(bytes(flipped))
    expect_error(bad, "corrupt")


def test_16bit_tiff_keeps_precision(tmp_path: Path) -> None:
    grey = ramp16()
    rgb = np.stack([grey, grey[::-1], 65535 - grey], axis=-1)
    tifffile.imwrite(tmp_path / "g16.tif", grey)
    tifffile.imwrite(tmp_path / "rgb16.tif", rgb, photometric="rgb")
    g = read_image(tmp_path / "g16.tif")
    assert float((g[0, 2] - torch.from_numpy(grey / 65535.0).float()).abs().max()) < 1e-6
    c = read_image(tmp_path / "rgb16.tif")
    expected = torch.from_numpy(rgb.astype(np.float32) / 65535).permute(2, 0, 1)
    assert c.shape == (1, 3, 32, 40)
    assert float((c[0] - expected).abs().max()) < 1e-6


def test_16bit_rgb_tiff_orientation(tmp_path: Path) -> None:
    rgb = np.stack([ramp16()] * 3, axis=-1)
    tifffile.imwrite(tmp_path / "o.tif", rgb, photometric="rgb", extratags=[(274, "H", 1, 6, True)])
    t = read_image(tmp_path / "o.tif")
    assert t.shape == (1, 3, 40, 32)
    expected = np.rot90(rgb[:, :, 0], -1).astype(np.float32) / 65535
    assert float((t[0, 0] - torch.from_numpy(expected.copy())).abs().max()) < 1e-6


def test_greyscale_becomes_rgb(tmp_path: Path, photo: np.ndarray) -> None:
    grey = np.asarray(Image.fromarray(photo).convert("L"))
    Image.fromarray(grey).save(tmp_path / "g.png")
    t = read_image(tmp_path / "g.png")
    assert t.shape == (1, 3, 48, 64)
    for c in range(3):
        np.testing.assert_array_equal((t[0, c] * 255).round().byte().numpy(), grey)


def test_alpha_is_composited_over_white(tmp_path: Path) -> None:
    rgba = np.zeros((8, 8, 4), np.uint8)
    rgba[..., 0] = 200
    rgba[0, 0, 3] = 0
    rgba[0, 1, 3] = 255
    rgba[0, 2, 3] = 128
    Image.fromarray(rgba, "RGBA").save(tmp_path / "a.png")
    t = read_image(tmp_path / "a.png")[0]
    assert t[:, 0, 0].tolist() == [1.0, 1.0, 1.0]
    assert torch.allclose(t[:, 0, 1], torch.tensor([200 / 255, 0.0, 0.0]))
    a = 128 / 255
    assert torch.allclose(t[:, 0, 2], torch.tensor([200 / 255 * a + 1 - a, 1 - a, 1 - a]))
    la = Image.fromarray(rgba[..., [0, 3]], "LA")
    la.save(tmp_path / "la.png")
    assert read_image(tmp_path / "la.png")[0, :, 0, 0].tolist() == [1.0, 1.0, 1.0]


def test_palette_transparency_over_white(tmp_path: Path) -> None:
    img = Image.new("P", (8, 8), 0)
    img.putpalette([255, 0, 0, 0, 0, 255])
    img.putpixel((1, 0), 1)
    img.save(tmp_path / "p.png", transparency=0)
    t = read_image(tmp_path / "p.png")[0]
    assert t[:, 0, 0].tolist() == [1.0, 1.0, 1.0]
    assert t[:, 0, 1].tolist() == [0.0, 0.0, 1.0]


@pytest.mark.parametrize("orientation, shape", [(1, (32, 48)), (3, (32, 48)), (6, (48, 32)), (8, (48, 32))])
def test_exif_orientation(tmp_path: Path, orientation: int, shape: tuple[int, int]) -> None:
    pixels = np.zeros((32, 48, 3), np.uint8)
    pixels[:8, :8] = 255
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(pixels).save(tmp_path / "o.jpg", exif=exif, quality=95)
    t = read_image(tmp_path / "o.jpg")
    assert tuple(t.shape[-2:]) == shape
    corners = {1: (0, 0), 3: (-1, -1), 6: (0, -1), 8: (-1, 0)}
    y, x = corners[orientation]
    assert float(t[0, :, y, x].mean()) > 0.9


def expect_error(path: Path, *words: str) -> str:
    with pytest.raises(WiseError) as info:
        read_image(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    for word in words:
        assert word in message
    return message


def test_read_refusals(tmp_path: Path, photo: np.ndarray) -> None:
    expect_error(tmp_path / "missing.png", "no such file")
    expect_error(tmp_path, "directory")
    (tmp_path / "notes.txt").write_text("hello, not an image\n")
    expect_error(tmp_path / "notes.txt", "not an image")
    (tmp_path / "zero.png").write_bytes(b"")
    expect_error(tmp_path / "zero.png", "empty")
    Image.fromarray(photo).save(tmp_path / "a.gif")
    expect_error(tmp_path / "a.gif", "unsupported image format GIF")


def test_corrupt_data_refused(tmp_path: Path, photo: np.ndarray) -> None:
    for fmt, ext in (("PNG", "png"), ("JPEG", "jpg"), ("WEBP", "webp")):
        good = tmp_path / f"good.{ext}"
        Image.fromarray(photo).save(good, format=fmt)
        bad = tmp_path / f"bad.{ext}"
        bad.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
        expect_error(bad, "corrupt")
    (tmp_path / "bad.tif").write_bytes(b"II*\x00" + bytes(20))
    expect_error(tmp_path / "bad.tif", "corrupt")


def test_zero_size_tiff_refused(tmp_path: Path) -> None:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tifffile.imwrite(tmp_path / "empty.tif", np.zeros((0, 5), np.uint8))
    expect_error(tmp_path / "empty.tif", "empty")


def test_write_refusals(tmp_path: Path) -> None:
    image = torch.rand(1, 3, 8, 8)
    with pytest.raises(WiseError, match=r"supported extensions: \.png, \.jpg, \.jpeg"):
        write_image(image, tmp_path / "a.webp")
    with pytest.raises(WiseError, match="does not exist"):
        write_image(image, tmp_path / "missing" / "a.png")
    with pytest.raises(WiseError, match="shape"):
        write_image(torch.rand(2, 3, 8, 8), tmp_path / "a.png")
    with pytest.raises(WiseError, match="NaN"):
        write_image(torch.full((1, 3, 8, 8), float("nan")), tmp_path / "a.png")
    with pytest.raises(WiseError, match="quality"):
        write_image(image, tmp_path / "a.jpg", quality=0)
    assert list(tmp_path.iterdir()) == []


def test_unwritable_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kwargs: object) -> tuple[int, str]:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(io_write.tempfile, "mkstemp", refuse)
    with pytest.raises(WiseError, match="cannot write"):
        write_image(torch.rand(1, 3, 8, 8), tmp_path / "a.png")
    assert list(tmp_path.iterdir()) == []


def test_failed_write_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "out.png"
    write_image(torch.zeros(1, 3, 8, 8), target)
    before = target.read_bytes()

    def broken_save(self: Image.Image, fp: object, *args: object, **kwargs: object) -> None:
        Path(str(fp)).write_bytes(b"\x89PNG partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Image.Image, "save", broken_save)
    with pytest.raises(WiseError, match="No space left"):
        write_image(torch.ones(1, 3, 8, 8), target)
    with pytest.raises(WiseError):
        write_image(torch.ones(1, 3, 8, 8), tmp_path / "new.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png"]
    assert target.read_bytes() == before


# ----- limits checked from the header, before decoding -----------------------------------------------------------

HUGE = (30000, 30000)
HUGE_MESSAGE = (
    ": 30000x30000 pixels (900.0 megapixels) is more than the limit of 64.0 megapixels; "
    "reduce the image or raise the limit with --max-pixels or WISE_MAX_PIXELS"
)


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bytes(width: int, height: int, depth: int = 8, colour: int = 2, idat: bytes | None = None) -> bytes:
    """A PNG whose IHDR (with a valid CRC) claims ``width`` x ``height``, with little or no image data."""
    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    data = zlib.compress(bytes(64)) if idat is None else idat
    return formats._PNG_MAGIC + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", data) + png_chunk(b"IEND", b"")


def jpeg_claiming(photo: np.ndarray, width: int, height: int) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(photo).save(buffer, format="JPEG")
    data = bytearray(buffer.getvalue())
    sof = data.index(b"\xff\xc0")
    data[sof + 5 : sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def tiff_claiming(data: bytes, width: int, height: int) -> bytes:
    """A little-endian TIFF with the first page's ImageWidth and ImageLength tags replaced."""
    out = bytearray(data)
    assert out[:4] == b"II*\x00"
    ifd = struct.unpack_from("<I", out, 4)[0]
    for i in range(struct.unpack_from("<H", out, ifd)[0]):
        entry = ifd + 2 + 12 * i
        tag, kind = struct.unpack_from("<HH", out, entry)
        if tag in (256, 257):
            struct.pack_into("<H" if kind == 3 else "<I", out, entry + 8, width if tag == 256 else height)
    return bytes(out)


def webp_claiming(width: int, height: int) -> bytes:
    vp8x = b"VP8X" + struct.pack("<I", 10) + bytes(4) + (width - 1).to_bytes(3, "little")
    vp8x += (height - 1).to_bytes(3, "little")
    return b"RIFF" + struct.pack("<I", 4 + len(vp8x)) + b"WEBP" + vp8x


def tiff_bytes(array: np.ndarray, **options: object) -> bytes:
    buffer = io.BytesIO()
    tifffile.imwrite(buffer, array, **options)
    return buffer.getvalue()


@pytest.fixture
def claiming_huge(photo: np.ndarray) -> dict[str, bytes]:
    """Small files of every decoding path whose headers claim 30000 x 30000 pixels."""
    rgb8 = tiff_bytes(photo, photometric="rgb")
    float_rgb = tiff_bytes(photo.astype(np.float32) / 255, photometric="rgb")
    return {
        "png": png_bytes(*HUGE),
        "png16": png_bytes(*HUGE, depth=16, colour=6),
        "jpeg": jpeg_claiming(photo, *HUGE),
        "webp": webp_claiming(16383, 16383),
        "tiff": tiff_claiming(rgb8, *HUGE),
        "float-tiff": tiff_claiming(float_rgb, *HUGE),
    }


def no_warnings(call: Callable[[], object]) -> object:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = call()
    assert [str(w.message) for w in caught] == []
    return result


def test_pixel_limit_is_checked_from_the_header(tmp_path: Path, claiming_huge: dict[str, bytes]) -> None:
    for kind, content in claiming_huge.items():
        path = tmp_path / f"{kind}.img"
        path.write_bytes(content)
        start = time.perf_counter()
        for read in (lambda: read_image(path), lambda: decode_image_bytes(content, f"{kind}.upload")):
            with pytest.raises(WiseError) as info:
                no_warnings(read)
            message = str(info.value)
            if kind == "webp":
                assert "16383x16383 pixels (268.4 megapixels) is more than the limit of 64.0 megapixels" in message
            else:
                assert message in (f"{path}{HUGE_MESSAGE}", f"{kind}.upload{HUGE_MESSAGE}")
        assert time.perf_counter() - start < 2.0, kind
    assert Image.MAX_IMAGE_PIXELS == PILLOW_LIMIT


PILLOW_LIMIT = Image.MAX_IMAGE_PIXELS


def test_the_pypng_and_tifffile_paths_check_the_header_too(tmp_path: Path, photo: np.ndarray) -> None:
    data = png_bytes(300, 200, depth=16, colour=6)
    with pytest.raises(WiseError, match=r"x: 300x200 pixels \(0\.06 megapixels\) is more than the limit of 1e-05"):
        formats.pypng_array(io.BytesIO(data), data[:64], "x", 10)
    tiff = tiff_bytes(ramp16()[..., None].repeat(3, axis=2), photometric="rgb")
    with pytest.raises(WiseError, match=r"x: 40x32 pixels"):
        formats.tifffile_array(io.BytesIO(tiff), "x", 10)


def test_pillow_does_not_check_or_warn_first(tmp_path: Path) -> None:
    # 10000 x 9000 is above Pillow's warning threshold; raising our limit must let it through to decoding
    path = tmp_path / "big.png"
    path.write_bytes(png_bytes(10000, 9000, depth=8, colour=0))
    assert 10000 * 9000 > PILLOW_LIMIT
    with pytest.raises(WiseError, match="corrupt or unreadable image data"):
        no_warnings(lambda: read_image(path, max_pixels=100_000_000))
    assert Image.MAX_IMAGE_PIXELS == PILLOW_LIMIT


def test_limit_from_the_argument_and_the_environment(
    tmp_path: Path, photo: np.ndarray, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "a.png"
    Image.fromarray(photo).save(path)  # 64 x 48 = 3072 pixels
    assert wio.pixel_limit() == wio.DEFAULT_MAX_PIXELS == 64_000_000
    assert read_image(path, max_pixels=3072).shape == (1, 3, 48, 64)
    with pytest.raises(WiseError, match=r"64x48 pixels \(0\.0031 megapixels\) is more than the limit of 0\.0031"):
        read_image(path, max_pixels=3071)
    monkeypatch.setenv(wio.MAX_PIXELS_ENV, "3000")
    assert wio.pixel_limit() == 3000
    with pytest.raises(WiseError, match="WISE_MAX_PIXELS"):
        read_image(path)
    with pytest.raises(WiseError, match="limit of 0.003 megapixels"):
        decode_image_bytes(path.read_bytes(), "a.png")
    assert read_image(path, max_pixels=5000).shape == (1, 3, 48, 64)  # the argument wins
    monkeypatch.setenv(wio.MAX_PIXELS_ENV, " ")
    assert wio.pixel_limit() == wio.DEFAULT_MAX_PIXELS
    for bad in ("abc", "0", "-5", "1e8", "2.5"):
        monkeypatch.setenv(wio.MAX_PIXELS_ENV, bad)
        with pytest.raises(WiseError) as info:
            read_image(path)
        assert str(info.value) == (
            f"WISE_MAX_PIXELS={bad!r}: not a positive whole number of pixels; unset it or set e.g. 100000000"
        )
    monkeypatch.delenv(wio.MAX_PIXELS_ENV)
    for bad in (0, -1, 2.5, True):
        with pytest.raises(WiseError, match="pixel limit"):
            read_image(path, max_pixels=bad)  # type: ignore[arg-type]


def test_special_files_and_size_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    os.mkfifo(tmp_path / "fifo.png")
    for path, words in ((tmp_path / "fifo.png", "named pipe"), (Path("/dev/zero"), "character device")):
        start = time.perf_counter()
        expect_error(path, words, "not a regular file")
        assert time.perf_counter() - start < 1.0
    monkeypatch.setattr(io_read, "MAX_IMAGE_BYTES", 100)
    (tmp_path / "big.png").write_bytes(png_bytes(8, 8) + bytes(200))
    expect_error(tmp_path / "big.png", "MB is more than the limit")
    with pytest.raises(WiseError, match="upload.png: 0.0 MB is more than the limit"):
        decode_image_bytes(png_bytes(8, 8) + bytes(200), "upload.png")


def test_data_inflating_beyond_the_header_is_refused(tmp_path: Path) -> None:
    bomb = png_bytes(8, 8, depth=16, colour=6, idat=zlib.compress(bytes(20_000_000)))
    (tmp_path / "bomb.png").write_bytes(bomb)
    expect_error(tmp_path / "bomb.png", "corrupt", "inflates to more than the image size")
    rgb16 = np.stack([ramp16()] * 3, axis=-1)
    shrunk = tiff_claiming(tiff_bytes(rgb16, photometric="rgb", compression="zlib"), 2, 2)
    (tmp_path / "bomb.tif").write_bytes(shrunk)
    expect_error(tmp_path / "bomb.tif", "corrupt", "inflates to more than the image size")


def test_float_tiff_read_the_same_from_files_and_bytes(tmp_path: Path) -> None:
    grey = (ramp16().astype(np.float32) / 65535) * 1.2 - 0.1  # outside [0, 1] at both ends
    rgb = np.stack([grey, grey[::-1], 1 - grey], axis=-1)
    for name, array, options in (("grey.tif", grey, {}), ("rgb.tif", rgb, {"photometric": "rgb"})):
        tifffile.imwrite(tmp_path / name, array, **options)
        from_file = no_warnings(lambda: read_image(tmp_path / name))
        from_bytes = no_warnings(lambda: decode_image_bytes((tmp_path / name).read_bytes(), name))
        assert isinstance(from_file, torch.Tensor) and torch.equal(from_file, from_bytes)
        expected = np.clip(array if array.ndim == 3 else np.repeat(array[..., None], 3, axis=2), 0, 1)
        assert float((from_file[0].permute(1, 2, 0) - torch.from_numpy(expected)).abs().max()) < 1e-6


def test_bytes_messages_name_the_upload(tmp_path: Path, photo: np.ndarray) -> None:
    buffer = io.BytesIO()
    Image.fromarray(photo).save(buffer, format="PNG")
    data = buffer.getvalue()
    assert torch.equal(decode_image_bytes(data, "a.png"), image_to_tensor(photo))
    assert torch.equal(decode_image_bytes(bytearray(data), "a.png"), image_to_tensor(photo))
    for content, words in ((b"", "the file is empty"), (b"hello", "not an image"), (data[:200], "corrupt")):
        with pytest.raises(WiseError) as info:
            decode_image_bytes(content, "upload.png")
        message = str(info.value)
        assert message.startswith("upload.png: ") and words in message and tempfile.gettempdir() not in message
    with pytest.raises(WiseError, match="bytes"):
        decode_image_bytes("text", "upload.png")  # type: ignore[arg-type]
    assert not [p for p in Path(tempfile.gettempdir()).glob("wise-image-*")]


def test_reads_from_threads_leave_pillow_as_it_was(tmp_path: Path, photo: np.ndarray) -> None:
    Image.fromarray(photo).save(tmp_path / "a.png")
    (tmp_path / "big.png").write_bytes(png_bytes(*HUGE))

    def read(i: int) -> str:
        try:
            return str(read_image(tmp_path / ("big.png" if i % 2 else "a.png")).shape)
        except WiseError as e:
            return "refused" if "30000x30000" in str(e) else str(e)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with ThreadPoolExecutor(4) as pool:
            results = list(pool.map(read, range(16)))
    assert results == ["torch.Size([1, 3, 48, 64])", "refused"] * 8
    assert caught == [] and Image.MAX_IMAGE_PIXELS == PILLOW_LIMIT


def test_libtiff_errors_are_not_printed(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    data = bytearray(tiff_bytes(np.full((8, 8, 3), 100, np.uint8), photometric="rgb", compression="zlib"))
    ifd = struct.unpack_from("<I", data, 4)[0]
    for i in range(struct.unpack_from("<H", data, ifd)[0]):
        if struct.unpack_from("<H", data, ifd + 2 + 12 * i)[0] == 273:  # StripOffsets: now an unknown tag
            struct.pack_into("<H", data, ifd + 2 + 12 * i, 65001)
    (tmp_path / "no-strips.tif").write_bytes(bytes(data))
    expect_error(tmp_path / "no-strips.tif", "corrupt")
    assert capfd.readouterr() == ("", "")
    print("stderr works again", file=sys.stderr)
    assert capfd.readouterr().err == "stderr works again\n"
