"""Fused CPU kernels of the filters, compiled by Dr.Jit.

The PyTorch filters of :mod:`wise.filters` set off one full-image tensor per sample and per
arithmetic step; on the CPU most of their time is memory traffic. Each module here holds the
same computation written per pixel (forward and backward), beside the PyTorch function it
speeds up and under the same names: ``fused/gaussian.py`` accelerates ``gaussian.py``. The
PyTorch path stays the reference (the tests compare with it) and the path on every other device.

Dr.Jit (:mod:`wise.filters.fused._drjit`) traces the per-pixel code into one kernel per pass,
vectorized across pixels (one SIMD lane per pixel) and parallel over blocks of them, compiled by
LLVM and cached on disk by its code; sizes and other values that change between calls are read
by the kernel, so a new picture size compiles nothing. Per-pixel chains of arithmetic (colour
conversions, noise) are differentiated by Dr.Jit itself (:mod:`wise.filters.fused._pointwise`);
kernels that sample their neighbourhood have hand-written backward passes.

Which path runs is decided per call by :func:`enabled`: fused on CPU tensors of float32 or
float64 when Dr.Jit's CPU backend works (it needs the system's LLVM library; without it a notice
says how to get it), unless the environment variable ``WISE_KERNELS=torch`` asks for the
PyTorch path. Kernels run on as many threads as PyTorch uses, one at a time in a process.
"""

from __future__ import annotations

import atexit
import hashlib
import os
from pathlib import Path

import torch

from wise.notices import take_compilation_announcer

ENVIRONMENT_VARIABLE = "WISE_KERNELS"
"""``torch`` selects the PyTorch path everywhere; ``fused`` (or unset) the fused kernels on the CPU."""

REQUESTS = ("torch", "fused")

_DTYPES = (torch.float32, torch.float64)


def requested() -> str:
    """The path the environment asks for: ``"torch"`` or ``"fused"``."""
    value = os.environ.get(ENVIRONMENT_VARIABLE, "fused").strip().lower() or "fused"
    if value not in REQUESTS:
        from wise.errors import WiseError

        raise WiseError(f"{ENVIRONMENT_VARIABLE} must be 'torch' or 'fused', got {value!r}")
    return value


def enabled(*tensors: torch.Tensor) -> bool:
    """Whether the fused kernels compute an operation on ``tensors``: all on the CPU, of one
    floating-point dtype the kernels handle, Dr.Jit's CPU backend working and not switched off."""
    if requested() == "torch":
        return False
    dtype = tensors[0].dtype
    if not (all(t.device.type == "cpu" and t.dtype == dtype for t in tensors) and dtype in _DTYPES):
        return False
    from wise.filters.fused._drjit import llvm_backend

    if not llvm_backend():
        return False
    _announce_if_cold()
    return True


def reduce_to(grad: torch.Tensor, shape: torch.Size) -> torch.Tensor:
    """Sum a gradient over the dimensions that were broadcast from ``shape``."""
    dims = [i for i, (g, s) in enumerate(zip(grad.shape, shape)) if s == 1 and g != 1]
    return grad.sum(dim=dims, keepdim=True) if dims else grad


COMPILE_NOTICE = (
    "compiling the CPU kernels on first use (a few seconds per effect, once: they are cached on disk; "
    "`python -m wise.effects.compile` compiles them ahead)"
)
"""What the printer of :func:`wise.notices.announce_compilation` gets when the kernels of this
version were never compiled here (not ahead by :mod:`wise.effects.compile`, nor by an earlier
command)."""


def kernels_version() -> str:
    """A digest of the kernels' sources: compiled kernels of another version do not count as warm."""
    digest = hashlib.sha256()
    for source in sorted(Path(__file__).parent.glob("*.py")):
        digest.update(source.read_bytes())
    return digest.hexdigest()[:16]


def warm_marker() -> Path:
    """The file :mod:`wise.effects.compile` leaves once every effect's kernels of this version are
    compiled into the cache (in the user's cache folder, beside Dr.Jit's own)."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "wise" / f"kernels-{kernels_version()}"


def _announce_if_cold() -> None:
    announce = take_compilation_announcer()
    if announce is not None and not warm_marker().exists():
        announce(COMPILE_NOTICE)
        atexit.register(_mark_warm)  # the next command loads what this one compiled


def _mark_warm() -> None:
    try:
        marker = warm_marker()
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.touch()
    except OSError:  # a read-only home: the notice shows again, nothing worse
        pass
