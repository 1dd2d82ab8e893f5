"""How many threads a process computes on: the cores it may use, not the cores of the machine.

PyTorch's pool of threads (and with it the fused kernels' pool, which follows PyTorch's count)
is sized by OpenMP, which counts the processors of the affinity mask but knows nothing of a CPU
quota: in a container limited to 2 cores of a 64-core machine it starts 64 threads, which then
take turns on 2 cores and wait on one another at every operation. :func:`usable_cores` takes the
smaller of the two; ``WISE_THREADS`` (or ``wise --threads``) overrides it.

``import wise`` applies the count before PyTorch loads (``OMP_NUM_THREADS``, unless that is set);
where PyTorch is loaded already, :func:`use_threads` sets its pool directly. Free of numerical
libraries, like the rest of what the command line does before its work.
"""

from __future__ import annotations

import math
import os
import sys
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
