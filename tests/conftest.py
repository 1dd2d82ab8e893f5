import os
import signal
import subprocess
import sys

import pytest
import torch
import torch.nn.functional as F
from skimage import data

from wise.filters import fused


def pytest_sessionstart(session: pytest.Session) -> None:
    """With a cold kernel cache (a fresh clone), the fused kernels are compiled before the tests,
    so that no timed test waits for a compilation."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        # started in the background by a shell without job control: the Ctrl-C tests need it back
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if fused.requested() != "fused":
        return
    if os.environ.get("PYTEST_XDIST_WORKER"):  # the controller compiled before it started the workers
        return
    if not fused.warm_marker().exists():
        subprocess.run([sys.executable, "-m", "wise.effects.compile", "float32", "float64"], check=True)


@pytest.fixture(scope="session")
def astronaut() -> torch.Tensor:
    """``skimage.data.astronaut()`` as a (1, 3, 512, 512) float tensor in [0, 1]."""
    return torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255.0


@pytest.fixture(scope="session")
def astronaut_small(astronaut: torch.Tensor) -> torch.Tensor:
    """The astronaut at 128x128."""
    return F.interpolate(astronaut, size=(128, 128), mode="area")


@pytest.fixture
def brief_readings(monkeypatch: pytest.MonkeyPatch) -> None:
    """One iteration for each candidate's brief descent and for the cartoon's colour fit, where a
    test runs a command through the readings but checks none of what they read (the users' twenty
    and two hundred iterations take about 20 s even on a 32-pixel picture)."""
    from wise.optimize import inversion

    monkeypatch.setattr(inversion, "SEARCH_ITERATIONS", 1)
    monkeypatch.setattr(inversion, "FIT_ITERATIONS", 1)
