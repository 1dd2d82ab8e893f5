"""PyTorch's OpenMP threads wait for work without spinning, when ``wise`` is imported before ``torch``.

After each parallel operation, GNU OpenMP's threads keep spinning for a while in case more work
comes. The Dr.Jit kernels run on threads of their own, and on a machine with few cores the
spinning threads hold the cores the next kernel needs: on two cores a 64-pixel training window of
oil paint took 54 ms instead of 26 ms, XDoG 27 ms instead of 10 ms. OpenMP reads its waiting
policy once, when PyTorch loads it, so the policy is set in the environment before ``torch`` is
first imported, unless the user chose one (``OMP_WAIT_POLICY``).
"""

from __future__ import annotations

import os
import sys

WAIT_POLICY_VARIABLE = "OMP_WAIT_POLICY"


def prefer_passive_waiting() -> bool:
    """Set OpenMP's waiting policy to passive for this process and its children where PyTorch is
    not loaded yet and no policy is set; whether it was set."""
    if "torch" in sys.modules or WAIT_POLICY_VARIABLE in os.environ:
        return False
    os.environ[WAIT_POLICY_VARIABLE] = "PASSIVE"
    return True
