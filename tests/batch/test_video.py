"""Videos stylized frame by frame (wise.batch.video): size, rate, frame times and sound kept,
still scenes stay still, bad inputs refused before any work, Ctrl-C leaves nothing behind,
painted masks smoothed over time."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest
import torch
from skimage import data

from wise.batch.look import Look, LookSpec, Rendered
from wise.batch.video import (
    VIDEO_OUTPUT_SUFFIXES,
    VideoResult,
    check_video_output,
    partial_path,
    probe,
    stylize_video,
)
from wise.errors import WiseError


def moving_pattern(index: int, width: int, height: int) -> np.ndarray:
    """A frame of a pattern that moves a little on each frame."""
    y, x = np.mgrid[0:height, 0:width]
    shift = 3 * index
    red = ((x + shift) // 16 + y // 16) % 2 * 200 + 20
    green = (x * 255 // max(1, width - 1)).astype(np.int64)
    blue = np.full_like(x, (index * 7) % 256)
    return np.stack([red, green, blue], axis=-1).astype(np.uint8)


def still_picture(width: int, height: int) -> np.ndarray:
    return np.ascontiguousarray(data.chelsea()[40 : 40 + height, 100 : 100 + width])


def make_clip(
    path: Path,
    frames: int,
    width: int = 96,
    height: int = 64,
    rate: int = 24,
    picture=moving_pattern,
    audio: str | None = None,
    codec: str = "libx264",
) -> Path:
    """Write a clip with PyAV: ``picture(i, width, height)`` on frame i, with a 440 Hz sine of
    the same length encoded with ``audio`` when given."""
    container = av.open(str(path), "w")
    video = container.add_stream(codec, rate=rate)
    video.width, video.height, video.pix_fmt = width, height, "yuv420p"
    sound = None
    sample_rate = 48000
    if audio is not None:
        sound = container.add_stream(audio, rate=sample_rate)
        sound.codec_context.layout = "stereo"
    samples = 0
    for index in range(frames):
        frame = av.VideoFrame.from_ndarray(picture(index, width, height), format="rgb24")
        frame.pts, frame.time_base = index, Fraction(1, rate)
        for packet in video.encode(frame):
            container.mux(packet)
        if sound is not None:
            count = sample_rate // rate
            wave = 0.3 * np.sin(2 * np.pi * 440 * (samples + np.arange(count)) / sample_rate)
            stereo = np.stack([wave, wave]).astype(np.float32)
            chunk = av.AudioFrame.from_ndarray(stereo, format="fltp", layout="stereo")
            chunk.sample_rate, chunk.pts, chunk.time_base = sample_rate, samples, Fraction(1, sample_rate)
            samples += count
            for packet in sound.encode(chunk):
                container.mux(packet)
    for packet in video.encode(None):
        container.mux(packet)
    if sound is not None:
        for packet in sound.encode(None):
            container.mux(packet)
    container.close()
    return path


def decoded_frames(path: Path) -> list[av.VideoFrame]:
    with av.open(str(path)) as container:
        return list(container.decode(video=0))


def stream_seconds(path: Path, kind: str) -> float:
    """The duration of the first stream of ``kind``, from its packets' times."""
    with av.open(str(path)) as container:
        stream = getattr(container.streams, kind)[0]
        end = 0.0
        for packet in container.demux(stream):
            if packet.pts is not None:
                end = max(end, float((packet.pts + (packet.duration or 0)) * packet.time_base))
        return end


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".partial" in p.name)


@pytest.fixture(scope="module")
def xdog() -> Look:
    return Look(LookSpec("xdog", preset="portrait"))


class StubLook:
    """Renders the frame itself (or a half-size copy, as a translator would), optionally
    raising ``error`` on render number ``fail_at``."""

    paints = False

    def __init__(self, fail_at: int | None = None, error: BaseException | None = None, half: bool = False) -> None:
        self.fail_at, self.error, self.half = fail_at, error, half
        self.calls = 0
        self.keeps_size = not half

    def masks(self, image: torch.Tensor) -> None:
        return None

    def render(self, image: torch.Tensor, masks: torch.Tensor | None = None) -> Rendered:
        self.calls += 1
        if self.fail_at is not None and self.calls == self.fail_at:
            raise self.error
        if self.half:
            image = torch.nn.functional.interpolate(image, scale_factor=0.5, mode="area")
        return Rendered(1.0 - image)


class PaintingStub:
    """Paints masks ``(1, 2, 4, 4)`` from each frame's mean colour, as a painting model would,
    and records what it predicted and what it was asked to render with."""

    paints = True
    keeps_size = True

    def __init__(self) -> None:
        self.predicted: list[torch.Tensor] = []
        self.used: list[torch.Tensor] = []

    def masks(self, image: torch.Tensor) -> torch.Tensor:
        mean = image.mean(dim=(2, 3))[:, :2]
        masks = mean[:, :, None, None].expand(1, 2, 4, 4).clone()
        self.predicted.append(masks)
        return masks

    def render(self, image: torch.Tensor, masks: torch.Tensor | None = None) -> Rendered:
        if masks is None:
            masks = self.masks(image)
        self.used.append(masks.clone())
        return Rendered(image, masks)


def test_size_rate_frames_and_times_are_kept(tmp_path: Path, xdog: Look) -> None:
    source = make_clip(tmp_path / "clip.mp4", frames=30, width=320, height=180, rate=30)
    output = tmp_path / "styled.mp4"
    result = stylize_video(xdog, source, output)
    assert result == VideoResult(frames=30, seconds=result.seconds, interrupted=False)
    info = probe(output)
    assert (info.width, info.height, info.frames, info.rate) == (320, 180, 30, Fraction(30))
    assert info.duration == pytest.approx(probe(source).duration, abs=1e-3)
    assert [f.time for f in decoded_frames(output)] == pytest.approx([f.time for f in decoded_frames(source)])
    assert leftovers(tmp_path) == []


def test_a_still_scene_stays_still(tmp_path: Path, xdog: Look) -> None:
    source = make_clip(tmp_path / "still.mp4", frames=12, width=160, height=128,
                       picture=lambda i, w, h: still_picture(w, h))  # fmt: skip
    picture = torch.from_numpy(still_picture(160, 128)).permute(2, 0, 1)[None].float() / 255.0
    assert torch.equal(xdog.render(picture).image, xdog.render(picture).image)  # deterministic
    output = tmp_path / "still-xdog.mp4"
    stylize_video(xdog, source, output)
    frames = [f.to_ndarray(format="rgb24").astype(np.float64) / 255.0 for f in decoded_frames(output)]
    assert len(frames) == 12
    assert frames[0].std() > 0.05  # lines were drawn
    for before, after in zip(frames, frames[1:]):
        assert np.abs(after - before).mean() <= 1 / 255


@pytest.mark.parametrize(("audio", "suffix", "codec"), [("aac", ".mp4", "aac"), ("aac", ".webm", "opus")])
def test_sound_is_kept(tmp_path: Path, audio: str, suffix: str, codec: str) -> None:
    source = make_clip(tmp_path / "sound.mp4", frames=24, audio=audio)
    output = tmp_path / f"styled{suffix}"
    stylize_video(StubLook(), source, output)
    info = probe(output)
    assert info.has_audio and info.audio_codec == codec  # copied to mp4, re-encoded to Opus for WebM
    assert stream_seconds(output, "audio") == pytest.approx(stream_seconds(source, "audio"), abs=0.05)
    assert stream_seconds(output, "video") == pytest.approx(1.0, abs=2e-3)  # WebM counts milliseconds


def test_a_translator_sets_the_video_size(tmp_path: Path) -> None:
    source = make_clip(tmp_path / "clip.mkv", frames=6, width=96, height=64)
    output = tmp_path / "small.mkv"
    assert stylize_video(StubLook(half=True), source, output).frames == 6
    info = probe(output)
    assert (info.width, info.height) == (48, 32)


def test_not_a_video_is_refused(tmp_path: Path) -> None:
    text = tmp_path / "notes.mp4"
    text.write_text("not a video at all\n" * 20)
    with pytest.raises(WiseError, match="not a video") as error:
        probe(text)
    assert "\n" not in str(error.value)
    with pytest.raises(WiseError, match="no such file"):
        probe(tmp_path / "missing.mp4")
    with pytest.raises(WiseError, match="not a video"):
        stylize_video(StubLook(), text, tmp_path / "out.mp4")
    assert not (tmp_path / "out.mp4").exists()


def test_sound_alone_is_refused(tmp_path: Path) -> None:
    sound = tmp_path / "sound.m4a"
    container = av.open(str(sound), "w")
    stream = container.add_stream("aac", rate=48000)
    wave = (0.2 * np.sin(np.arange(48000) / 10)).astype(np.float32)[None]
    chunk = av.AudioFrame.from_ndarray(wave, format="fltp", layout="mono")
    chunk.sample_rate = 48000
    for packet in [*stream.encode(chunk), *stream.encode(None)]:
        container.mux(packet)
    container.close()
    with pytest.raises(WiseError, match="has no video stream; pass a video with pictures"):
        probe(sound)


def test_bad_outputs_are_refused_before_any_work(tmp_path: Path) -> None:
    source = make_clip(tmp_path / "clip.mp4", frames=2)
    look = StubLook()
    with pytest.raises(WiseError, match=r"\.mp4, \.mkv, \.webm, \.mov"):
        stylize_video(look, source, tmp_path / "out.avi")
    with pytest.raises(WiseError, match="libx264"):
        check_video_output(tmp_path / "out.mp4", "libx246")
    with pytest.raises(WiseError, match="cannot hold"):
        check_video_output(tmp_path / "out.webm", "libx264")
    with pytest.raises(WiseError, match="--crf"):
        stylize_video(look, source, tmp_path / "out.mp4", crf=70)
    with pytest.raises(WiseError, match="--quality-preset"):
        stylize_video(look, source, tmp_path / "out.mp4", quality_preset="quick")
    with pytest.raises(WiseError, match="temporal-smoothing"):
        stylize_video(look, source, tmp_path / "out.mp4", temporal_smoothing=1.0)
    with pytest.raises(WiseError, match="overwrite the source"):
        stylize_video(look, source, source)
    assert look.calls == 0
    assert check_video_output(tmp_path / "out.webm", None) == "libvpx-vp9"
    assert sorted(VIDEO_OUTPUT_SUFFIXES) == [".mkv", ".mov", ".mp4", ".webm"]


def test_ctrl_c_leaves_nothing(tmp_path: Path) -> None:
    source = make_clip(tmp_path / "clip.mp4", frames=24)
    output = tmp_path / "styled.mp4"
    result = stylize_video(StubLook(fail_at=6, error=KeyboardInterrupt()), source, output)
    assert result.interrupted and result.frames == 5
    assert not output.exists() and not partial_path(output).exists()
    assert leftovers(tmp_path) == []


def test_an_error_leaves_nothing_and_keeps_an_old_output(tmp_path: Path) -> None:
    source = make_clip(tmp_path / "clip.mp4", frames=12)
    output = tmp_path / "styled.webm"
    output.write_bytes(b"an earlier result")
    with pytest.raises(RuntimeError, match="boom"):
        stylize_video(StubLook(fail_at=4, error=RuntimeError("boom")), source, output)
    assert output.read_bytes() == b"an earlier result"
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("amount", [0.0, 0.6])
def test_painted_masks_are_smoothed_over_time(tmp_path: Path, amount: float) -> None:
    source = make_clip(tmp_path / "clip.mp4", frames=10)
    look = PaintingStub()
    stylize_video(look, source, tmp_path / "styled.mp4", temporal_smoothing=amount)
    predicted, used = look.predicted, look.used
    assert len(predicted) == len(used) == 10
    assert torch.equal(used[0], predicted[0])
    for index in range(1, 10):
        expected = amount * used[index - 1] + (1 - amount) * predicted[index]
        assert torch.allclose(used[index], expected, atol=1e-6)
    if amount:
        assert not torch.allclose(used[-1], predicted[-1], atol=1e-4)  # the smoothing did something
