"""The bad-input catalogue of the command line.

Every case must be refused before any work: exit code 2, one ``wise: error:`` line on stderr
(no traceback, no warning), nothing on stdout, no new or changed file or folder (the inputs
included), and within a time far below what the work would take (the photos are large enough
that rendering or optimizing them takes many times longer). Most cases run in-process; those
that once crashed, hung or overflowed run as real processes.
"""

from __future__ import annotations

import hashlib
import os
import socket
import stat
import struct
import subprocess
import sys
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import av
import numpy as np
import pytest
import torch
from PIL import Image
from safetensors.torch import save_file
from skimage import data

import wise
from wise import ppn
from wise.cli import main
from wise.paramfile import save_params
from wise.ppn.modelfile import ModelInfo, save_model

SRC = Path(wise.__file__).resolve().parent.parent
IN_PROCESS_LIMIT = 1.0
"""Seconds a refusal may take in-process; the work behind each case takes far longer."""
SUBPROCESS_LIMIT = 20.0
"""Seconds for a refusal in a fresh interpreter (imports included)."""
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


def _png_claiming(width: int, height: int) -> bytes:
    """A PNG whose header claims ``width`` x ``height`` grey pixels, with one tiny data chunk."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")
    )


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Every input of the catalogue in one folder (compared before and after each case)."""
    root = tmp_path_factory.mktemp("world")
    photo = Image.fromarray(data.astronaut()).resize((1024, 768), Image.Resampling.BILINEAR)
    photo.save(root / "photo.png")
    Image.fromarray(data.coffee()).resize((1024, 768), Image.Resampling.BILINEAR).save(root / "target.png")
    Image.fromarray(data.chelsea()).resize((300, 300), Image.Resampling.BILINEAR).save(root / "square.png")
    (root / "notes.png").write_text("not an image")
    (root / "empty.png").write_bytes(b"")
    whole = (root / "photo.png").read_bytes()
    (root / "truncated.png").write_bytes(whole[: len(whole) // 2])
    (root / "bomb.png").write_bytes(_png_claiming(30000, 30000))
    (root / "folder.png").mkdir()
    os.symlink("loop.png", root / "loop.png")
    os.symlink("loop.safetensors", root / "loop.safetensors")
    os.symlink("photo.png", root / "photo-link.png")
    os.mkfifo(root / "fifo.png")
    os.mkfifo(root / "fifo.safetensors")
    (root / "a-file").write_text("a file, not a folder")
    xdog = wise.effects.create("xdog")
    save_params(root / "xdog.safetensors", xdog, xdog.default_params())
    save_params(
        root / "cartoon.safetensors", wise.effects.create("cartoon"), wise.effects.create("cartoon").default_params()
    )
    save_file({"params": torch.zeros(len(xdog.param_specs))}, root / "no-metadata.safetensors")
    nan = xdog.default_params().clone()
    nan[0] = float("nan")
    (root / "nan.safetensors").write_bytes(_with_nan(root / "xdog.safetensors", xdog.default_params(), nan))
    (root / "huge-header.safetensors").write_bytes(struct.pack("<Q", 2**60) + b"{}")
    (root / "notes.safetensors").write_text("not a parameter file")
    (root / "run-file").write_text("a file where a folder goes")
    (root / "run-with-folder" / "result.png").mkdir(parents=True)
    (root / "done-run").mkdir()
    photo.save(root / "done-run" / "result.png")
    (root / "results.json").mkdir()
    (root / "photos").mkdir()
    photo.save(root / "photos" / "one.png")
    photo.resize((512, 384)).save(root / "photos" / "two.png")
    (root / "no-photos").mkdir()
    (root / "bad-photos").mkdir()
    photo.save(root / "bad-photos" / "good.png")
    (root / "bad-photos" / "broken.png").write_text("not an image")
    (root / "clash").mkdir()
    photo.save(root / "clash" / "a.png")
    photo.save(root / "clash" / "a.jpg")
    (root / "notes.mp4").write_text("not a video")
    _media(root)
    (root / "read-only").mkdir()
    (root / "read-only").chmod(stat.S_IRUSR | stat.S_IXUSR)
    _models(root, photo)
    main(["effects"])  # imports done before the clock runs
    return {"root": root}


def _media(root: Path) -> None:
    """``clip.mp4`` (4 frames, no sound) and ``sound.mp4`` (sound, no pictures)."""
    with av.open(str(root / "clip.mp4"), "w") as container:
        stream = container.add_stream("libx264", rate=24)
        stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
        for _ in range(4):
            frame = av.VideoFrame.from_ndarray(np.zeros((48, 64, 3), np.uint8), format="rgb24")
            container.mux(stream.encode(frame))
        container.mux(stream.encode(None))
    with av.open(str(root / "sound.mp4"), "w") as container:
        stream = container.add_stream("aac", rate=44100)
        tone = (0.1 * np.sin(np.arange(44100) / 10)).astype(np.float32)[None]
        frame = av.AudioFrame.from_ndarray(tone, format="fltp", layout="mono")
        frame.sample_rate = 44100
        container.mux(stream.encode(frame))
        container.mux(stream.encode(None))


def _models(root: Path, photo: Image.Image) -> None:
    """Model files, training photos and a finished training run."""
    for effect in ("xdog", "cartoon"):
        count = len(wise.effects.create(effect).param_specs)
        info = ModelInfo(effect, "simple", wise.effects.create(effect).param_names, size=64, render_size=128)
        save_model(root / f"{effect}-model.safetensors", ppn.create("simple", count), info)
    whole = (root / "xdog-model.safetensors").read_bytes()
    (root / "cut-model.safetensors").write_bytes(whole[: len(whole) // 2])
    (root / "model.pth").write_bytes(b"\x80\x04not loaded")
    (root / "photos4").mkdir()
    for index in range(4):
        photo.resize((200 + 8 * index, 150)).save(root / "photos4" / f"photo{index}.png")
    (root / "old-run").mkdir()
    (root / "old-run" / "settings.json").write_text("{}")
    for effect in ("xdog", "cartoon"):
        names = wise.effects.create(effect).param_names
        info = ModelInfo(effect, "unet", names, size=64, render_size=64, kind="local", network={"depth": 2, "width": 4})
        save_model(root / f"{effect}-local.safetensors", ppn.create_local("unet", len(names), depth=2, width=4), info)
    _pairs(root, photo)


def _pairs(root: Path, photo: Image.Image) -> None:
    """Paired folders: a good one of XDoG's task, one with a photo whose target is missing, one
    without a test split."""
    small = photo.resize((64, 48))
    for split in ("train", "test"):
        for side in ("A", "B"):
            (root / "pairs" / split / side).mkdir(parents=True)
            small.save(root / "pairs" / split / side / "one.png")
    (root / "pairs" / "task.json").write_text('{"task": "contours", "effect": "xdog", "preset": "portrait"}')
    for side, name in (("A", "one"), ("A", "two"), ("B", "one")):
        (root / "pairs-unpaired" / "train" / side).mkdir(parents=True, exist_ok=True)
        small.save(root / "pairs-unpaired" / "train" / side / f"{name}.png")
    for side in ("A", "B"):
        (root / "pairs-no-test" / "train" / side).mkdir(parents=True)
        small.save(root / "pairs-no-test" / "train" / side / "one.png")


def _with_nan(source: Path, good: torch.Tensor, bad: torch.Tensor) -> bytes:
    """The bytes of the parameter file ``source`` with its values replaced by ``bad``."""
    raw = source.read_bytes()
    good_bytes, bad_bytes = good.numpy().astype(np.float32).tobytes(), bad.numpy().astype(np.float32).tobytes()
    assert raw.count(good_bytes) == 1
    return raw.replace(good_bytes, bad_bytes)


def snapshot(root: Path) -> dict[str, tuple]:
    """Every path under ``root`` with its kind, and the content hash of regular files."""
    found: dict[str, tuple] = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder) / name
            info = os.lstat(path)
            entry: tuple = (stat.S_IFMT(info.st_mode), info.st_mode & 0o777)
            if stat.S_ISREG(info.st_mode):
                entry += (info.st_size, info.st_mtime_ns, hashlib.sha256(path.read_bytes()).hexdigest())
            found[str(path.relative_to(root))] = entry
    return found


@dataclass(frozen=True)
class Case:
    argv: str
    """Arguments, space-separated, with ``{root}`` for the catalogue's folder."""
    words: str
    """Part of the error message (case-insensitive)."""
    process: bool = False
    """Run as a real ``python -m wise`` process."""
    needs_user: bool = False
    """Needs file permissions to apply (skipped when running as root)."""


APPLY = "apply xdog {root}/photo.png -o {root}/out.png"
GALLERY = "gallery {root}/photo.png -o {root}/sheet.png"
OPTIMIZE = "optimize xdog --content {root}/photo.png --target {root}/target.png -o {root}/run"
TRANSFER = "transfer watercolor --content {root}/photo.png --builtin-style 0 -o {root}/run"
GATYS = "transfer watercolor --content {root}/photo.png --style {root}/target.png --nst gatys -o {root}/run"
RECOVER = "bench recover xdog --images {root}/photos --json {root}/bench.json"
EDIT = "edit {root}/photo.png --port 8931"
PREDICT = (
    "predict xdog --content {root}/photo.png --target {root}/target.png -o {root}/pred "
    "--model {root}/xdog-model.safetensors"
)
PREDICT_WITH = "predict xdog --content {root}/photo.png --target {root}/target.png -o {root}/pred --model"
TRAIN = "train global xdog --images {root}/photos4 -o {root}/train-run"
PPN = "bench ppn xdog --images {root}/photos --json {root}/ppn.json --model"
LOCAL = "train local xdog --pairs {root}/pairs -o {root}/local-run"
PAINT = "predict xdog --content {root}/photo.png -o {root}/pred --model"
PAIRS = "bench pairs --pairs {root}/pairs --json {root}/pairs.json --model"

CASES: dict[str, Case] = {
    # predict
    "predict: unknown effect": Case(PREDICT.replace("xdog", "oil", 1), "unknown effect 'oil'"),
    "predict: model of another effect": Case(
        PREDICT_WITH + " {root}/cartoon-model.safetensors", "a model for 'cartoon', not 'xdog'"
    ),
    "predict: corrupt model": Case(PREDICT_WITH + " {root}/cut-model.safetensors", "not a safetensors file"),
    "predict: parameter file as model": Case(PREDICT_WITH + " {root}/xdog.safetensors", "not a wise model file"),
    "predict: text as model": Case(PREDICT_WITH + " {root}/notes.safetensors", "not a safetensors file"),
    "predict: pickled model": Case(PREDICT_WITH + " {root}/model.pth", "must be a .safetensors file"),
    "predict: missing model": Case(PREDICT_WITH + " {root}/nope.safetensors", "no such file"),
    "predict: FIFO as model": Case(PREDICT_WITH + " {root}/fifo.safetensors", "not a regular file", process=True),
    "predict: target of another aspect ratio": Case(
        PREDICT.replace("target.png", "square.png"), "another aspect ratio"
    ),
    "predict: text as content": Case(PREDICT.replace("photo.png", "notes.png"), "not an image"),
    "predict: output is a file": Case(PREDICT.replace("{root}/pred", "{root}/a-file"), "not a directory"),
    "predict: negative --refine": Case(PREDICT + " --refine -1", "--refine: must be from 0"),
    "predict: unknown --mode": Case(PREDICT + " --refine 5 --mode painted", "invalid choice"),
    # train global
    "train: unknown effect": Case(TRAIN.replace("xdog", "oil", 1), "unknown effect 'oil'"),
    "train: unknown architecture": Case(TRAIN + " --arch vgg", "invalid choice: 'vgg'"),
    "train: unknown loss": Case(TRAIN + " --loss perceptual", "invalid choice: 'perceptual'"),
    "train: empty photo folder": Case(TRAIN.replace("photos4", "no-photos"), "0 readable photos"),
    "train: unreadable photos": Case(TRAIN.replace("photos4", "bad-photos"), "(1 skipped); training needs at least 4"),
    "train: missing photo folder": Case(TRAIN.replace("photos4", "nope"), "not a directory of photos"),
    "train: photo folder is a file": Case(TRAIN.replace("photos4", "a-file"), "not a directory of photos"),
    "train: validation photos are training photos": Case(
        TRAIN + " --val-images {root}/photos4", "also training photos"
    ),
    "train: resume without a run": Case(TRAIN + " --resume", "no checkpoint to resume"),
    "train: folder holds a run": Case(TRAIN.replace("train-run", "old-run"), "pass --resume"),
    "train: run folder is a file": Case(TRAIN.replace("train-run", "a-file"), "not a directory"),
    "train: --batch 0": Case(TRAIN + " --batch 0", "--batch: must be from 1"),
    "train: --steps and --epochs": Case(TRAIN + " --steps 5 --epochs 5", "not allowed with"),
    "train: --lr nan": Case(TRAIN + " --lr nan", "--lr: 'nan' is not a finite number"),
    "train: huge seed": Case(TRAIN + " --seed 4294967296", "--seed: must be from 0 to 4,294,967,295"),
    "train: gpu without CUDA": Case(TRAIN + " --accelerator gpu", "CUDA is not available"),
    "train: --devices 0": Case(TRAIN + " --devices 0", "--devices: must be from 1"),
    "train: render size below size": Case(TRAIN + " --size 256 --render-size 128", "below --size 256"),
    "train: window above size": Case(TRAIN + " --size 64 --window 100", "--window 100 must be from 8"),
    "train: too few examples": Case(TRAIN + " --examples 4 --batch 8", "fewer than one global batch"),
    "train: --param-weight with a parameter loss": Case(
        TRAIN + " --loss param-l1 --param-weight 0.2", "adds to an image-space loss"
    ),
    "train: negative --param-weight": Case(TRAIN + " --param-weight -1", "--param-weight: must be at least 0"),
    "train: backbone for simple": Case(TRAIN + " --backbone-weights {root}/xdog.safetensors", "no ImageNet backbone"),
    # train local, predict and bench with local models
    "train local: missing pairs": Case(LOCAL.replace("/pairs", "/nope"), "not a directory of pairs"),
    "train local: photo without a target": Case(
        LOCAL.replace("/pairs", "/pairs-unpaired"), "1 photo in A/ without a target in B/ (two)"
    ),
    "train local: no test split": Case(LOCAL.replace("/pairs", "/pairs-no-test"), "no test/ folder"),
    "train local: pairs of another effect": Case(LOCAL.replace("xdog", "cartoon", 1), "pairs of the 'xdog' effect"),
    "train local: crop above the load size": Case(LOCAL + " --load-size 64 --crop-size 96", "larger than --load-size"),
    "train local: nothing to learn": Case(LOCAL + " --gan-weight 0 --l1-weight 0", "nothing would be learned"),
    "train local: negative --tv-weight": Case(LOCAL + " --tv-weight -1", "--tv-weight: must be at least 0"),
    "train local: unknown --start": Case(LOCAL + " --start noir", "no preset 'noir'"),
    "train local: --depth 1": Case(LOCAL + " --depth 1", "--depth: must be from 2"),
    "train local: --soft-gradients above 1": Case(
        LOCAL + " --soft-gradients 1.5", "--soft-gradients: must be at most 1"
    ),
    "train local: --init of a missing file": Case(LOCAL + " --init nothing.safetensors", "nothing.safetensors"),
    "train local: --init of an unknown built-in task": Case(LOCAL + " --init builtin:hair", "builtin:hair"),
    "train local: no effect and no CNN": Case(
        LOCAL.replace("local xdog", "local none"), "the effect 'none' trains a CNN alone"
    ),
    "train local: a preset and no CNN": Case(LOCAL + " --ppn preset", "nothing to learn"),
    "train local: unknown --post": Case(LOCAL + " --post vgg", "--post: invalid choice"),
    "train local: --init without a PPN": Case(
        LOCAL + " --ppn preset --post unet --init {root}/xdog-local.safetensors", "--init starts the PPN"
    ),
    "train local: --post-width 0": Case(LOCAL + " --post unet --post-width 0", "--post-width: must be from 1"),
    "train local: folder holds a run": Case(LOCAL.replace("local-run", "old-run"), "pass --resume"),
    "predict: local model with --target": Case(
        PAINT + " {root}/xdog-local.safetensors --target {root}/target.png", "leave out --target"
    ),
    "predict: global model without --target": Case(PAINT + " {root}/xdog-model.safetensors", "--target is required"),
    "predict: local model of another effect": Case(
        PAINT + " {root}/cartoon-local.safetensors", "a model for 'cartoon'"
    ),
    "predict: unknown built-in task": Case(PAINT + " builtin:chin", "no built-in model builtin:chin"),
    "bench pairs: global model": Case(PAIRS + " {root}/xdog-model.safetensors", "a global model"),
    "bench pairs: photo without a target": Case(
        PAIRS.replace("/pairs ", "/pairs-unpaired/train ") + " {root}/xdog-local.safetensors", "without a target"
    ),
    "bench pairs: json is a folder": Case(
        PAIRS.replace("pairs.json", "results.json") + " {root}/xdog-local.safetensors", "is a directory"
    ),
    "bench pairs: model of another effect": Case(
        PAIRS + " {root}/xdog-local.safetensors --effect cartoon", "a model for 'xdog'"
    ),
    "bench pairs: --fid with a missing weight file": Case(
        PAIRS + " {root}/xdog-local.safetensors --fid --inception-weights {root}/nothing.safetensors",
        "nothing.safetensors",
    ),
    "bench pairs: --fid with pickled weights": Case(
        PAIRS + " {root}/xdog-local.safetensors --fid --inception-weights {root}/model.pth", "safetensors"
    ),
    "bench pairs: --lpips-weights without --lpips": Case(
        PAIRS + " {root}/xdog-local.safetensors --lpips-weights {root}/xdog.safetensors", "add --lpips"
    ),
    "bench pairs: html page of another kind": Case(
        PAIRS + " {root}/xdog-local.safetensors --html {root}/page.png", ".html"
    ),
    "apply: --params with a local model": Case(
        APPLY + " --params {root}/xdog.safetensors --model {root}/xdog-local.safetensors", "paints the masks"
    ),
    "predict: a CNN alone without its model": Case(
        "predict none --content {root}/photo.png -o {root}/pred", "pass its --model"
    ),
    "edit: --model without --params": Case(EDIT + " --model {root}/xdog-local.safetensors", "pass them with --params"),
    "edit: --model without a CNN": Case(
        EDIT + " --params {root}/xdog.safetensors --model {root}/xdog-local.safetensors", "not a model with a CNN"
    ),
    "data drawing: missing photo folder": Case(
        "data drawing --images {root}/nope -o {root}/drawings", "not a directory of photos"
    ),
    "data drawing: --count 1": Case("data drawing --images {root}/photos -o {root}/drawings --count 1", "--count"),
    "data drawing: output inside the photos": Case(
        "data drawing --images {root}/photos -o {root}/photos/pairs", "inside the photo folder"
    ),
    "bench ppn: local model": Case(PPN + " {root}/xdog-local.safetensors", "a local model"),
    # bench ppn and recover --init ppn
    "bench ppn: model of another effect": Case(PPN + " {root}/cartoon-model.safetensors", "a model for 'cartoon'"),
    "bench ppn: corrupt model": Case(PPN + " {root}/cut-model.safetensors", "not a safetensors file"),
    "bench ppn: --trials 0": Case(PPN + " {root}/xdog-model.safetensors --trials 0", "--trials: must be from 1"),
    "bench ppn: json is a folder": Case(
        PPN.replace("ppn.json", "results.json") + " {root}/xdog-model.safetensors", "is a directory"
    ),
    "bench recover: unknown --init": Case(
        "bench recover xdog --images {root}/photos --json {root}/bench.json --init magic", "--init 'magic'"
    ),
    "bench recover: --init model of another effect": Case(
        "bench recover xdog --images {root}/photos --json {root}/bench.json "
        "--init ppn:{root}/cartoon-model.safetensors",
        "a model for 'cartoon'",
    ),
    # the command itself
    "no command": Case("", "required"),
    "unknown command": Case("frobnicate", "invalid choice"),
    "effects: unknown effect": Case("effects oil", "unknown effect 'oil'"),
    # apply: names and values
    "apply: unknown effect": Case("apply oil {root}/photo.png -o {root}/out.png", "unknown effect 'oil'"),
    "apply: unknown parameter": Case(APPLY + " --set sharpness=1", "no parameter 'sharpness'"),
    "apply: unknown preset": Case(APPLY + " --preset noir", "no preset 'noir'"),
    "apply: value out of range": Case(APPLY + " --set contour=99", "outside the range [0, 3]"),
    "apply: malformed --set": Case(APPLY + " --set contour", "expected NAME=VALUE"),
    "apply: non-numeric --set": Case(APPLY + " --set contour=lots", "not a number"),
    "apply: NaN --set": Case(APPLY + " --set contour=nan", "finite"),
    "apply: infinite --set": Case(APPLY + " --set contour=inf", "finite"),
    "apply: params and preset": Case(APPLY + " --preset sketch --params {root}/xdog.safetensors", "cannot be combined"),
    "apply: kernel size 0": Case(APPLY + " --kernel-size 0", "--kernel-size: must be from 1"),
    "apply: kernel size not a number": Case(APPLY + " --kernel-size two", "not a whole number"),
    "apply: huge kernel size": Case(APPLY + " --kernel-size 100000", "--kernel-size: must be from 1 to 32"),
    "apply: quality above 100": Case(APPLY + " --quality 101", "--quality: must be from 1 to 100"),
    "apply: negative quality": Case(APPLY + " --quality -5", "--quality"),
    "apply: unknown device": Case(APPLY + " --device tpu", "invalid choice"),
    # apply: many images and videos
    "apply: empty folder": Case("apply xdog {root}/no-photos -o {root}/styled", "no images"),
    "apply: pattern matching nothing": Case("apply xdog {root}/photos/*.webp -o {root}/styled", "matches no image"),
    "apply: output folder is a file": Case("apply xdog {root}/photos -o {root}/a-file", "not a directory"),
    "apply: output inside an input folder": Case(
        "apply xdog {root}/photos -o {root}/photos/styled", "inside the input folder"
    ),
    "apply: unwritable output folder": Case(
        "apply xdog {root}/photos -o {root}/read-only/styled", "cannot write", needs_user=True
    ),
    "apply: images to one image file": Case("apply xdog {root}/photos -o {root}/out.png", "give a folder name"),
    "apply: two images, one output": Case("apply xdog {root}/clash -o {root}/styled", "would be written there"),
    "apply: log file is a folder": Case(
        "apply xdog {root}/photos -o {root}/styled --log {root}/folder.png", "is a directory"
    ),
    "apply: --format for one image": Case(APPLY + " --format jpg", "extension chooses"),
    "apply: --ray-address without --ray": Case(
        "apply xdog {root}/photos -o {root}/styled --ray-address 127.0.0.1:6379", "add --ray"
    ),
    "apply: video without a video stream": Case("apply xdog {root}/sound.mp4 -o {root}/out.mp4", "no video stream"),
    "apply: text as video": Case("apply xdog {root}/notes.mp4 -o {root}/out.mp4", "not a video"),
    "apply: video to an image file": Case("apply xdog {root}/clip.mp4 -o {root}/out.png", "a video is written as"),
    "apply: --crf for an image": Case(APPLY + " --crf 20", "for a video"),
    "apply: smoothing of 1": Case(
        "apply xdog {root}/clip.mp4 -o {root}/out.mp4 --temporal-smoothing 1", "--temporal-smoothing"
    ),
    # apply: input images
    "apply: text as image": Case("apply xdog {root}/notes.png -o {root}/out.png", "not an image"),
    "apply: empty image": Case("apply xdog {root}/empty.png -o {root}/out.png", "empty"),
    "apply: truncated image": Case("apply xdog {root}/truncated.png -o {root}/out.png", "truncated.png"),
    "apply: missing image": Case("apply xdog {root}/nope.png -o {root}/out.png", "no such file"),
    "apply: folder as image": Case("apply xdog {root}/folder.png -o {root}/out.png", "folder.png"),
    "apply: symlink loop as image": Case("apply xdog {root}/loop.png -o {root}/out.png", "loop"),
    "apply: FIFO as image": Case("apply xdog {root}/fifo.png -o {root}/out.png", "not a regular file"),
    "apply: header claims 30000x30000": Case(
        "apply xdog {root}/bomb.png -o {root}/out.png", "30000x30000 pixels", process=True
    ),
    "apply: over --max-pixels": Case(APPLY + " --max-pixels 1000", "1024x768 pixels"),
    "apply: --max-pixels 0": Case(APPLY + " --max-pixels 0", "--max-pixels: must be from 1"),
    # apply: outputs
    "apply: output folder missing": Case("apply xdog {root}/photo.png -o {root}/nope/out.png", "does not exist"),
    "apply: output .webp": Case("apply xdog {root}/photo.png -o {root}/out.webp", "use one of .png"),
    "apply: output without extension": Case("apply xdog {root}/photo.png -o {root}/out", "no extension"),
    "apply: output is a folder": Case("apply xdog {root}/photo.png -o {root}/folder.png", "is a directory"),
    "apply: output under a file": Case("apply xdog {root}/photo.png -o {root}/a-file/out.png", "not a directory"),
    "apply: output is the input": Case(
        "apply xdog {root}/photo.png -o {root}/photo.png", "is also the input", process=True
    ),
    "apply: output links to the input": Case(
        "apply xdog {root}/photo.png -o {root}/photo-link.png", "is also the input"
    ),
    "apply: output is a FIFO": Case("apply xdog {root}/photo.png -o {root}/fifo.png", "not a regular file"),
    "apply: read-only output folder": Case(
        "apply xdog {root}/photo.png -o {root}/read-only/out.png", "cannot write", needs_user=True
    ),
    # apply: parameter files
    "apply: /dev/zero as params": Case(APPLY + " --params /dev/zero", "not a regular file", process=True),
    "apply: FIFO as params": Case(APPLY + " --params {root}/fifo.safetensors", "not a regular file", process=True),
    "apply: missing params": Case(APPLY + " --params {root}/nope.safetensors", "no such file"),
    "apply: text as params": Case(APPLY + " --params {root}/notes.safetensors", "not a safetensors file"),
    "apply: params of another effect": Case(APPLY + " --params {root}/cartoon.safetensors", "'cartoon'"),
    "apply: params without metadata": Case(APPLY + " --params {root}/no-metadata.safetensors", "no wise metadata"),
    "apply: NaN params": Case(APPLY + " --params {root}/nan.safetensors", "nan"),
    "apply: params header too long": Case(APPLY + " --params {root}/huge-header.safetensors", "header"),
    "apply: params symlink loop": Case(APPLY + " --params {root}/loop.safetensors", "loop"),
    "apply: params folder": Case(APPLY + " --params {root}/folder.png", "folder.png"),
    # gallery
    "gallery: size 0": Case(GALLERY + " --size 0", "--size: must be from 16"),
    "gallery: huge size": Case(GALLERY + " --size 100000", "--size: must be from 16 to 2,048"),
    "gallery: unknown effect": Case("gallery {root}/photo.png -o {root}/sheet.png --effects nope", "unknown effect"),
    "gallery: output folder missing": Case("gallery {root}/photo.png -o {root}/nope/s.png", "does not exist"),
    "gallery: output is the input": Case("gallery {root}/photo.png -o {root}/photo.png", "is also the input"),
    "gallery: text as image": Case("gallery {root}/notes.png -o {root}/sheet.png", "not an image"),
    # optimize: numbers
    "optimize: --lr inf": Case(OPTIMIZE + " --lr inf", "--lr: 'inf' is not a finite number", process=True),
    "optimize: --lr nan": Case(OPTIMIZE + " --lr nan", "not a finite number"),
    "optimize: --lr 0": Case(OPTIMIZE + " --lr 0", "--lr: must be above 0"),
    "optimize: --lr negative": Case(OPTIMIZE + " --lr -1", "must be above 0"),
    "optimize: --tv inf": Case(OPTIMIZE + " --tv inf", "--tv: 'inf' is not a finite number"),
    "optimize: --tv nan": Case(OPTIMIZE + " --tv nan", "not a finite number"),
    "optimize: --tv negative": Case(OPTIMIZE + " --tv -1", "--tv: must be at least 0"),
    "optimize: huge seed": Case(OPTIMIZE + " --seed 100000000000000000000000", "--seed: must be from 0", process=True),
    "optimize: negative seed": Case(OPTIMIZE + " --seed -1", "--seed: must be from 0"),
    "optimize: --iters 0": Case(OPTIMIZE + " --iters 0", "--iters: must be from 1"),
    "optimize: huge --iters": Case(OPTIMIZE + " --iters 1000000000", "--iters: must be from 1 to 100,000"),
    "optimize: --iters 1.5": Case(OPTIMIZE + " --iters 1.5", "not a whole number"),
    "optimize: huge --size": Case(OPTIMIZE + " --size 100000", "--size: must be from 16 to 4,096"),
    "optimize: tiny --size": Case(OPTIMIZE + " --size 8", "--size: must be from 16"),
    "optimize: --levels 5": Case(OPTIMIZE + " --levels 5", "invalid choice"),
    "optimize: --mode foo": Case(OPTIMIZE + " --mode foo", "invalid choice"),
    "optimize: unknown effect": Case(
        "optimize oil --content {root}/photo.png --target {root}/target.png -o {root}/run", "unknown effect"
    ),
    # optimize: files
    "optimize: missing VGG weights": Case(
        OPTIMIZE + " --loss nst --vgg-weights {root}/vgg.safetensors", "VGG-19 weights not found"
    ),
    "optimize: wrong VGG weights": Case(OPTIMIZE + " --loss nst --vgg-weights {root}/xdog.safetensors", "VGG-19"),
    "optimize: unknown --init preset": Case(OPTIMIZE + " --init noir", "no preset 'noir'"),
    "optimize: missing --init file": Case(OPTIMIZE + " --init {root}/nope.safetensors", "no such file"),
    "optimize: --init of another effect": Case(OPTIMIZE + " --init {root}/cartoon.safetensors", "'cartoon'"),
    "optimize: -o is a file": Case(
        "optimize xdog --content {root}/photo.png --target {root}/target.png -o {root}/run-file", "not a directory"
    ),
    "optimize: result.png is a folder": Case(
        "optimize xdog --content {root}/photo.png --target {root}/target.png -o {root}/run-with-folder",
        "is a directory",
    ),
    "optimize: target would be overwritten": Case(
        "optimize xdog --content {root}/photo.png --target {root}/done-run/result.png -o {root}/done-run",
        "is also the input --target",
    ),
    "optimize: other aspect ratio": Case(
        "optimize xdog --content {root}/photo.png --target {root}/square.png -o {root}/run", "aspect ratio"
    ),
    "optimize: missing target": Case(
        "optimize xdog --content {root}/photo.png --target {root}/nope.png -o {root}/run", "no such file"
    ),
    "optimize: text as content": Case(
        "optimize xdog --content {root}/notes.png --target {root}/target.png -o {root}/run", "not an image"
    ),
    "optimize: read-only parent": Case(
        "optimize xdog --content {root}/photo.png --target {root}/target.png -o {root}/read-only/run",
        "cannot write",
        needs_user=True,
    ),
    "optimize: under a file": Case(
        "optimize xdog --content {root}/photo.png --target {root}/target.png -o {root}/a-file/run", "is a file"
    ),
    # transfer
    "transfer: --tv inf": Case(TRANSFER + " --tv inf", "--tv: 'inf' is not a finite number", process=True),
    "transfer: unknown built-in style": Case(
        "transfer watercolor --content {root}/photo.png --builtin-style 99 -o {root}/run", "--builtin-style"
    ),
    "transfer: negative built-in style": Case(
        "transfer watercolor --content {root}/photo.png --builtin-style -1 -o {root}/run", "--builtin-style"
    ),
    "transfer: two styles": Case(TRANSFER + " --style {root}/target.png", "not allowed with"),
    "transfer: no style": Case("transfer watercolor --content {root}/photo.png -o {root}/run", "one of the arguments"),
    "transfer: gatys without style image": Case(TRANSFER + " --nst gatys", "needs a style image"),
    "transfer: gatys without weights": Case(
        GATYS + " --vgg-weights {root}/vgg.safetensors", "VGG-19 weights not found"
    ),
    "transfer: gatys with wrong weights": Case(GATYS + " --vgg-weights {root}/xdog.safetensors", "VGG-19"),
    "transfer: -o is a file": Case(
        "transfer watercolor --content {root}/photo.png --builtin-style 0 -o {root}/run-file", "not a directory"
    ),
    "transfer: text as style": Case(
        "transfer watercolor --content {root}/photo.png --style {root}/notes.png -o {root}/run", "not an image"
    ),
    "transfer: huge seed": Case(TRANSFER + " --seed 100000000000000000000000", "--seed"),
    "transfer: --lr inf": Case(TRANSFER + " --lr inf", "--lr"),
    # bench recover
    "recover: huge --size": Case(RECOVER + " --size 100000", "--size: must be from 16 to 4,096"),
    "recover: --json folder missing": Case(
        "bench recover xdog --images {root}/photos --json {root}/nope/b.json", "does not exist"
    ),
    "recover: --json read-only folder": Case(
        "bench recover xdog --images {root}/photos --json {root}/read-only/b.json", "cannot write", needs_user=True
    ),
    "recover: --json .txt": Case("bench recover xdog --images {root}/photos --json {root}/b.txt", "use one of .json"),
    "recover: --json is a folder": Case(
        "bench recover xdog --images {root}/photos --json {root}/results.json", "is a directory"
    ),
    "recover: missing images": Case("bench recover xdog --images {root}/nope --json {root}/b.json", "not a directory"),
    "recover: no images": Case("bench recover xdog --images {root}/no-photos --json {root}/b.json", "no images"),
    "recover: broken photo": Case("bench recover xdog --images {root}/bad-photos --json {root}/b.json", "broken.png"),
    "recover: --trials 0": Case(RECOVER + " --trials 0", "--trials: must be from 1"),
    "recover: --lr inf": Case(RECOVER + " --lr inf", "--lr", process=True),
    "recover: --loss nst": Case(RECOVER + " --loss nst", "invalid choice"),
    "recover: negative seed": Case(RECOVER + " --seed -5", "--seed"),
    "recover: unknown effect": Case("bench recover oil --images {root}/photos --json {root}/b.json", "unknown effect"),
    "recover: unknown benchmark": Case("bench speed", "invalid choice"),
    # edit (refused before the server starts)
    "edit: missing image": Case("edit {root}/nope.png --port 8931", "nope.png"),
    "edit: empty image": Case("edit {root}/empty.png --port 8931", "empty"),
    "edit: text as params": Case("edit {root}/photo.png --params {root}/notes.safetensors --port 8931", "notes"),
    "edit: FIFO as params": Case("edit --params {root}/fifo.safetensors --port 8931", "not a regular file"),
    "edit: preset without effect": Case(EDIT + " --preset wet", "--preset needs --effect"),
    "edit: params and effect": Case(EDIT + " --params {root}/xdog.safetensors --effect xdog", "not allowed with"),
    "edit: unknown effect": Case(EDIT + " --effect oil", "unknown effect"),
    "edit: port 0": Case("edit {root}/photo.png --port 0", "--port: must be from 1 to 65,535"),
    "edit: port too large": Case("edit {root}/photo.png --port 70000", "--port"),
    "edit: port not a number": Case("edit {root}/photo.png --port http", "not a whole number"),
    "edit: port in use": Case("edit {root}/photo.png --port {busy_port}", "cannot listen"),
}


@pytest.fixture(scope="module")
def busy_port() -> int:
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        yield held.getsockname()[1]


def _argv(case: Case, root: Path, port: int) -> list[str]:
    return [part.format(root=root, busy_port=port) for part in case.argv.split()]


def _check(code: int, out: str, err: str, case: Case, seconds: float, limit: float) -> None:
    lines = err.splitlines()
    assert code == 2, (code, err)
    assert len(lines) == 1, err
    assert lines[0].startswith("wise: error: "), err
    assert "Traceback" not in err and "warning" not in err.lower(), err
    assert out == "", out
    assert case.words.lower() in err.lower(), err
    assert seconds < limit, f"took {seconds:.2f} s"


def test_catalogue_is_large() -> None:
    assert len(CASES) >= 60
    commands = {case.argv.split()[0] for case in CASES.values() if case.argv}
    assert {"effects", "apply", "gallery", "optimize", "transfer", "bench", "edit", "predict", "train"} <= commands


@pytest.mark.parametrize("name", sorted(CASES))
def test_refused_before_the_work(
    name: str,
    world: dict[str, Path],
    busy_port: int,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    case = CASES[name]
    if case.needs_user and IS_ROOT:
        pytest.skip("file permissions do not apply to root")
    root = world["root"]
    argv = _argv(case, root, busy_port)
    before = snapshot(root)
    if case.process:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))}
        start = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "wise", *argv], capture_output=True, text=True, env=env, timeout=120
        )
        seconds = time.perf_counter() - start
        _check(proc.returncode, proc.stdout, proc.stderr, case, seconds, SUBPROCESS_LIMIT)
    else:
        monkeypatch.setattr("uvicorn.run", _must_not_serve)
        capsys.readouterr()
        start = time.perf_counter()
        code = main(argv)
        seconds = time.perf_counter() - start
        captured = capsys.readouterr()
        _check(code, captured.out, captured.err, case, seconds, IN_PROCESS_LIMIT)
    assert snapshot(root) == before


def _must_not_serve(*args: object, **kwargs: object) -> None:
    raise AssertionError("a refused 'wise edit' started the server")


def test_out_of_range_parameter_files_are_clamped_with_one_warning(
    world: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The value policy: a finite value outside the declared range is clamped, with a warning."""
    xdog = wise.effects.create("xdog")
    values = xdog.default_params().clone()
    values[xdog.param_names.index("contour")] = 1e30
    save_params(tmp_path / "wild.safetensors", xdog, values)
    photo, output, clamped = world["root"] / "square.png", tmp_path / "out.png", tmp_path / "clamped.png"
    code = main(["apply", "xdog", str(photo), "-o", str(output), "--params", str(tmp_path / "wild.safetensors")])
    err = capsys.readouterr().err
    assert code == 0 and output.is_file()
    assert len(err.splitlines()) == 1 and err.startswith("wise: warning: ") and "contour" in err, err
    highest = f"contour={xdog.spec('contour').max}"
    assert main(["apply", "xdog", str(photo), "-o", str(clamped), "--set", highest]) == 0
    assert output.read_bytes() == clamped.read_bytes()
