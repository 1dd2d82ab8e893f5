"""Fused CPU kernels for the filters' sample loops, compiled by Dr.Jit or Numba.

The PyTorch filters of :mod:`wise.filters` set off one full-image tensor per sample and per
arithmetic step; on the CPU most of their time is memory traffic. Each module here holds the
same computation as one loop over pixels (forward and an analytic backward), beside the
PyTorch function it speeds up and under the same names: ``fused/gaussian.py`` accelerates
``gaussian.py``. The PyTorch path stays the reference (the tests compare with it) and the
path on every other device.

Two engines compile them, while the kernels move from the first to the second: Dr.Jit
(:mod:`wise.filters.fused._drjit`; vectorized across pixels, with its own compiled-code cache)
for the kernels written for it, Numba for the others. Which path runs is decided per call by
:func:`drjit_enabled` and :func:`enabled`: fused on CPU tensors of float32 or float64 when the
engine works, unless the environment variable ``WISE_KERNELS=torch`` asks for the PyTorch path.
Numba's compiled code is cached on disk (next to the sources, or in Numba's
per-user cache folder where the package is read-only), so only the first process compiles.

Kernels run on as many threads as PyTorch uses (:func:`torch.get_num_threads`), and one at a
time: Numba's default thread pool must not be entered by two threads at once (the editor's
server renders in threads).
"""

from __future__ import annotations

import importlib.util
import os
import signal
import sys
import threading
from contextlib import contextmanager
from typing import Callable, Iterator

import torch

ENVIRONMENT_VARIABLE = "WISE_KERNELS"
"""``torch`` selects the PyTorch path everywhere; ``fused`` (or unset) the fused kernels on the CPU."""

REQUESTS = ("torch", "fused")

FASTMATH = {"nsz", "arcp", "contract", "reassoc"}
"""LLVM flags for the kernels: reordering and fused multiply-add, but finite-math is not
assumed (a Gaussian weight may underflow to 0 and a sample may be exactly at the border)."""

_DTYPES = (torch.float32, torch.float64)
_lock = threading.Lock()
_numba_found: bool | None = None


def numba_available() -> bool:
    global _numba_found
    if _numba_found is None:
        _numba_found = importlib.util.find_spec("numba") is not None
    return _numba_found


def requested() -> str:
    """The path the environment asks for: ``"torch"`` or ``"fused"``."""
    value = os.environ.get(ENVIRONMENT_VARIABLE, "fused").strip().lower() or "fused"
    if value not in REQUESTS:
        from wise.errors import WiseError

        raise WiseError(f"{ENVIRONMENT_VARIABLE} must be 'torch' or 'fused', got {value!r}")
    return value


def enabled(*tensors: torch.Tensor) -> bool:
    """Whether the fused kernels compute an operation on ``tensors``: all on the CPU, of one
    floating-point dtype the kernels compile for, Numba installed and not switched off."""
    if requested() == "torch" or not numba_available():
        return False
    dtype = tensors[0].dtype
    return all(t.device.type == "cpu" and t.dtype == dtype for t in tensors) and dtype in _DTYPES


def drjit_enabled(*tensors: torch.Tensor) -> bool:
    """Whether the Dr.Jit kernels compute an operation on ``tensors``: all on the CPU, of one
    floating-point dtype the kernels handle, Dr.Jit's CPU backend working and not switched off."""
    if requested() == "torch":
        return False
    dtype = tensors[0].dtype
    if not (all(t.device.type == "cpu" and t.dtype == dtype for t in tensors) and dtype in _DTYPES):
        return False
    from wise.filters.fused._drjit import llvm_backend

    return llvm_backend()


def _numba():
    """Numba, on its own work-sharing thread pool unless ``NUMBA_THREADING_LAYER`` chooses another:
    an OpenMP pool does not survive the fork of a DataLoader worker (GNU OpenMP is not fork-safe),
    and the lock around the kernels makes up for the pool not being thread-safe."""
    import numba

    if "NUMBA_THREADING_LAYER" not in os.environ:
        numba.config.THREADING_LAYER = "workqueue"
    if _announce is not None:
        _listen_for_compilation()
    return numba


COMPILE_NOTICE = (
    "compiling the CPU kernels on first use (about 20 s per effect, once: they are cached on disk; "
    "`python -m wise.effects.compile` compiles them all ahead)"
)
"""What :func:`announce_compilation` prints when a kernel is compiled rather than loaded from the cache."""


_announce: Callable[[str], None] | None = None
_listening = False


def _listen_for_compilation() -> None:
    """Install, once per process, the Numba listener that hands :data:`COMPILE_NOTICE` to
    ``_announce`` at the process's first compilation (Numba reports one only on a cache miss, so
    a warm cache prints nothing)."""
    global _listening
    if _listening:
        return
    from numba.core import event

    class Listener(event.Listener):
        def on_start(self, _event: object) -> None:
            global _announce
            announce, _announce = _announce, None
            if announce is not None:
                announce(COMPILE_NOTICE)

        def on_end(self, _event: object) -> None:
            pass

    event.register("numba:compile", Listener())
    _listening = True


def announce_compilation(print_line: Callable[[str], None]) -> None:
    """Have ``print_line`` called once with :data:`COMPILE_NOTICE` when this process next compiles
    a kernel instead of loading it from the cache, so that a command does not wait silently."""
    global _announce
    _announce = print_line
    if "numba" in sys.modules:  # imported already: kernels may compile from now on
        _listen_for_compilation()


@contextmanager
def _interrupt_after() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) until the block ends, then deliver it to the handler that was there.

    A kernel's first call compiles it, and LLVM reports to Python through ctypes callbacks, which
    swallow an exception raised in them: a Ctrl-C that lands there would be lost. Signals are
    handled only in the main thread, so elsewhere the block runs as it is."""
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(previous):
        yield
        return
    received: list[object] = []
    signal.signal(signal.SIGINT, lambda signum, frame: received.append(frame))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if received:
            previous(signal.SIGINT, received[0])


@contextmanager
def kernel_threads() -> Iterator[None]:
    """Run a kernel with PyTorch's thread count, one kernel at a time in the process; a Ctrl-C
    during the kernel (or its compilation) takes effect when it returns."""
    numba = _numba()
    with _lock, _interrupt_after():
        torch_threads = torch.get_num_threads()
        numba.set_num_threads(max(1, min(torch_threads, numba.config.NUMBA_NUM_THREADS)))
        try:
            yield
        finally:  # an OpenMP pool shared with PyTorch (NUMBA_THREADING_LAYER=omp) would change its count
            torch.set_num_threads(torch_threads)


def chunks() -> int:
    """Number of private accumulators of a backward pass that scatters: one per thread."""
    numba = _numba()

    return max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS))


def array(tensor: torch.Tensor):
    """A contiguous NumPy view (or copy) of a CPU tensor, detached."""
    return tensor.detach().contiguous().numpy()


def full(tensor: torch.Tensor, shape: torch.Size | tuple[int, ...]):
    """``tensor`` broadcast to ``shape`` as a contiguous NumPy array."""
    return tensor.detach().expand(shape).contiguous().numpy()


def reduce_to(grad: torch.Tensor, shape: torch.Size) -> torch.Tensor:
    """Sum a gradient over the dimensions that were broadcast from ``shape``."""
    dims = [i for i, (g, s) in enumerate(zip(grad.shape, shape)) if s == 1 and g != 1]
    return grad.sum(dim=dims, keepdim=True) if dims else grad
