"""Inputs of a batch expanded to jobs: relative paths kept, conflicts refused before any work."""

from __future__ import annotations

from pathlib import Path

import pytest

from wise.batch.inputs import is_batch, plan
from wise.errors import WiseError


def _touch(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"")


@pytest.fixture
def photos(tmp_path: Path) -> Path:
    for name in ("a.jpg", "sub/b.png", "sub/deeper/c.TIF", "sub/notes.txt", ".hidden/d.png", "sub/.e.png"):
        _touch(tmp_path / "photos" / name)
    return tmp_path / "photos"


def test_a_folder_keeps_relative_paths_and_skips_hidden_and_other_files(photos: Path, tmp_path: Path) -> None:
    jobs = plan([str(photos)], tmp_path / "out", "png", save_params=True)
    assert [j.output.relative_to(tmp_path / "out").as_posix() for j in jobs] == [
        "a.png", "sub/b.png", "sub/deeper/c.png"
    ]  # fmt: skip
    assert [j.params.name for j in jobs] == ["a.safetensors", "b.safetensors", "c.safetensors"]


def test_patterns_keep_the_path_below_their_fixed_part(photos: Path, tmp_path: Path) -> None:
    jobs = plan([str(photos / "**" / "*.png"), str(photos / "a.jpg")], tmp_path / "out", "jpg")
    assert sorted(j.output.relative_to(tmp_path / "out").as_posix() for j in jobs) == ["a.jpg", "sub/b.jpg"]
    assert is_batch([str(photos / "*.jpg")]) and is_batch([str(photos)]) and not is_batch([str(photos / "a.jpg")])


def test_results_of_an_earlier_run_are_not_inputs(photos: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    _touch(out / "sub" / "b.png")
    jobs = plan([str(tmp_path / "**" / "*.png")], out)
    assert all(out not in j.source.parents for j in jobs)


@pytest.mark.parametrize(
    "inputs, out, words",
    [
        (["{photos}/sub/deeper/../..", "{photos}"], "{tmp}/out", None),  # the same files twice: one job each
        (["{photos}"], "{photos}/styled", "inside the input folder"),
        (["{photos}/*.webp"], "{tmp}/out", "matches no image"),
        (["{tmp}/nothing"], "{tmp}/out", "no such file"),
        (["{photos}/a.jpg", "{photos}/sub/../a.jpg", "{tmp}/other/a.png"], "{tmp}/out", "would be written there"),
    ],
)
def test_conflicts_are_refused(photos: Path, tmp_path: Path, inputs: list[str], out: str, words: str | None) -> None:
    _touch(tmp_path / "other" / "a.png")
    args = [i.format(photos=photos, tmp=tmp_path) for i in inputs]
    if words is None:
        assert len(plan(args, out.format(photos=photos, tmp=tmp_path))) == 3
        return
    with pytest.raises(WiseError, match=words):
        plan(args, out.format(photos=photos, tmp=tmp_path))


def test_an_empty_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(WiseError, match="no images"):
        plan([str(tmp_path / "empty")], tmp_path / "out")
