"""Video stylization: speed, and how much the look changes from one frame to the next.

A panning clip is made from ``skimage.data.astronaut()`` (enlarged, then cropped by a window
that moves ``--step`` pixels per frame; ``--frames`` frames at ``--width`` x ``--height``,
24 fps, x264 at CRF 12), together with a still clip of its first frame. Each look stylizes
both through :func:`wise.batch.video.stylize_video`; printed per look and clip: frames per
second (decoding, render and encoding together) and the mean absolute change between
consecutive decoded frames, in 0-255 units, of the input and of the output. A still clip
should give an output change near 0 (the looks are deterministic; only the codec differs).

    python benchmarks/bench_video.py [--frames 96] [--looks xdog:portrait cartoon]
"""

from __future__ import annotations

import argparse
import tempfile
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
from PIL import Image
from skimage import data

from wise.batch.look import Look, LookSpec
from wise.batch.video import stylize_video

RATE = 24


def panorama(width: int, height: int, frames: int, step: int) -> np.ndarray:
    """The astronaut enlarged so that a ``width`` x ``height`` window can move ``step`` pixels
    on each of ``frames`` frames, left to right."""
    photo = Image.fromarray(data.astronaut())
    side = max(width + step * (frames - 1), height)
    return np.asarray(photo.resize((side, side), Image.Resampling.LANCZOS))


def write_clip(path: Path, pictures) -> None:
    container = av.open(str(path), "w")
    stream = None
    for index, picture in enumerate(pictures):
        if stream is None:
            stream = container.add_stream("libx264", rate=RATE, options={"crf": "12"})
            stream.height, stream.width = picture.shape[:2]
            stream.pix_fmt = "yuv420p"
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(picture), format="rgb24")
        frame.pts, frame.time_base = index, Fraction(1, RATE)
        for packet in stream.encode(frame):
            container.mux(packet)
    for packet in stream.encode(None):
        container.mux(packet)
    container.close()


def frame_change(path: Path) -> float:
    """The mean absolute difference between consecutive frames, in 0-255 units."""
    total, count, previous = 0.0, 0, None
    with av.open(str(path)) as container:
        for frame in container.decode(video=0):
            pixels = frame.to_ndarray(format="rgb24").astype(np.int16)
            if previous is not None:
                total += float(np.abs(pixels - previous).mean())
                count += 1
            previous = pixels
    return total / max(1, count)


def parse_look(text: str) -> LookSpec:
    """``EFFECT[:PRESET]`` or ``EFFECT@MODEL`` (a local model, e.g. ``xdog@builtin:contours``)."""
    if "@" in text:
        effect, _, model = text.partition("@")
        return LookSpec(effect, model=model)
    effect, _, preset = text.partition(":")
    return LookSpec(effect, preset=preset or None)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=96)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=360)
    parser.add_argument("--step", type=int, default=4, help="pixels the window moves per frame")
    parser.add_argument(
        "--looks", nargs="+", default=["xdog:portrait", "cartoon", "xdog@builtin:contours"],
        help="EFFECT[:PRESET] or EFFECT@MODEL",
    )  # fmt: skip
    parser.add_argument(
        "--smoothing", nargs="+", type=float, default=[0.0, 0.3], help="temporal smoothing of a model's masks"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        photo = panorama(args.width, args.height, args.frames, args.step)
        top = (photo.shape[0] - args.height) // 2
        lefts = [i * args.step for i in range(args.frames)]
        window = [photo[top : top + args.height, left : left + args.width] for left in lefts]
        clips = {"pan": folder / "pan.mp4", "still": folder / "still.mp4"}
        write_clip(clips["pan"], window)
        write_clip(clips["still"], [window[0]] * args.frames)
        changes = {name: frame_change(path) for name, path in clips.items()}
        print(f"{args.frames} frames {args.width}x{args.height}, pan {args.step} px/frame; change in 0-255 units")
        print("| look | smoothing | clip | frames/s | input change | output change |")
        print("| --- | --- | --- | --- | --- | --- |")
        for text in args.looks:
            look = Look(parse_look(text))
            for amount in args.smoothing if look.paints else [None]:
                for name, path in clips.items():
                    output = folder / f"{name}-out.mp4"
                    result = stylize_video(look, path, output, temporal_smoothing=amount or 0.0)
                    rate = result.frames / result.seconds
                    shown = "-" if amount is None else f"{amount:g}"
                    change = frame_change(output)
                    print(f"| {text} | {shown} | {name} | {rate:.2f} | {changes[name]:.2f} | {change:.2f} |")


if __name__ == "__main__":
    main()
