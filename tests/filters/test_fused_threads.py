"""The fused kernels leave PyTorch's thread count as the caller set it."""

import pytest
import torch

from tests.filters.paths import kernels
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
