"""How many threads a process computes on: the cores it may use, not the cores of the machine.

PyTorch's pool of threads (and with it the fused kernels' pool, which follows PyTorch's count)
is sized by OpenMP, which counts the processors of the affinity mask but knows nothing of a CPU
quota: in a container limited to 2 cores of a 64-core machine it starts 64 threads, which then
take turns on 2 cores and wait on one another at every operation. :func:`usable_cores` takes the
smaller of the two; ``WISE_THREADS`` (or ``wise --threads``) overrides it.

``import wise`` applies the count before PyTorch loads (``OMP_NUM_THREADS``, unless that is set);
where PyTorch is loaded already, :func:`use_threads` sets its pool directly. Work that runs for
seconds (a refinement, an optimization) computes inside :func:`following_load` on the cores other
programs leave free, measured again as it runs. Free of numerical libraries, like the rest of
what the command line does before its work.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from wise.errors import WiseError

THREADS_VARIABLE = "WISE_THREADS"
"""The number of threads to compute on, overriding :func:`usable_cores`."""
OPENMP_VARIABLE = "OMP_NUM_THREADS"
MAX_THREADS = 1024

CGROUP_ROOT = Path("/sys/fs/cgroup")
"""Where the kernel shows the process's control groups (their CPU quota)."""


def affinity_cores() -> int:
    """The processors the process may run on (its affinity mask; all of them where there is none)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def cgroup_quota(root: Path = CGROUP_ROOT) -> float | None:
    """The CPU quota of the process's control group in cores (``cpu.max`` of cgroup v2, or
    ``cpu.cfs_quota_us / cpu.cfs_period_us`` of v1), or ``None`` where there is none."""
    try:
        quota, period = (root / "cpu.max").read_text().split()[:2]
        if quota != "max":
            return int(quota) / int(period)
        return None
    except (OSError, ValueError):
        pass
    try:
        quota_us = int((root / "cpu" / "cpu.cfs_quota_us").read_text())
        period_us = int((root / "cpu" / "cpu.cfs_period_us").read_text())
    except (OSError, ValueError):
        return None
    return quota_us / period_us if quota_us > 0 and period_us > 0 else None


def usable_cores(root: Path = CGROUP_ROOT) -> int:
    """The cores the process may use: its affinity mask, at most its CPU quota rounded up."""
    cores = affinity_cores()
    quota = cgroup_quota(root)
    if quota is not None:
        cores = min(cores, max(1, math.ceil(quota)))
    return cores


def parse_threads(text: str, source: str) -> int:
    """A thread count from ``text``, refused in one line naming ``source`` when it is not one."""
    try:
        count = int(text.strip())
    except ValueError:
        count = 0
    if not 1 <= count <= MAX_THREADS:
        raise WiseError(f"{source}: expected a whole number of threads from 1 to {MAX_THREADS}, got {text!r}")
    return count


def thread_count() -> int:
    """``WISE_THREADS`` when set, else :func:`usable_cores`."""
    text = os.environ.get(THREADS_VARIABLE, "")
    if text.strip():
        return parse_threads(text, THREADS_VARIABLE)
    return usable_cores()


def prefer_usable_cores() -> bool:
    """Before PyTorch loads: size OpenMP's pool to :func:`thread_count` for this process and its
    children, unless ``OMP_NUM_THREADS`` is set and ``WISE_THREADS`` is not. Whether it did."""
    if "torch" in sys.modules:
        return False
    explicit = bool(os.environ.get(THREADS_VARIABLE, "").strip())
    if OPENMP_VARIABLE in os.environ and not explicit:
        return False
    try:
        count = thread_count()
    except WiseError:
        return False  # a bad WISE_THREADS is reported by the command that reads it
    os.environ[OPENMP_VARIABLE] = str(count)
    return True


def use_threads(count: int) -> int:
    """Compute on ``count`` threads from now on (in this process and the processes it starts)."""
    os.environ[THREADS_VARIABLE] = os.environ[OPENMP_VARIABLE] = str(count)
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(count)
    return count


PROC_STAT = Path("/proc/stat")
"""Where Linux counts each processor's busy and idle time since boot."""
LOAD_WINDOW = 0.1
"""Seconds over which the first measure of the other programs' load is taken."""
LOAD_EVERY = 1.0
"""Seconds between the measures of the other programs' load while work runs."""
IDLE_FIELDS = (3, 4)
"""The idle and iowait columns of a processor's line in ``/proc/stat``."""


def processor_ticks(cpus: set[int], stat: Path = PROC_STAT) -> tuple[int, int] | None:
    """The busy and the total clock ticks of the processors ``cpus`` since boot, or ``None``
    where the system does not count them (not Linux)."""
    busy = total = 0
    try:
        lines = stat.read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        name, *fields = line.split()
        if not (name.startswith("cpu") and name[3:].isdigit() and int(name[3:]) in cpus):
            continue
        ticks = [int(field) for field in fields[:8]]
        idle = sum(ticks[index] for index in IDLE_FIELDS)
        busy, total = busy + sum(ticks) - idle, total + sum(ticks)
    return (busy, total) if total else None


def cores_left(busy_seconds: float, own_seconds: float, wall_seconds: float, cores: int) -> int:
    """Threads to compute on when the processors were busy ``busy_seconds`` in ``wall_seconds``,
    ``own_seconds`` of it this process's: the cores the others left, rounded, from 1 to ``cores``."""
    others = max(0.0, busy_seconds - own_seconds) / max(wall_seconds, 1e-6)
    return min(cores, max(1, math.floor(cores - others + 0.5)))


class LoadFollower:
    """Sizes PyTorch's pool of threads (and the fused kernels', which follow it) to the cores that
    other programs leave free, measured on the processors the process may run on, up to the count
    it had: a thread waiting for a core that another program holds makes every parallel operation
    wait for it (an XDoG refinement beside two busy processes made 33 iterations on two threads
    and 63 on one, BENCHMARKS.md, "Threads beside busy programs"). Not where ``WISE_THREADS`` is
    set, one thread is given, a CPU quota rather than the processors bounds the process, or the
    system does not count the processors' time."""

    def __init__(self, every: float = LOAD_EVERY) -> None:
        self.every = every
        self.cores = 0
        self.cpus: set[int] = set()
        self._last: tuple[float, float, int] | None = None  # wall, own CPU seconds, busy ticks

    def start(self, torch_threads: int) -> bool:
        """Begin following from ``torch_threads``; whether the load can be followed here."""
        if os.environ.get(THREADS_VARIABLE, "").strip() or torch_threads < 2:
            return False
        quota = cgroup_quota()
        self.cpus = set(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else set()
        if not self.cpus or (quota is not None and quota < len(self.cpus)):
            return False
        self.cores = torch_threads
        self._sample()
        return self._last is not None

    def _sample(self) -> tuple[float, float, int] | None:
        ticks = processor_ticks(self.cpus)
        if ticks is None:
            return None
        previous, self._last = self._last, (time.perf_counter(), time.process_time(), ticks[0])
        return previous

    def threads(self, force: bool = False) -> int | None:
        """The threads to compute on now, where a measure is due (``every`` seconds after the
        last, at once with ``force``); else ``None``."""
        if self._last is None or not (force or time.perf_counter() - self._last[0] >= self.every):
            return None
        previous = self._sample()
        if previous is None or self._last is None:
            return None
        wall, own, busy = (now - then for now, then in zip(self._last, previous))
        return cores_left(busy / TICKS_PER_SECOND, own, wall, self.cores)


TICKS_PER_SECOND = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
_follower: LoadFollower | None = None


@contextlib.contextmanager
def following_load() -> Iterator[None]:
    """While the block runs, PyTorch computes on the cores other programs leave free
    (:class:`LoadFollower`), measured over :data:`LOAD_WINDOW` at the start and again every
    :data:`LOAD_EVERY` seconds where the work calls :func:`follow_load`; the count it had is
    restored after. Nested blocks follow the outermost's measure."""
    global _follower
    torch = sys.modules.get("torch")
    follower = LoadFollower()
    if _follower is not None or torch is None or not follower.start(torch.get_num_threads()):
        yield
        return
    given = torch.get_num_threads()
    _follower = follower
    try:
        time.sleep(LOAD_WINDOW)
        follow_load(force=True)
        yield
    finally:
        _follower = None
        torch.set_num_threads(given)


def follow_load(force: bool = False) -> None:
    """Inside :func:`following_load`, resize PyTorch's pool where a measure is due; else nothing."""
    torch = sys.modules.get("torch")
    if _follower is None or torch is None:
        return
    count = _follower.threads(force)
    if count is not None and count != torch.get_num_threads():
        torch.set_num_threads(count)
