import re
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image, ImageSequence

from wise.optimize.report import VIRIDIS_STOPS, heatmap, write_animation, write_report
from wise.params import ParamSpec


class StandIn:
    """A minimal effect-like object."""

    name = "tiny<fx>"
    param_specs = (
        ParamSpec("alpha", 0.0, 2.0, 1.0),
        ParamSpec("beta&gamma", -1.0, 3.0, 0.0),
    )

    @property
    def param_names(self) -> list[str]:
        return [s.name for s in self.param_specs]


def _images() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    return tuple(torch.rand(1, 3, 12, 16, generator=g) for _ in range(3))  # type: ignore[return-value]


METRICS = {"l1": 0.125, "psnr": 27.5, "iterations": 7, "note": "ok"}
LOSSES = [1.0, 0.8, 0.5, 0.4, 0.35, 0.3, 0.29]


def _write(tmp_path: Path, params: torch.Tensor) -> str:
    path = tmp_path / "report.html"
    write_report(path, StandIn(), *_images(), params, LOSSES, METRICS)
    assert path.is_file()
    assert not [p for p in tmp_path.iterdir() if p.name != "report.html"]
    return path.read_text(encoding="utf-8")


def test_local_report(tmp_path: Path) -> None:
    masks = torch.stack([torch.linspace(-0.5, 0.5, 20).view(4, 5), torch.zeros(4, 5)])[None]
    text = _write(tmp_path, masks)
    assert "tiny&lt;fx&gt;" in text and "tiny<fx>" not in text
    assert text.count("<img") == 3 + 2
    assert len(re.findall(r'src="data:image/png;base64,', text)) == 5
    assert "http://" not in text.replace('xmlns="http://www.w3.org/2000/svg"', "")
    assert "<script" not in text
    points = re.search(r'<polyline[^>]*points="([^"]*)"', text)
    assert "<svg" in text and points is not None
    assert len(points.group(1).split()) == len(LOSSES)
    assert ">iteration<" in text and ">loss<" in text
    for value in ("0.125", "27.5", "7", "ok", "l1", "psnr"):
        assert f">{value}<" in text
    assert "alpha" in text and "beta&amp;gamma" in text and "beta&gamma" not in text
    assert "[0, 2]" in text and "[-1, 3]" in text
    assert "min 0 · mean 1 · max 2" in text and "min 1 · mean 1 · max 1" in text


def test_global_report(tmp_path: Path) -> None:
    params = torch.tensor([[0.0, 0.25]])
    text = _write(tmp_path, params)
    assert text.count("<img") == 3
    assert "<td>1</td>" in text and "<td>2</td>" in text
    assert "[0, 2]" in text and "[-1, 3]" in text


def test_report_rejects_bad_params(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        write_report(tmp_path / "r.html", StandIn(), *_images(), torch.zeros(1, 3), LOSSES, METRICS)
    assert not list(tmp_path.iterdir())


def test_report_downscales_images(tmp_path: Path) -> None:
    big = torch.rand(1, 3, 40, 600)
    path = tmp_path / "r.html"
    write_report(path, StandIn(), big, big, big, torch.zeros(1, 2), [1.0], {})
    widths = [int(w) for w in re.findall(r'<img[^>]*width="(\d+)"', path.read_text())]
    assert widths == [512, 512, 512]


def test_animation(tmp_path: Path) -> None:
    frames = [np.full((200, 500, 3), 40 * i, np.uint8) for i in range(4)]
    path = tmp_path / "run.gif"
    write_animation(path, frames, duration_ms=50)
    with Image.open(path) as gif:
        assert gif.format == "GIF"
        assert max(gif.size) <= 384
        assert sum(1 for _ in ImageSequence.Iterator(gif)) == 4
        assert gif.info.get("loop") == 0


def test_animation_needs_frames(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        write_animation(tmp_path / "a.gif", [])
    assert not list(tmp_path.iterdir())


def test_heatmap_stops_and_clamping() -> None:
    values = np.array([[1.0, 3.0, 2.0], [-10.0, 10.0, np.nan]])
    out = heatmap(values, 1.0, 3.0)
    assert out.shape == (2, 3, 3) and out.dtype == np.uint8
    first, last, middle = VIRIDIS_STOPS[0], VIRIDIS_STOPS[-1], VIRIDIS_STOPS[2]
    np.testing.assert_array_equal(out[0, 0], first)
    np.testing.assert_array_equal(out[0, 1], last)
    np.testing.assert_array_equal(out[0, 2], middle)
    np.testing.assert_array_equal(out[1, 0], first)
    np.testing.assert_array_equal(out[1, 1], last)
    np.testing.assert_array_equal(out[1, 2], first)
