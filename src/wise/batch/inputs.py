"""The images of a batch: inputs (files, folders, glob patterns) expanded to a plan of
input and output paths, every conflict refused before any work.

A folder is searched recursively for the image types ``wise`` reads (hidden files and folders
skipped); its images keep their path relative to it under the output folder
(``photos/a/b.jpg`` -> ``OUT/a/b.png``). A glob pattern keeps the path relative to its part
before the first wildcard; a file given by name goes to the top of the output folder.
"""

from __future__ import annotations

import glob
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

from wise.errors import WiseError
from wise.io import IMAGE_SUFFIXES

VIDEO_SUFFIXES = frozenset({".mp4", ".mov", ".mkv", ".webm"})
FORMATS = {"png": ".png", "jpg": ".jpg"}
PARAMS_SUFFIX = ".safetensors"
_WILDCARDS = frozenset("*?[")


@dataclass(frozen=True)
class Job:
    """One image of a batch: where it is read, and where its result (and, with
    ``--save-params``, its parameter file) is written."""

    source: Path
    output: Path
    params: Path | None = None


def is_pattern(text: str) -> bool:
    """Whether ``text`` is a glob pattern rather than the name of an existing file."""
    return any(c in _WILDCARDS for c in text) and not os.path.lexists(text)


def is_video(path: str | os.PathLike[str]) -> bool:
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def is_batch(inputs: Sequence[str]) -> bool:
    """Whether the inputs make a batch (the output is a folder): more than one, a folder or a pattern."""
    return len(inputs) > 1 or any(is_pattern(text) or Path(text).is_dir() for text in inputs)


def _visible(name: str) -> bool:
    return not name.startswith(".")


def _images_in(folder: Path) -> Iterator[Path]:
    for root, dirs, files in os.walk(folder, followlinks=False):
        dirs[:] = sorted(d for d in dirs if _visible(d))
        for name in sorted(files):
            if _visible(name) and Path(name).suffix.lower() in IMAGE_SUFFIXES:
                yield Path(root) / name


def _pattern_root(pattern: str) -> Path:
    """The part of ``pattern`` before its first component with a wildcard."""
    parts = Path(pattern).parts
    fixed = []
    for part in parts:
        if any(c in _WILDCARDS for c in part):
            break
        fixed.append(part)
    return Path(*fixed) if fixed else Path(".")


def _expand(text: str) -> list[tuple[Path, Path]]:
    """``(image, path relative to its root)`` of one input, in a stable order."""
    if is_pattern(text):
        root = _pattern_root(text)
        found: list[tuple[Path, Path]] = []
        for match in sorted(glob.glob(text, recursive=True)):
            path = Path(match)
            if path.is_dir():
                found += [(image, image.relative_to(root)) for image in _images_in(path)]
            elif _visible(path.name) and path.suffix.lower() in IMAGE_SUFFIXES:
                found.append((path, path.relative_to(root)))
        if not found:
            raise WiseError(
                f"{text}: the pattern matches no image ({', '.join(sorted(IMAGE_SUFFIXES))}); "
                "check it, and quote it so that the shell does not expand it"
            )
        return found
    path = Path(text)
    if path.is_dir():
        found = [(image, image.relative_to(path)) for image in _images_in(path)]
        if not found:
            raise WiseError(f"{path}: no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in this folder or its subfolders")
        return found
    if not os.path.lexists(path):
        raise WiseError(f"{path}: no such file or folder; check the path")
    if is_video(path):
        raise WiseError(f"{path}: a video is stylized on its own: wise apply EFFECT {path.name} -o OUT.mp4")
    return [(path, Path(path.name))]


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder.resolve())
    except ValueError:
        return False
    return True


def plan(inputs: Sequence[str], out: str | os.PathLike[str], fmt: str = "png", save_params: bool = False) -> list[Job]:
    """The jobs of a batch: every input expanded, duplicates (the same file reached twice) dropped,
    and refused when the output folder lies inside an input folder or two inputs would be
    written to the same output."""
    if fmt not in FORMATS:
        raise WiseError(f"--format {fmt}: use one of {', '.join(FORMATS)}")
    out = Path(out)
    for text in inputs:
        folder = Path(text)
        if not is_pattern(text) and folder.is_dir() and _inside(out, folder):
            raise WiseError(
                f"{out}: the output folder is inside the input folder {folder}, so its results would be "
                "read as inputs next time; choose an output folder outside it"
            )
    jobs: list[Job] = []
    by_output: dict[Path, Path] = {}
    seen: set[tuple[Path, Path]] = set()
    for text in inputs:
        for source, relative in _expand(text):
            if is_pattern(text) and _inside(source, out):
                continue  # a result of an earlier run that the pattern reaches
            key = (source.resolve(), relative)
            if key in seen:
                continue
            seen.add(key)
            output = out / relative.with_suffix(FORMATS[fmt])
            if output in by_output:
                raise WiseError(
                    f"{output}: both {by_output[output]} and {source} would be written there; "
                    "rename one of them or stylize them in separate runs"
                )
            by_output[output] = source
            jobs.append(Job(source, output, output.with_suffix(PARAMS_SUFFIX) if save_params else None))
    return jobs
