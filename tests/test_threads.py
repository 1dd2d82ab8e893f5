"""The threads a process computes on: its affinity mask, its CPU quota, ``WISE_THREADS`` and
``wise --threads``."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from wise.errors import WiseError
from wise.threads import (
    THREADS_VARIABLE,
    TICKS_PER_SECOND,
    affinity_cores,
    cgroup_quota,
    cores_left,
    follow_load,
    following_load,
    processor_ticks,
    thread_count,
    usable_cores,
)

POOL = "import wise, torch; print(torch.get_num_threads())"
PLANNED = "import os, wise; print(os.environ['OMP_NUM_THREADS'])"


def _unset(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    """``name`` unset for the test and restored after, also when the code under test sets it
    (``delenv`` alone records nothing for a variable that is not set)."""
    monkeypatch.setenv(name, "")
    monkeypatch.delenv(name)


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

    _unset(monkeypatch, THREADS_VARIABLE)
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


STAT = """cpu  900 0 100 1000 0 0 0 0 0 0
cpu0 400 0 50 500 20 0 0 0 0 0
cpu1 500 0 50 500 0 0 10 0 0 0
cpu2 7 0 0 9 0 0 0 0 0 0
intr 1 2 3
"""


def test_processor_ticks_count_the_processors_given(tmp_path: Path) -> None:
    stat = tmp_path / "stat"
    stat.write_text(STAT)
    assert processor_ticks({0}, stat) == (450, 970)  # idle and iowait are not busy
    assert processor_ticks({0, 1}, stat) == (450 + 560, 970 + 1060)
    assert processor_ticks({5}, stat) is None
    assert processor_ticks({0}, tmp_path / "missing") is None


def test_the_cores_left_by_other_programs() -> None:
    assert cores_left(busy_seconds=2.0, own_seconds=2.0, wall_seconds=1.0, cores=2) == 2  # only this process
    assert cores_left(busy_seconds=2.0, own_seconds=0.7, wall_seconds=1.0, cores=2) == 1  # two busy programs
    assert cores_left(busy_seconds=0.2, own_seconds=0.0, wall_seconds=0.1, cores=2) == 1
    assert cores_left(busy_seconds=0.4, own_seconds=0.0, wall_seconds=1.0, cores=2) == 2  # a little noise
    assert cores_left(busy_seconds=8.0, own_seconds=0.0, wall_seconds=1.0, cores=4) == 1  # never none
    assert cores_left(busy_seconds=1.0, own_seconds=0.0, wall_seconds=1.0, cores=4) == 3


@pytest.fixture
def two_threads(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    import torch

    _unset(monkeypatch, THREADS_VARIABLE)
    monkeypatch.setattr("wise.threads.cgroup_quota", lambda root=None: None)
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1})
    given = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(given)


def _machine(monkeypatch: pytest.MonkeyPatch, others: list[float]) -> None:
    """/proc/stat as if other programs kept ``others[i]`` cores busy from the i-th measure on."""
    state = {"busy": 0.0, "wall": time.perf_counter(), "measures": 0}

    def ticks(cpus: set[int], stat: Path = Path()) -> tuple[int, int]:
        now = time.perf_counter()
        load = others[min(state["measures"], len(others) - 1)]
        state["busy"] += load * (now - state["wall"]) * TICKS_PER_SECOND
        state["wall"], state["measures"] = now, state["measures"] + 1
        return round(state["busy"]), 10**9

    monkeypatch.setattr("wise.threads.processor_ticks", ticks)
    monkeypatch.setattr("time.process_time", lambda: 0.0)


def test_work_computes_on_the_cores_other_programs_leave(monkeypatch: pytest.MonkeyPatch, two_threads: None) -> None:
    import torch

    _machine(monkeypatch, others=[0.0, 2.0, 2.0, 0.0])  # busy from the first measure, quiet again later
    with following_load():
        assert torch.get_num_threads() == 1
        with following_load():  # a nested block keeps the outer measure
            assert torch.get_num_threads() == 1
        follow_load()  # not due yet
        assert torch.get_num_threads() == 1
        follow_load(force=True)
        assert torch.get_num_threads() == 2  # the others stopped
    assert torch.get_num_threads() == 2
    _machine(monkeypatch, others=[0.0])
    with following_load():
        assert torch.get_num_threads() == 2


def test_a_chosen_thread_count_is_kept(monkeypatch: pytest.MonkeyPatch, two_threads: None) -> None:
    import torch

    _machine(monkeypatch, others=[2.0])
    monkeypatch.setenv(THREADS_VARIABLE, "2")
    with following_load():
        assert torch.get_num_threads() == 2
    monkeypatch.delenv(THREADS_VARIABLE)
    monkeypatch.setattr("wise.threads.cgroup_quota", lambda root=None: 1.5)  # a quota binds, not the processors
    with following_load():
        assert torch.get_num_threads() == 2


SPIN = "import time\nend = time.time() + 4\nwhile time.time() < end: sum(range(10_000))"


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or not Path("/proc/stat").exists(), reason="Linux only")
def test_beside_programs_holding_every_core_one_thread_computes() -> None:
    import torch

    cores = len(os.sched_getaffinity(0))
    if not 2 <= cores <= 8:
        pytest.skip("needs 2 to 8 processors to keep them all busy")
    given = torch.get_num_threads()
    torch.set_num_threads(cores)
    spinners = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(cores)]
    try:
        time.sleep(0.5)
        with following_load():
            assert torch.get_num_threads() == 1
        assert torch.get_num_threads() == cores
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()
        torch.set_num_threads(given)
