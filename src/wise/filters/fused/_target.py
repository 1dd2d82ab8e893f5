"""The CPU that Dr.Jit's LLVM backend compiles for, and its hardware gathers.

The kernels read bilinear samples with gathers: one SIMD instruction (``vgatherdps``) reads 8
lanes' values from 8 addresses. LLVM emits that instruction only for CPUs its cost model calls
fast at gathers (Intel from Skylake on, and any CPU with AVX-512); for the others, AMD's Zen 3
among them, it writes every gather as 8 scalar loads, each behind a branch on its lane's mask,
about six times the code. On Zen 3 the hardware gathers were measured faster
(``benchmarks/bench_gathers.py``: whole renders at 1024² ×1.08–1.23), so for the CPUs in
:data:`HARDWARE_GATHER_CPUS` the backend is told that gathers are fast. The kernels compute the
same values either way; only the instructions that read them differ.

Dr.Jit keeps the setter in its C++ library (``jit_llvm_set_target``) without a Python binding,
so it is called through ``ctypes``; where the library lacks the symbols nothing changes.
"""

from __future__ import annotations

import ctypes
import functools
import os
from dataclasses import dataclass

HARDWARE_GATHER_CPUS = ("znver3",)
"""LLVM's names of the CPUs on which hardware gathers were measured faster than LLVM's scalar
code (AVX-512 CPUs get hardware gathers from LLVM already)."""

FAST_GATHER = "+fast-gather"
"""LLVM's target feature that makes its cost model emit hardware gathers."""


@dataclass(frozen=True)
class Target:
    """What the backend compiles for: the CPU's LLVM name, the target features and the number of
    lanes of a packet."""

    cpu: str
    features: str
    vector_width: int

    @property
    def hardware_gathers(self) -> bool:
        flags = self.features.split(",")
        return FAST_GATHER in flags or "+avx512f" in flags


def wants_hardware_gathers(target: Target) -> bool:
    """Whether ``target`` should be told that gathers are fast: a measured CPU with AVX2 whose
    features do not already give hardware gathers."""
    return target.cpu in HARDWARE_GATHER_CPUS and "+avx2" in target.features.split(",") and not target.hardware_gathers


@functools.cache
def _library() -> ctypes.CDLL | None:
    import drjit

    path = os.path.join(os.path.dirname(drjit.__file__), "libdrjit-core.so")
    if not os.path.isfile(path):
        return None
    library = ctypes.CDLL(path)
    try:
        library._Z19jit_llvm_target_cpuv.restype = ctypes.c_char_p
        library._Z24jit_llvm_target_featuresv.restype = ctypes.c_char_p
        library._Z21jit_llvm_vector_widthv.restype = ctypes.c_uint32
        library._Z19jit_llvm_set_targetPKcS0_j.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
        library._Z19jit_llvm_set_targetPKcS0_j.restype = None
    except AttributeError:
        return None
    return library


def current() -> Target | None:
    """The backend's target (once the LLVM backend has started), or ``None`` where this Dr.Jit
    does not export it."""
    library = _library()
    if library is None:
        return None
    return Target(
        library._Z19jit_llvm_target_cpuv().decode(),
        library._Z24jit_llvm_target_featuresv().decode(),
        int(library._Z21jit_llvm_vector_widthv()),
    )


def set_hardware_gathers(enabled: bool) -> bool:
    """Add or remove :data:`FAST_GATHER` in the backend's features for the kernels compiled from
    now on (compiled kernels are cached by their code, which names the features, so both kinds
    can live side by side). Returns whether the target was changed."""
    library, target = _library(), current()
    if library is None or target is None:
        return False
    flags = [flag for flag in target.features.split(",") if flag and flag != FAST_GATHER]
    if enabled:
        flags.append(FAST_GATHER)
    features = ",".join(flags)
    if features == target.features:
        return False
    library._Z19jit_llvm_set_targetPKcS0_j(target.cpu.encode(), features.encode(), target.vector_width)
    return True


def choose_gathers() -> None:
    """Hardware gathers where :func:`wants_hardware_gathers` says so; called once, right after
    the LLVM backend starts."""
    target = current()
    if target is not None and wants_hardware_gathers(target):
        set_hardware_gathers(True)
