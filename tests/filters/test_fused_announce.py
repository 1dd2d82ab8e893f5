"""A command that will compile the kernels says so once; after they were compiled ahead it says nothing."""

from __future__ import annotations

import os
import subprocess
import sys

from tests.filters.paths import needs_kernels
from wise.filters import fused

pytestmark = needs_kernels

PROGRAM = """
import torch
from wise import notices
from wise.filters.gaussian import gaussian_blur
notices.announce_compilation(lambda line: print("NOTICE", line))
for size in (9, 12):
    gaussian_blur(torch.rand(1, 1, size, size), torch.full((1, 1, size, size), 1.0), scale=1.0)
print("done")
"""


def _run(tmp_path) -> str:
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    done = subprocess.run([sys.executable, "-c", PROGRAM], env=env, capture_output=True, text=True, check=True)
    return done.stdout


def test_the_first_use_of_cold_kernels_is_announced_once(tmp_path) -> None:
    cold = _run(tmp_path)
    assert cold.count("NOTICE") == 1 and fused.COMPILE_NOTICE in cold
    assert cold.strip().endswith("done")
    assert "NOTICE" not in _run(tmp_path)  # the next command loads what the first compiled


def test_kernels_compiled_ahead_are_not_announced(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    marker = fused.warm_marker()
    marker.parent.mkdir(parents=True)
    marker.touch()
    assert "NOTICE" not in _run(tmp_path)


def test_the_command_line_installs_the_announcement(monkeypatch) -> None:
    from wise import notices
    from wise.cli import main

    monkeypatch.setattr(notices, "_compilation", None)
    assert main(["effects"]) == 0
    assert notices._compilation is not None
