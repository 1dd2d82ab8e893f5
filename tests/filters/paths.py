"""Run a filter on the PyTorch path and on the fused CPU kernels, and compare the two."""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Callable, Iterator, Sequence

import pytest
import torch

from wise.filters.fused import ENVIRONMENT_VARIABLE
from wise.filters.fused._drjit import llvm_backend

needs_kernels = pytest.mark.skipif(not llvm_backend(), reason="Dr.Jit's CPU backend does not start here (no LLVM)")
"""For tests of the fused kernels themselves: without them both paths would be PyTorch's."""


@contextmanager
def kernels(path: str) -> Iterator[None]:
    """Select ``"torch"`` or ``"fused"`` for the calls inside the block."""
    before = os.environ.get(ENVIRONMENT_VARIABLE)
    os.environ[ENVIRONMENT_VARIABLE] = path
    try:
        yield
    finally:
        if before is None:
            del os.environ[ENVIRONMENT_VARIABLE]
        else:
            os.environ[ENVIRONMENT_VARIABLE] = before


def run(path: str, fn: Callable[..., torch.Tensor], inputs: Sequence[torch.Tensor], seed: int = 0):
    """``fn(*inputs)`` on ``path`` and the gradients of a seeded random projection of its output
    for every input that requires grad."""
    with kernels(path):
        out = fn(*inputs)
        weights = torch.rand(out.shape, generator=torch.Generator().manual_seed(seed), dtype=out.dtype)
        wanted = [x for x in inputs if x.requires_grad]
        grads = torch.autograd.grad((out * weights).sum(), wanted, allow_unused=True) if wanted else ()
    return out.detach(), [g if g is not None else torch.zeros_like(x) for g, x in zip(grads, wanted)]


def assert_paths_agree(
    fn: Callable[..., torch.Tensor], inputs: Sequence[torch.Tensor], rtol: float = 1e-6, atol: float = 1e-9
) -> None:
    """Outputs and gradients of both paths agree within ``rtol`` of the largest magnitude of
    each tensor (plus ``atol``)."""
    out_torch, grads_torch = run("torch", fn, inputs)
    out_fused, grads_fused = run("fused", fn, inputs)
    for name, a, b in [("output", out_torch, out_fused)] + [
        (f"gradient {i}", g, h) for i, (g, h) in enumerate(zip(grads_torch, grads_fused))
    ]:
        scale = float(a.abs().max())
        error = float((a - b).abs().max())
        assert error <= rtol * scale + atol, f"{name}: max |torch - fused| {error:.3g}, scale {scale:.3g}"


def image_gradients(loss: Callable[[torch.Tensor], torch.Tensor], image: torch.Tensor, threads: int, runs: int = 2):
    """The gradient of ``loss(image)`` for ``image`` on the fused path, ``runs`` times, with PyTorch
    (and so the kernels) on ``threads`` threads."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with kernels("fused"):
            return [torch.autograd.grad(loss(image), image)[0] for _ in range(runs)]
    finally:
        torch.set_num_threads(before)


def assert_scatters_repeat(loss: Callable[[torch.Tensor], torch.Tensor], image: torch.Tensor) -> None:
    """A backward that scatters the image's gradient into per-thread copies: identical runs on one
    thread; on two, within rounding of one thread's (the copies are summed in the order the
    threads took the work, which may change the last bits)."""
    first, second = image_gradients(loss, image, threads=1)
    assert torch.equal(first, second)
    for parallel in image_gradients(loss, image, threads=2):
        assert torch.allclose(parallel, first, rtol=1e-5, atol=1e-5 * float(first.abs().max()))
