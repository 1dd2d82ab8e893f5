"""Output locations checked before any work, and nothing left behind when a command fails.

One rule for every command (:data:`OVERWRITE_RULE`, shown in each ``--help``): an existing
output file is replaced, but only once its new content is complete (files are written to a
temporary name and moved into place); an output that is one of the command's inputs is
refused; an output folder a failed command created is removed again.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from pathlib import Path
from typing import Iterable, Iterator, Mapping

from wise.errors import WiseError

OVERWRITE_RULE = (
    "Outputs: an existing output file is replaced once the new one is complete; an output that is "
    "one of the inputs is refused; a failed or refused command leaves no new files or folders."
)

Inputs = Mapping[str, "str | os.PathLike[str] | None"]
"""The command's input files by the option that names them, e.g. ``{"--content": "photo.jpg"}``."""


def _stat(path: Path, follow: bool = True) -> os.stat_result | None:
    """``os.stat`` of ``path``; None when it does not exist; refuses symbolic-link loops."""
    try:
        return os.stat(path) if follow else os.lstat(path)
    except FileNotFoundError:
        return None
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise WiseError(f"{path}: a loop of symbolic links; choose another name") from None
        if e.errno == errno.ENOTDIR:
            raise WiseError(f"{path}: a part of the path is a file, not a directory") from None
        raise WiseError(f"{path}: cannot be used ({e.strerror or e})") from None


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def _probe_writable(folder: Path, shown: Path) -> None:
    """Create and remove a temporary file in ``folder``: the only test that also catches
    read-only file systems and access rules ``os.access`` does not see."""
    try:
        fd, name = tempfile.mkstemp(prefix=".wise-probe-", dir=folder)
    except OSError as e:
        raise WiseError(f"{shown}: cannot write into the directory {folder} ({e.strerror or e})") from None
    os.close(fd)
    os.unlink(name)


def _refuse_inputs(path: Path, inputs: Inputs) -> None:
    for option, given in inputs.items():
        if given is not None and _same_file(path, Path(given)):
            raise WiseError(f"{path}: is also the input {option}; write the result to another file")


def _check_file_slot(path: Path, inputs: Inputs) -> None:
    """``path`` may be written: absent, or a regular file that is not an input."""
    found = _stat(path)
    if found is None:
        if _stat(path, follow=False) is not None:
            raise WiseError(f"{path}: a symbolic link to a missing file; remove it or choose another name")
        return
    if stat.S_ISDIR(found.st_mode):
        raise WiseError(f"{path}: is a directory; give the name of a file to write")
    if not stat.S_ISREG(found.st_mode):
        raise WiseError(f"{path}: exists and is not a regular file; choose another name")
    _refuse_inputs(path, inputs)


def output_file(path: str | os.PathLike[str], inputs: Inputs, suffixes: Iterable[str] | None = None) -> Path:
    """Check an output file before the work: a writable folder, a name that is free or a
    regular file (replaced at the end), a supported extension, not one of ``inputs``."""
    target = Path(path)
    if suffixes is not None:
        allowed = tuple(suffixes)
        if target.suffix.lower() not in allowed:
            found = f"'{target.suffix}'" if target.suffix else "no extension"
            raise WiseError(f"{target}: cannot write a file with {found}; use one of {', '.join(allowed)}")
    _check_file_slot(target, inputs)
    folder = target.parent
    found = _stat(folder)
    if found is None:
        raise WiseError(f"{target}: the directory {folder} does not exist; create it first")
    if not stat.S_ISDIR(found.st_mode):
        raise WiseError(f"{target}: {folder} is not a directory")
    _probe_writable(folder, target)
    return target


class OutputFolder:
    """A results folder checked before the work (:meth:`check` runs on creation) and removed
    again by :meth:`guard` when the command fails before it has written its results."""

    def __init__(self, path: str | os.PathLike[str], files: Iterable[str], inputs: Inputs) -> None:
        self.path = Path(path)
        self.files = tuple(files)
        self.inputs = inputs
        self.check()

    def check(self) -> None:
        found = _stat(self.path)
        if found is not None:
            if not stat.S_ISDIR(found.st_mode):
                raise WiseError(f"{self.path}: exists and is not a directory; give a directory name for the results")
            _probe_writable(self.path, self.path)
            for name in self.files:
                _check_file_slot(self.path / name, self.inputs)
            return
        if _stat(self.path, follow=False) is not None:
            raise WiseError(f"{self.path}: a symbolic link to a missing directory; remove it or choose another name")
        ancestor = self.path.parent
        while _stat(ancestor) is None and ancestor != ancestor.parent:
            ancestor = ancestor.parent
        if not ancestor.is_dir():
            raise WiseError(f"{self.path}: {ancestor} is a file, not a directory")
        _probe_writable(ancestor, self.path)

    def _missing_parts(self) -> list[Path]:
        """The folders of ``path`` that do not exist yet, innermost first."""
        missing, folder = [], self.path
        while _stat(folder) is None and folder != folder.parent:
            missing.append(folder)
            folder = folder.parent
        return missing

    @contextlib.contextmanager
    def guard(self) -> Iterator[Path]:
        """Run the work; when it raises (Ctrl-C included), remove the folders it created
        together with the result files in them (never anything else)."""
        created = self._missing_parts()
        try:
            yield self.path
        except BaseException:
            for folder in created:
                for name in self.files:
                    with contextlib.suppress(OSError):
                        (folder / name).unlink()
                for leftover in folder.glob(".*.tmp"):
                    with contextlib.suppress(OSError):
                        leftover.unlink()
                with contextlib.suppress(OSError):
                    folder.rmdir()
            raise
