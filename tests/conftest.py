import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import torch.nn.functional as F
from skimage import data

from wise.filters import fused

COMPILED_KERNELS = 50
"""Compiled kernels (float32 and float64) in the package's cache when every effect has run."""


def pytest_sessionstart(session: pytest.Session) -> None:
    """With a cold cache (a fresh clone), the fused kernels are compiled for both dtypes before
    the tests, the two at once: that halves the compile time, and no timed test waits for a
    compilation."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        # started in the background by a shell without job control: the Ctrl-C tests need it back
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if fused.requested() != "fused" or not fused.numba_available():
        return
    if os.environ.get("PYTEST_XDIST_WORKER"):  # the controller compiled before it started the workers
        return
    cache = Path(fused.__file__).parent / "__pycache__"
    if len(list(cache.glob("*.nbc"))) < COMPILED_KERNELS:
        subprocess.run([sys.executable, "-m", "wise.effects.compile", "float32", "float64"], check=True)


@pytest.fixture(scope="session")
def astronaut() -> torch.Tensor:
    """``skimage.data.astronaut()`` as a (1, 3, 512, 512) float tensor in [0, 1]."""
    return torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255.0


@pytest.fixture(scope="session")
def astronaut_small(astronaut: torch.Tensor) -> torch.Tensor:
    """The astronaut at 128x128."""
    return F.interpolate(astronaut, size=(128, 128), mode="area")
