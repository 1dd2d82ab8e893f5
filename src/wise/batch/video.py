"""Stylize a video frame by frame: decoded, rendered by a :class:`~wise.batch.look.Look` and
encoded again, through PyAV.

The result keeps the source's size (a translator's has its working size), frame rate, frame
times and duration; its sound is copied as it is when the container accepts the codec, else
re-encoded (AAC, or Opus in WebM). Frames pass through a short queue between a decoding thread
and the render, so memory does not grow with the video's length.

Every effect is deterministic, so a still scene stays still. A model that paints masks predicts
them anew on each frame; ``temporal_smoothing`` averages them exponentially over time, so that
small changes between frames do not make the look flicker (after a cut, the old scene's share
fades as its powers: at 0.3, below 3 % after three frames).

The video is written to a hidden temporary file next to the output (``.NAME.partial.mp4``) and
takes the output's name only when complete. An error or Ctrl-C removes it: a partly stylized
video is not kept (the output, if it existed, is left as it was).

Example::

    from wise.batch.look import Look, LookSpec
    from wise.batch.video import stylize_video

    result = stylize_video(Look(LookSpec("xdog", preset="portrait")), "clip.mp4", "clip-xdog.mp4")
"""

from __future__ import annotations

import difflib
import io
import os
import queue
import sys
import threading
import time
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import av
import numpy as np
import torch

from wise.batch.look import Look
from wise.errors import WiseError, size_text
from wise.interrupt import CtrlC, ctrl_c
from wise.io import image_to_tensor, tensor_to_image
from wise.io.common import one_line

VIDEO_OUTPUT_SUFFIXES = (".mp4", ".mkv", ".webm", ".mov")
CONTAINER_FORMATS = {".mp4": "mp4", ".mkv": "matroska", ".webm": "webm", ".mov": "mov"}
DEFAULT_CODECS = {".mp4": "libx264", ".mkv": "libx264", ".webm": "libvpx-vp9", ".mov": "libx264"}
DEFAULT_CRF = {"libx264": 18, "libvpx-vp9": 32}
"""CRF when none is given. The scales differ: x264's runs to 51 and 18 is close to transparent;
VP9's runs to 63 and 32 is the value commonly recommended for HD VP9."""
CRF_RANGES = {
    "libx264": 51,
    "libx264rgb": 51,
    "libx265": 51,
    "libvpx": 63,
    "libvpx-vp9": 63,
    "libaom-av1": 63,
    "libsvtav1": 63,
}
"""The encoders that take a CRF, and its largest value (0 is the best quality)."""
QUALITY_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")
"""Encoder speed presets (x264's names): faster ones write larger files at the same CRF."""
_VPX_SPEED = {
    "ultrafast": 8, "superfast": 7, "veryfast": 6, "faster": 5, "fast": 4,
    "medium": 3, "slow": 2, "slower": 1, "veryslow": 0,
}  # fmt: skip
"""libvpx's ``cpu-used`` for each preset (8 and 7 need its realtime mode)."""
AUDIO_COPIED = {
    ".webm": frozenset({"opus", "vorbis"}),
    ".mp4": frozenset({"aac", "mp3", "opus", "ac3", "alac"}),
    ".mov": frozenset({"aac", "mp3", "ac3", "alac"}),  # QuickTime files cannot hold Opus
    ".mkv": None,  # any codec
}
"""The sound codecs copied as they are into each container (when its muxer accepts the stream);
others are re-encoded."""
AUDIO_ENCODERS = {".mp4": "aac", ".mkv": "aac", ".mov": "aac", ".webm": "libopus"}
_AUDIO_BIT_RATE = 160_000
_QUEUE_FRAMES = 4
"""Decoded frames waiting for the render at most."""


@dataclass(frozen=True)
class VideoInfo:
    """What :func:`probe` found: the first video stream's size, frame count (0 when the
    container does not say), average frame rate and the duration in seconds; whether there is
    sound and its codec."""

    width: int
    height: int
    frames: int
    rate: Fraction
    duration: float
    has_audio: bool
    audio_codec: str | None = None

    @property
    def expected_frames(self) -> int:
        """The frame count, or an estimate from the duration and rate when it is unknown."""
        return self.frames or max(0, round(self.duration * float(self.rate)))


@dataclass
class VideoResult:
    """The outcome of :func:`stylize_video`: frames written (reached, when interrupted), the
    time it took and whether Ctrl-C stopped it (then no output was written)."""

    frames: int
    seconds: float
    interrupted: bool = False


@dataclass(frozen=True)
class _Encoding:
    suffix: str
    format: str
    codec: str
    options: dict[str, str]


def _video_stream(container: Any) -> Any | None:
    """The first stream of moving pictures (cover art of a sound file does not count)."""
    for stream in container.streams.video:
        if not stream.disposition & av.stream.Disposition.attached_pic:
            return stream
    return None


def _audio_stream(container: Any) -> Any | None:
    return container.streams.audio[0] if container.streams.audio else None


def _reason(error: BaseException) -> str:
    return getattr(error, "strerror", None) or one_line(error)


def _open_input(source: Path) -> Any:
    if not source.exists():
        raise WiseError(f"{source}: no such file; check the path")
    if source.is_dir():
        raise WiseError(f"{source}: a folder, not a video; pass a video file")
    try:
        container = av.open(str(source), metadata_errors="ignore")
    except (av.FFmpegError, OSError, UnicodeDecodeError) as error:
        raise WiseError(f"{source}: not a video ({_reason(error)}); pass an .mp4, .mkv, .webm or .mov file") from None
    name = container.format.name
    if name == "image2" or name.endswith("_pipe"):
        container.close()
        raise WiseError(f"{source}: not a video (an image); stylize it as an image: wise apply EFFECT {source.name}")
    return container


def probe(source: str | os.PathLike[str]) -> VideoInfo:
    """The size, frame rate, length and sound of the video ``source``; raises
    :class:`WiseError` when it is not a video or has no pictures."""
    source = Path(source)
    container = _open_input(source)
    try:
        video = _video_stream(container)
        if video is None:
            raise WiseError(f"{source}: has no video stream; pass a video with pictures")
        context = video.codec_context
        if not context.width or not context.height:
            raise WiseError(f"{source}: not a video (its picture size is unknown); pass another file")
        rate = video.average_rate or video.guessed_rate or video.base_rate or Fraction(25)
        if video.duration is not None and video.time_base is not None:
            duration = float(video.duration * video.time_base)
        elif container.duration is not None:
            duration = container.duration / av.time_base
        else:
            duration = 0.0
        audio = _audio_stream(container)
        return VideoInfo(
            width=context.width,
            height=context.height,
            frames=max(0, video.frames or 0),
            rate=Fraction(rate),
            duration=duration,
            has_audio=audio is not None,
            audio_codec=None if audio is None else audio.codec_context.codec.canonical_name,
        )
    finally:
        container.close()


def _video_encoders() -> list[str]:
    names = []
    for name in av.codecs_available:
        try:
            if av.Codec(name, "w").type == "video":
                names.append(name)
        except Exception:  # noqa: BLE001 (a decoder only, or not usable here)
            continue
    return sorted(names)


def _unknown_codec(codec: str) -> WiseError:
    known = _video_encoders()
    close = difflib.get_close_matches(codec, known, n=4, cutoff=0.5)
    suggestions = list(dict.fromkeys([*close, "libx264", "libvpx-vp9"]))
    return WiseError(f"--codec {codec}: not a video encoder here; try {', '.join(suggestions)}")


def check_video_output(
    output: str | os.PathLike[str],
    codec: str | None = None,
    *,
    crf: float | None = None,
    quality_preset: str | None = None,
) -> str:
    """Check where and how a video will be written, before any work: the output's suffix (one of
    :data:`VIDEO_OUTPUT_SUFFIXES`), the encoder (``None``: the container's default), that the
    container takes it, and ``crf`` and ``quality_preset`` for it. Returns the encoder's name."""
    return _encoding(Path(output), codec, crf, quality_preset).codec


def _encoding(output: Path, codec: str | None, crf: float | None, quality_preset: str | None) -> _Encoding:
    suffix = output.suffix.lower()
    if suffix not in CONTAINER_FORMATS:
        raise WiseError(
            f"{output}: a video is written as {', '.join(VIDEO_OUTPUT_SUFFIXES)}; give the output one of these suffixes"
        )
    fmt = CONTAINER_FORMATS[suffix]
    codec = DEFAULT_CODECS[suffix] if codec is None else codec
    try:
        kind = av.Codec(codec, "w").type
    except Exception:  # noqa: BLE001 (unknown name, or a decoder only)
        raise _unknown_codec(codec) from None
    if kind != "video":
        raise WiseError(
            f"--codec {codec}: encodes {kind}, not video; pass a video encoder such as libx264 or libvpx-vp9"
        )
    probe_container = av.open(io.BytesIO(), "w", format=fmt)
    try:
        probe_container.add_stream(codec)
    except ValueError:
        raise WiseError(
            f"--codec {codec}: {suffix} files cannot hold it; use {DEFAULT_CODECS[suffix]} or another container"
        ) from None
    finally:
        probe_container.close()
    options: dict[str, str] = {}
    if crf is None:
        crf = DEFAULT_CRF.get(codec)
    elif codec not in CRF_RANGES:
        raise WiseError(f"--crf: {codec} takes no CRF; leave it out, or use {', '.join(CRF_RANGES)}")
    if crf is not None:
        top = CRF_RANGES[codec]
        if not isinstance(crf, (int, float)) or not 0 <= crf <= top or int(crf) != crf:
            raise WiseError(f"--crf {crf}: {codec} takes a whole number from 0 (best) to {top}")
        options["crf"] = str(int(crf))
        if codec in ("libvpx-vp9", "libaom-av1"):
            options["b"] = "0"  # constant quality rather than a bit rate capped by the CRF
    if quality_preset is not None and quality_preset not in QUALITY_PRESETS:
        raise WiseError(f"--quality-preset {quality_preset}: use one of {', '.join(QUALITY_PRESETS)}")
    if codec.startswith("libvpx"):
        speed = _VPX_SPEED[quality_preset or "fast"]  # libvpx's own default is several times slower
        options.update({"deadline": "realtime" if speed > 5 else "good", "cpu-used": str(speed)})
        if codec == "libvpx-vp9":
            options["row-mt"] = "1"
    elif codec in ("libx264", "libx264rgb", "libx265"):
        if quality_preset is not None:
            options["preset"] = quality_preset
    elif quality_preset is not None:
        raise WiseError(f"--quality-preset: {codec} has no speed presets; leave it out")
    return _Encoding(suffix, fmt, codec, options)


def check_smoothing(temporal_smoothing: float) -> float:
    """``temporal_smoothing`` checked: a number in [0, 1)."""
    if not isinstance(temporal_smoothing, (int, float)) or not 0.0 <= temporal_smoothing < 1.0:
        raise WiseError(f"--temporal-smoothing {temporal_smoothing}: use a number from 0 (off) up to, not including, 1")
    return float(temporal_smoothing)


def partial_path(output: str | os.PathLike[str]) -> Path:
    """The temporary file a video is written to before it takes the name ``output``."""
    output = Path(output)
    return output.with_name(f".{output.stem}.partial{output.suffix}")


class MaskSmoother:
    """Exponential smoothing of a painting model's masks over a video's frames:
    ``smoothed = a * previous + (1 - a) * predicted``; the first frame keeps its prediction."""

    def __init__(self, amount: float) -> None:
        self.amount = check_smoothing(amount)
        self.previous: torch.Tensor | None = None

    def __call__(self, predicted: torch.Tensor) -> torch.Tensor:
        previous = self.previous
        if previous is None or previous.shape != predicted.shape or self.amount == 0.0:
            smoothed = predicted
        else:
            smoothed = self.amount * previous + (1.0 - self.amount) * predicted
        self.previous = smoothed
        return smoothed


def _render(look: Look, image: torch.Tensor, smoother: MaskSmoother | None) -> torch.Tensor:
    if smoother is not None:
        predicted = look.masks(image)
        if predicted is not None:
            return look.render(image, masks=smoother(predicted)).image
    return look.render(image).image


_END = ("end",)


class _Reader(threading.Thread):
    """Demuxes the source in its own thread: decoded frames as RGB arrays, and the sound as
    packets (copied) or frames (re-encoded), in file order, through a short queue."""

    def __init__(self, source: Path, audio: str | None) -> None:
        super().__init__(name="wise-video-reader", daemon=True)
        self.source = source
        self.audio = audio  # None: left out; "copy": packets; "encode": decoded frames
        self.items: queue.Queue = queue.Queue(maxsize=_QUEUE_FRAMES)
        self.stopping = threading.Event()

    def _put(self, item: tuple) -> bool:
        while not self.stopping.is_set():
            try:
                self.items.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def run(self) -> None:
        try:
            with av.open(str(self.source), metadata_errors="ignore") as container:
                video = _video_stream(container)
                video.codec_context.thread_type = "AUTO"
                audio = _audio_stream(container) if self.audio else None
                streams = [video] if audio is None else [video, audio]
                size: dict[str, int] = {}
                for packet in container.demux(streams):
                    if packet.stream.index == video.index:
                        for frame in packet.decode():
                            size = size or {"width": frame.width, "height": frame.height}  # kept throughout
                            pixels = frame.to_ndarray(format="rgb24", **size)
                            item = ("video", pixels, frame.pts, frame.time_base, frame.duration)
                            if not self._put(item):
                                return
                    elif self.audio == "copy":
                        if packet.dts is not None and packet.size and not self._put(("audio", packet)):
                            return
                    else:
                        for frame in packet.decode():
                            if not self._put(("audio", frame)):
                                return
            self._put(_END)
        except BaseException as error:  # noqa: BLE001 (handed to the main thread, raised there)
            self._put(("error", error))

    def get(self) -> tuple:
        return self.items.get()

    def stop(self) -> None:
        self.stopping.set()
        while True:
            try:
                self.items.get_nowait()
            except queue.Empty:
                break
        self.join(timeout=10)


def _audio_mode(source: Path, info: VideoInfo, suffix: str) -> str | None:
    """How the sound goes into the output: ``"copy"`` (packets as they are), ``"encode"``, or
    None (there is none)."""
    if not info.has_audio:
        return None
    copied = AUDIO_COPIED[suffix]
    if copied is not None and info.audio_codec not in copied:
        return "encode"
    with av.open(str(source), metadata_errors="ignore") as container:
        return "copy" if _can_copy(CONTAINER_FORMATS[suffix], _audio_stream(container)) else "encode"


def _can_copy(fmt: str, template: Any) -> bool:
    """Whether a ``fmt`` file takes the sound stream ``template`` as it is (its header written
    in memory: some muxers refuse a codec only there)."""
    trial = av.open(io.BytesIO(), "w", format=fmt)
    try:
        trial.add_stream_from_template(template)
        trial.start_encoding()
        return True
    except (ValueError, av.FFmpegError):
        return False
    finally:
        try:
            trial.close()
        except (ValueError, av.FFmpegError):
            pass


def _add_audio(out: Any, source: Path, suffix: str, mode: str) -> Any:
    """The output's sound stream, set up from the source's."""
    with av.open(str(source), metadata_errors="ignore") as container:
        template = _audio_stream(container)
        if mode == "copy":
            return out.add_stream_from_template(template)
        encoder = AUDIO_ENCODERS[suffix]
        rate = template.codec_context.sample_rate or 48000
        supported = av.Codec(encoder, "w").audio_rates
        if supported and rate not in supported:
            rate = 48000
        stream = out.add_stream(encoder, rate=rate)
        channels = template.codec_context.channels or 2
        stream.codec_context.layout = "mono" if channels == 1 else "stereo"
        stream.codec_context.bit_rate = _AUDIO_BIT_RATE
        return stream


def _add_video(out: Any, encoding: _Encoding, width: int, height: int, rate: Fraction, time_base: Fraction) -> Any:
    stream = out.add_stream(encoding.codec, rate=rate)
    stream.width, stream.height = width, height
    formats = [f.name for f in av.Codec(encoding.codec, "w").video_formats or ()]
    if "yuv420p" in formats and (width % 2 == 0 and height % 2 == 0 or encoding.codec.startswith("libvpx")):
        stream.pix_fmt = "yuv420p"
    elif "yuv444p" in formats:
        stream.pix_fmt = "yuv444p"  # x264 cannot subsample the colour of an odd size
    elif formats:
        stream.pix_fmt = formats[0]
    stream.time_base = time_base
    stream.codec_context.time_base = time_base
    stream.options = dict(encoding.options)
    return stream


def _encode_error(output: Path, error: Exception) -> WiseError:
    return WiseError(f"{output}: the video could not be encoded ({_reason(error)}); try another --codec or container")


def _write(
    look: Look,
    source: Path,
    output: Path,
    temporary: Path,
    info: VideoInfo,
    encoding: _Encoding,
    smoothing: float,
    bar: Any,
    interrupt: CtrlC,
    counter: list[int],
) -> None:
    mode = _audio_mode(source, info, encoding.suffix)
    options = {"movflags": "+faststart"} if encoding.format in ("mp4", "mov") else {}
    out = av.open(str(temporary), "w", format=encoding.format, options=options)
    reader = _Reader(source, mode)
    smoother = MaskSmoother(smoothing) if look.paints and smoothing > 0 else None
    closed = False
    try:
        reader.start()
        video = audio = None
        waiting: list[Any] = []  # sound that came before the first picture was rendered
        step = 1
        last_pts: int | None = None

        def mux(packets: Any) -> None:
            for packet in packets:
                out.mux(packet)

        def sound(item: Any) -> None:
            if mode == "copy":
                item.stream = audio
                out.mux(item)
            else:
                mux(audio.encode(item))

        while True:
            kind, *rest = reader.get()
            if kind == "end":
                break
            if kind == "error":
                error = rest[0]
                if isinstance(error, av.FFmpegError):
                    raise WiseError(
                        f"{source}: cannot be decoded after frame {counter[0]} ({_reason(error)}); check the file"
                    )
                raise error
            if kind == "audio":
                if video is None:
                    waiting.append(rest[0])
                else:
                    sound(rest[0])
                continue
            array, pts, time_base, duration = rest
            image = image_to_tensor(array)
            result = tensor_to_image(_render(look, image, smoother))
            if video is None:
                time_base = time_base or Fraction(1) / info.rate
                step = max(1, round(1 / (info.rate * time_base)))
                height, width = result.shape[:2]
                video = _add_video(out, encoding, width, height, info.rate, time_base)
                if mode is not None:
                    audio = _add_audio(out, source, encoding.suffix, mode)
                out_size = (width, height)
                for item in waiting:
                    sound(item)
                waiting.clear()
            elif result.shape[1::-1] != out_size:
                size = size_text(*result.shape[1::-1])
                raise WiseError(
                    f"{source}: the look made frame {counter[0] + 1} {size}, the first {size_text(*out_size)}; "
                    "a video needs one size throughout"
                )
            if pts is None or (last_pts is not None and pts <= last_pts):
                pts = 0 if last_pts is None else last_pts + step
            last_pts = pts
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(result), format="rgb24")
            frame.pts = pts
            frame.time_base = video.codec_context.time_base
            frame.duration = duration or step  # the last frame's length, when the source gives none
            try:
                mux(video.encode(frame))
            except av.FFmpegError as error:
                raise _encode_error(output, error) from None
            counter[0] += 1
            bar.update(1)
        interrupt.hold()  # the last frames: a Ctrl-C from here on lets the video finish
        if video is None:
            raise WiseError(f"{source}: no frame could be decoded; check the file")
        try:
            mux(video.encode(None))
            if mode == "encode":
                mux(audio.encode(None))
            out.close()
            closed = True
        except av.FFmpegError as error:
            raise _encode_error(output, error) from None
    finally:
        reader.stop()
        if not closed:
            try:
                out.close()
            except Exception:  # noqa: BLE001 (the file is removed anyway)
                pass


def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total or None, unit="frame", disable=not enabled, file=sys.stderr, dynamic_ncols=True)


def stylize_video(
    look: Look,
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    crf: float | None = None,
    codec: str | None = None,
    temporal_smoothing: float = 0.3,
    progress: bool = False,
    quality_preset: str | None = None,
) -> VideoResult:
    """Stylize the video ``source`` with ``look`` frame by frame into ``output`` (see the module).

    ``codec`` is the video encoder (default: libx264 for .mp4, .mkv and .mov, libvpx-vp9 for
    .webm), ``crf`` its constant quality (default 18 for x264, 32 for VP9; lower is better and
    larger), ``quality_preset`` its speed preset (:data:`QUALITY_PRESETS`; by default x264's
    medium, and ``fast`` for VP9). ``temporal_smoothing`` in [0, 1) is the weight of the
    previous frame's masks for a model that paints them (0: each frame its own). Bad arguments
    raise :class:`WiseError` before any frame is rendered. Ctrl-C returns a result with
    ``interrupted`` set and leaves no output file.
    """
    source, output = Path(source), Path(output)
    info = probe(source)
    encoding = _encoding(output, codec, crf, quality_preset)
    smoothing = check_smoothing(temporal_smoothing)
    if output.exists() and output.samefile(source):
        raise WiseError(f"{output}: the output would overwrite the source; choose another output name")
    if output.is_dir():
        raise WiseError(f"{output}: a folder; give the output video's file name")
    output.parent.mkdir(parents=True, exist_ok=True)
    temporary = partial_path(output)
    began = time.perf_counter()
    counter = [0]
    bar = _progress(info.expected_frames, progress)
    interrupted = False
    with ctrl_c() as interrupt:
        try:
            _write(look, source, output, temporary, info, encoding, smoothing, bar, interrupt, counter)
            os.replace(temporary, output)
        except KeyboardInterrupt:
            interrupted = True
        except BaseException:
            temporary.unlink(missing_ok=True)
            raise
        finally:
            bar.close()
        if interrupted:
            temporary.unlink(missing_ok=True)
    return VideoResult(frames=counter[0], seconds=time.perf_counter() - began, interrupted=interrupted)
