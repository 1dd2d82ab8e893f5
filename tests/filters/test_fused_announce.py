"""A command that compiles the kernels says so once; loading them from the cache says nothing."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

numba = pytest.importorskip("numba")

from wise.filters import fused  # noqa: E402

PROGRAM = """
import numba
from wise.filters import fused
fused.announce_compilation(lambda line: print("NOTICE", line))
add = numba.njit(cache=True)(lambda x: x + 1)
def twice(x):
    return 2 * x
twice = numba.njit(cache=True)(twice)
print(add(1), twice(2.0), twice(3))
"""


def test_the_first_compilation_is_announced_once(tmp_path) -> None:
    script = tmp_path / "kernels.py"
    script.write_text(PROGRAM)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    cold = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, check=True)
    assert cold.stdout.count("NOTICE") == 1 and fused.COMPILE_NOTICE in cold.stdout
    assert cold.stdout.strip().endswith("2 4.0 6")
    warm = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, check=True)
    assert "NOTICE" not in warm.stdout  # loaded from the cache: nothing to wait for


def test_the_command_line_installs_the_announcement(monkeypatch) -> None:
    from wise.cli import main

    monkeypatch.setattr(fused, "_announce", None)
    assert main(["effects"]) == 0
    assert fused._announce is not None
