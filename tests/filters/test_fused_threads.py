"""The fused kernels leave PyTorch's thread count as the caller set it, and Ctrl-C for after them."""

import os
import signal
import time

import pytest
import torch

from tests.filters.paths import kernels
from wise.filters.fused import kernel_threads
from wise.filters.gaussian import gaussian_blur


@pytest.mark.parametrize("threads", [1, 2])
def test_a_kernel_leaves_pytorchs_thread_count_as_it_was(threads: int) -> None:
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with kernels("fused"):
            gaussian_blur(torch.rand(1, 1, 16, 16), 1.0, scale=1.0)
        assert torch.get_num_threads() == threads
    finally:
        torch.set_num_threads(before)


def test_ctrl_c_during_a_kernel_is_delivered_when_it_returns() -> None:
    reached_end = False
    with pytest.raises(KeyboardInterrupt):
        with kernel_threads():
            os.kill(os.getpid(), signal.SIGINT)  # as if it landed in a callback of the compiler
            time.sleep(0.05)
            reached_end = True
    assert reached_end
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
