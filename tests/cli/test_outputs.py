"""Output checks before the work, and the cleanup of a failed command's folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from wise.cli.outputs import OutputFolder, output_file
from wise.errors import WiseError


def test_output_file_accepts_new_and_existing_files(tmp_path: Path) -> None:
    assert output_file(tmp_path / "a.png", {}, (".png",)) == tmp_path / "a.png"
    (tmp_path / "b.png").write_bytes(b"old")
    assert output_file(tmp_path / "b.png", {}, (".png",)) == tmp_path / "b.png"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.png"]  # the probe left nothing


def test_output_file_refuses_an_input_by_any_name(tmp_path: Path) -> None:
    (tmp_path / "photo.png").write_bytes(b"photo")
    os.symlink("photo.png", tmp_path / "link.png")
    for name in ("photo.png", "link.png", "./photo.png"):
        with pytest.raises(WiseError, match="is also the input INPUT"):
            output_file(tmp_path / name, {"INPUT": tmp_path / "photo.png"})


def test_output_folder_guard_removes_only_what_it_created(tmp_path: Path) -> None:
    folder = OutputFolder(tmp_path / "a" / "b", ("result.png",), {})
    with pytest.raises(RuntimeError):
        with folder.guard() as path:
            path.mkdir(parents=True)
            (path / "result.png").write_bytes(b"partial")
            raise RuntimeError("failed")
    assert list(tmp_path.iterdir()) == []

    existing = tmp_path / "old"
    existing.mkdir()
    (existing / "notes.txt").write_text("keep")
    with pytest.raises(KeyboardInterrupt):
        with OutputFolder(existing, ("result.png",), {}).guard():
            (existing / "result.png").write_bytes(b"new")
            raise KeyboardInterrupt
    assert sorted(p.name for p in existing.iterdir()) == ["notes.txt", "result.png"]


def test_output_folder_success_keeps_everything(tmp_path: Path) -> None:
    with OutputFolder(tmp_path / "run", ("result.png",), {}).guard() as path:
        path.mkdir()
        (path / "result.png").write_bytes(b"done")
    assert (tmp_path / "run" / "result.png").read_bytes() == b"done"
