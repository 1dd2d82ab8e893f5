"""The fused kernels run on PyTorch's thread count, leave it as it was, and serve several threads."""

from concurrent.futures import ThreadPoolExecutor

import pytest
import torch

from tests.filters.paths import kernels, needs_kernels
from wise.filters.bilateral import bilateral_pass
from wise.filters.gaussian import gaussian_blur

pytestmark = needs_kernels


@pytest.mark.parametrize("threads", [1, 2])
def test_a_kernel_runs_on_pytorchs_thread_count_and_leaves_it(threads: int) -> None:
    import drjit as dr

    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with kernels("fused"):
            gaussian_blur(torch.rand(1, 1, 16, 16), torch.full((1, 1, 16, 16), 1.0), scale=1.0)  # a Dr.Jit kernel
        assert torch.get_num_threads() == threads
        assert dr.thread_count() == threads
    finally:
        torch.set_num_threads(before)


def test_threads_rendering_at_once_get_their_own_results() -> None:
    # the editor's server renders in threads: kernels are traced and run one at a time
    generator = torch.Generator().manual_seed(0)
    images = [torch.rand(1, 3, 40 + 8 * k, 48, generator=generator) for k in range(6)]

    def render(image: torch.Tensor) -> torch.Tensor:
        direction = torch.zeros(1, 2, *image.shape[-2:])
        direction[:, 0] = 1.0
        return bilateral_pass(gaussian_blur(image, 1.5, scale=1.0), direction, 2.0, 0.3, scale=1.0)

    with kernels("fused"):
        alone = [render(image) for image in images]
        with ThreadPoolExecutor(max_workers=3) as pool:
            together = list(pool.map(render, images * 3))
    for k, result in enumerate(together):
        assert torch.equal(result, alone[k % len(images)])
