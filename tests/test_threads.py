"""The threads a process computes on: its affinity mask, its CPU quota, ``WISE_THREADS`` and
``wise --threads``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from wise.errors import WiseError
from wise.threads import THREADS_VARIABLE, affinity_cores, cgroup_quota, thread_count, usable_cores

POOL = "import wise, torch; print(torch.get_num_threads())"
PLANNED = "import os, wise; print(os.environ['OMP_NUM_THREADS'])"


def test_a_cgroup_quota_is_read_in_cores(tmp_path: Path) -> None:
    assert cgroup_quota(tmp_path) is None  # no control group files: no quota
    (tmp_path / "cpu.max").write_text("max 100000\n")
    assert cgroup_quota(tmp_path) is None
    (tmp_path / "cpu.max").write_text("150000 100000\n")
    assert cgroup_quota(tmp_path) == 1.5
    assert usable_cores(tmp_path) == min(affinity_cores(), 2)
    (tmp_path / "cpu.max").write_text("50000 100000\n")
    assert usable_cores(tmp_path) == 1


def test_a_cgroup_v1_quota_is_read(tmp_path: Path) -> None:
    (tmp_path / "cpu").mkdir()
    (tmp_path / "cpu" / "cpu.cfs_quota_us").write_text("-1\n")
    (tmp_path / "cpu" / "cpu.cfs_period_us").write_text("100000\n")
    assert cgroup_quota(tmp_path) is None
    (tmp_path / "cpu" / "cpu.cfs_quota_us").write_text("100000\n")
    assert cgroup_quota(tmp_path) == 1.0


def test_wise_threads_overrides_and_is_checked(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(THREADS_VARIABLE, "3")
    assert thread_count() == 3
    monkeypatch.setenv(THREADS_VARIABLE, "many")
    with pytest.raises(WiseError, match="WISE_THREADS: expected a whole number of threads"):
        thread_count()


def _threads_of(env: dict[str, str], program: str = PLANNED) -> int:
    clean = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", THREADS_VARIABLE)}
    done = subprocess.run([sys.executable, "-c", program], env={**clean, **env}, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return int(done.stdout)


def test_importing_wise_first_sizes_pytorch_to_the_usable_cores() -> None:
    assert _threads_of({}) == usable_cores()
    assert _threads_of({THREADS_VARIABLE: "1"}, POOL) == 1  # PyTorch's pool takes the count
    assert _threads_of({"OMP_NUM_THREADS": "1"}) == 1  # the user's OpenMP setting stands
    assert _threads_of({"OMP_NUM_THREADS": "1", THREADS_VARIABLE: "2"}) == 2  # unless wise's is given


def test_the_command_line_takes_a_thread_count(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    import torch

    from wise.cli import main

    monkeypatch.delenv(THREADS_VARIABLE, raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", os.environ.get("OMP_NUM_THREADS", "1"))
    threads = torch.get_num_threads()
    try:
        assert main(["--threads", "1", "effects", "xdog"]) == 0
        assert os.environ[THREADS_VARIABLE] == "1" and torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(threads)
    assert main(["--threads", "0", "effects"]) == 2
    assert "--threads" in capsys.readouterr().err
    monkeypatch.setenv(THREADS_VARIABLE, "none")
    assert main(["effects", "xdog"]) == 2
    assert "WISE_THREADS: expected a whole number of threads" in capsys.readouterr().err
