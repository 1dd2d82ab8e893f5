"""Reading and writing images: formats, bit depths, orientation, refusals, atomic writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile
import torch
from PIL import Image
from skimage import data

import wise.io as wio
from wise.errors import WiseError
from wise.io import image_to_tensor, read_image, tensor_to_image, write_image


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
    assert wio._needs_pypng(bad)
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

    monkeypatch.setattr(wio.tempfile, "mkstemp", refuse)
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
