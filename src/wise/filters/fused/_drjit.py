"""The Dr.Jit engine of the fused kernels: finding LLVM, moving tensors in and out, threads.

Dr.Jit (the engine of the Mitsuba 3 renderer) traces array code in which each SIMD lane is a
pixel, fuses it into one kernel and compiles it with LLVM on the CPU (vectorized over 8 or 16
pixels, parallel over blocks of pixels) or for CUDA. Kernels are cached on disk, keyed by their
code, so a process pays the compilation only for kernels no process has compiled before.

The CPU backend loads the system's ``libLLVM`` at run time. Without it the kernels of this
engine are off, the filters run on the PyTorch path, and :data:`MISSING_LLVM_NOTICE` says once
on stderr how to get the fast path.
"""

from __future__ import annotations

import glob
import importlib.util
import os
import re
import sys
import tempfile
import threading
from contextlib import contextmanager
from typing import Iterator

import torch

LIBLLVM_VARIABLE = "DRJIT_LIBLLVM_PATH"
"""Dr.Jit's own variable for the ``libLLVM`` it loads; set, it is used as it is."""

LIBRARY_FOLDERS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/usr/lib/llvm-*/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)
"""Where :func:`find_libllvm` looks for ``libLLVM`` (Debian and Ubuntu, Fedora, Homebrew)."""

MISSING_LLVM_NOTICE = (
    "the fast CPU kernels need the LLVM library (on Debian or Ubuntu: `sudo apt-get install libllvm15` or newer, "
    f"or set {LIBLLVM_VARIABLE} to a libLLVM); rendering on the slower PyTorch path"
)

_lock = threading.Lock()
_state: dict[str, bool] = {}


MIN_LLVM = 15
"""The oldest LLVM Dr.Jit's CPU backend works with."""


def _version(path: str) -> tuple[int, ...]:
    numbers = re.findall(r"\d+", os.path.basename(path))
    return tuple(int(n) for n in numbers) or (0,)


def _too_old(path: str) -> bool:
    """Whether a library's name says it is an LLVM older than :data:`MIN_LLVM` (a name without a
    version says nothing)."""
    version = _version(path)
    return version != (0,) and version[0] < MIN_LLVM


_TOO_OLD = f" (the LLVM found is too old: Dr.Jit needs {MIN_LLVM} or newer)"


def find_libllvm() -> str | None:
    """The newest ``libLLVM`` shared library in :data:`LIBRARY_FOLDERS`, or ``None``."""
    found: list[str] = []
    for folder in LIBRARY_FOLDERS:
        for pattern in ("libLLVM-*.so*", "libLLVM.so.*", "libLLVM.dylib"):
            found.extend(glob.glob(os.path.join(folder, pattern)))
    found = [path for path in found if os.path.isfile(path)]
    return max(found, key=_version) if found else None


def drjit_installed() -> bool:
    return importlib.util.find_spec("drjit") is not None


def llvm_backend() -> bool:
    """Whether Dr.Jit's CPU backend works in this process (imports Dr.Jit the first time)."""
    if "llvm" not in _state:
        _state["llvm"] = _start_llvm()
    return _state["llvm"]


def _start_llvm() -> bool:
    if not drjit_installed():
        return False
    if LIBLLVM_VARIABLE not in os.environ:
        library = find_libllvm()
        if library is not None:
            os.environ[LIBLLVM_VARIABLE] = library
    if _too_old(os.environ.get(LIBLLVM_VARIABLE, "")):
        # not handed to Dr.Jit at all: it would only refuse it (and a refused library has been
        # seen to leave the process hanging at exit under load)
        print(f"wise: {MISSING_LLVM_NOTICE}{_TOO_OLD}", file=sys.stderr, flush=True)
        return False
    with _stderr_of_native_code() as messages:
        import drjit

        working = bool(drjit.has_backend(drjit.JitBackend.LLVM))
    if working:
        from wise.filters.fused._target import choose_gathers

        choose_gathers()
    if not working:
        too_old = any("too old" in line for line in messages)
        print(f"wise: {MISSING_LLVM_NOTICE}{_TOO_OLD if too_old else ''}", file=sys.stderr, flush=True)
    return working


@contextmanager
def _stderr_of_native_code() -> Iterator[list[str]]:
    """Collect what native code writes to the process's stderr inside the block (Dr.Jit reports a
    missing or unusable LLVM in several lines of its own; the notice says it in one)."""
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as captured:
        os.dup2(captured.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            captured.seek(0)
            lines.extend(captured.read().decode(errors="replace").splitlines())


def float_type(dtype: torch.dtype):
    """Dr.Jit's CPU array type of ``dtype`` (float32 or float64)."""
    import drjit.llvm as backend

    return backend.Float64 if dtype == torch.float64 else backend.Float32


def flat(tensor: torch.Tensor, array_type, shape: torch.Size | tuple[int, ...] | None = None):
    """``tensor`` (broadcast to ``shape``) as a flat Dr.Jit array, sharing memory where it is contiguous."""
    value = tensor.detach()
    if shape is not None:
        value = value.expand(shape)
    return array_type(value.contiguous().reshape(-1))


def as_tensor(array, shape: tuple[int, ...]) -> torch.Tensor:
    """An evaluated flat array as a tensor of ``shape``. Kernels write into Dr.Jit's own arrays
    (``drjit.zeros``), not into tensors' memory: a scatter may move its target to a new buffer."""
    import drjit

    drjit.sync_thread()  # kernels run asynchronously
    return array.torch().view(shape)


def to_torch(arrays, shape: tuple[int, ...]) -> torch.Tensor:
    """Flat arrays of one picture channel each (``shape`` = ``(B, H, W)``, without the channel)
    as ``(B, len(arrays), H, W)``: written into one array by a Dr.Jit kernel (a copy on the
    engine's threads into its cached memory, where ``torch.stack`` would fault in fresh pages)."""
    import drjit
    from drjit.llvm import UInt32

    if len(arrays) == 1:
        return as_tensor(arrays[0], (shape[0], 1, *shape[1:]))
    batch, height, width = shape
    plane, channels = height * width, len(arrays)
    lane = drjit.arange(UInt32, batch * plane)
    picture, pixel = lane // drjit.opaque(UInt32, plane), lane % drjit.opaque(UInt32, plane)
    target = drjit.empty(type(arrays[0]), batch * channels * plane)
    for channel, array in enumerate(arrays):
        index = (picture * channels + channel) * drjit.opaque(UInt32, plane) + pixel
        drjit.scatter(target, array, index, mode=drjit.ReduceMode.Permute)
    drjit.eval(target)
    return as_tensor(target, (batch, channels, height, width))


@contextmanager
def kernel_threads() -> Iterator[None]:
    """Trace and run a kernel on as many threads as PyTorch uses, one kernel at a time in the
    process (the editor's server renders in threads)."""
    import drjit

    with _lock:
        threads = max(1, torch.get_num_threads())
        if drjit.thread_count() != threads:
            drjit.set_thread_count(threads)
        yield
