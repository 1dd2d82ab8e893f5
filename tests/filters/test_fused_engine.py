"""The Dr.Jit engine: finding LLVM, and the PyTorch path with one notice line without it."""

import os
import subprocess
import sys

import pytest

from wise.filters.fused._drjit import LIBLLVM_VARIABLE, MISSING_LLVM_NOTICE, find_libllvm, llvm_backend

SCRIPT = """
import torch
from tests.filters.paths import kernels
from wise.filters.bilateral import bilateral_pass
image = torch.rand(1, 3, 24, 24, generator=torch.Generator().manual_seed(0), requires_grad=True)
direction = torch.zeros(1, 2, 24, 24)
direction[:, 0] = 1.0
fused = bilateral_pass(image, direction, 2.0, 0.2, scale=1.0)
fused.sum().backward()
with kernels("torch"):
    reference = bilateral_pass(image, direction, 2.0, 0.2, scale=1.0)
bilateral_pass(image, direction, 2.0, 0.2, scale=1.0)
print(float((fused - reference).abs().max().detach()))
"""


def _run_without_llvm(library: str) -> subprocess.CompletedProcess:
    env = {**os.environ, LIBLLVM_VARIABLE: library, "PYTHONPATH": os.getcwd()}
    return subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=120)


def test_without_llvm_the_filters_run_on_the_pytorch_path_with_one_notice(tmp_path) -> None:
    done = _run_without_llvm(str(tmp_path / "libLLVM.so"))
    assert done.returncode == 0, done.stderr
    assert float(done.stdout.strip()) == 0.0  # the same path as the reference
    assert done.stderr.strip().splitlines() == [f"wise: {MISSING_LLVM_NOTICE}"]


def test_an_llvm_too_old_is_named_in_the_notice() -> None:
    old = [
        os.path.join(folder, name)
        for folder in ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu")
        if os.path.isdir(folder)
        for name in os.listdir(folder)
        if name.startswith(("libLLVM-14", "libLLVM-13"))
    ]
    if not old:
        pytest.skip("no LLVM older than 15 on this machine")
    done = _run_without_llvm(old[0])
    assert done.returncode == 0, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"wise: {MISSING_LLVM_NOTICE}") and "too old" in line


def test_the_newest_llvm_is_chosen(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("libLLVM-14.so.1", "libLLVM-19.so.1", "libLLVM-15.so", "libLLVM.so.17.0"):
        (tmp_path / name).write_bytes(b"")
    monkeypatch.setattr("wise.filters.fused._drjit.LIBRARY_FOLDERS", (str(tmp_path),))
    assert os.path.basename(find_libllvm()) == "libLLVM-19.so.1"
    monkeypatch.setattr("wise.filters.fused._drjit.LIBRARY_FOLDERS", (str(tmp_path / "none"),))
    assert find_libllvm() is None


@pytest.mark.skipif(not llvm_backend(), reason="Dr.Jit's CPU backend does not start here")
def test_the_engine_check_reports_the_library() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "wise.filters.fused.llvm"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0
    assert "(works)" in done.stdout
    assert "compiled for: " in done.stdout and "lanes, gathers as " in done.stdout


@pytest.mark.skipif(not llvm_backend(), reason="Dr.Jit's CPU backend does not start here")
def test_a_new_picture_size_or_tile_origin_compiles_no_new_kernel() -> None:
    import drjit as dr
    import torch

    from wise.filters.bilateral import bilateral_pass
    from wise.filters.color import adjust_color, rgb_to_lab
    from wise.filters.noise import paper_texture

    def run(height: int, width: int, origin: tuple[int, int]) -> list[dict]:
        image = torch.rand(1, 3, height, width)
        direction = torch.zeros(1, 2, height, width)
        direction[:, 1] = 1.0
        dr.kernel_history()  # clears it
        bilateral_pass(rgb_to_lab(adjust_color(image, brightness=0.1, saturation=1.2)), direction, 2.0, 4.0)
        paper_texture(image, origin=origin, scale=0.9)
        return [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        run(31, 40, (0, 0))
        later = run(47, 29, (64, 128))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert later and all(kernel["cache_hit"] for kernel in later)


def test_the_kernels_take_cpu_tensors_of_float32_and_float64_only() -> None:
    import torch

    from wise.filters import fused

    # other devices (CUDA included) and dtypes run on the PyTorch path
    assert not fused.enabled(torch.zeros(1, device="meta"))
    assert not fused.enabled(torch.zeros(1, dtype=torch.float16))
    assert not fused.enabled(torch.zeros(1), torch.zeros(1, dtype=torch.float64))
    assert fused.enabled(torch.zeros(1, dtype=torch.float64)) == llvm_backend()


def test_a_library_named_older_than_15_is_not_loaded() -> None:
    from wise.filters.fused._drjit import _too_old

    assert _too_old("/usr/lib/x86_64-linux-gnu/libLLVM-14.so.1") and _too_old("/usr/lib/libLLVM.so.13.0")
    assert not _too_old("/usr/lib/x86_64-linux-gnu/libLLVM-15.so") and not _too_old("/usr/lib/libLLVM.so.19.1")
    assert not _too_old("/opt/llvm/lib/libLLVM.dylib")  # no version in the name: Dr.Jit is asked


def test_hardware_gathers_are_chosen_for_measured_cpus_with_avx2_only() -> None:
    from wise.filters.fused._target import Target, wants_hardware_gathers

    assert wants_hardware_gathers(Target("znver3", "+avx,+avx2,+fma", 8))
    assert not wants_hardware_gathers(Target("znver3", "+avx,-avx2", 8))
    assert not wants_hardware_gathers(Target("znver3", "+avx2,+fast-gather", 8))  # already
    assert not wants_hardware_gathers(Target("znver4", "+avx2,+avx512f", 16))  # LLVM's own choice
    assert not wants_hardware_gathers(Target("znver2", "+avx2", 8))  # not measured
    assert Target("skylake-avx512", "+avx2,+avx512f", 16).hardware_gathers
    assert not Target("znver3", "+avx2,-fast-gather", 8).hardware_gathers


@pytest.mark.skipif(not llvm_backend(), reason="Dr.Jit's CPU backend does not start here")
def test_hardware_gathers_give_the_same_bits_as_scalar_loads() -> None:
    import torch

    from wise.filters.bilateral import bilateral_pass
    from wise.filters.fused._target import current, set_hardware_gathers
    from wise.filters.kuwahara import anisotropic_kuwahara
    from wise.filters.structure import structure_tensor

    generator = torch.Generator().manual_seed(3)
    image = torch.rand(1, 3, 40, 52, generator=generator, requires_grad=True)
    angle = torch.rand(1, 1, 40, 52, generator=generator) * 6.3
    direction = torch.cat((angle.cos(), angle.sin()), dim=1)

    def outputs() -> list[torch.Tensor]:
        smoothed = bilateral_pass(image, direction, 3.0, 0.2, scale=1.0)
        washed = anisotropic_kuwahara(image, structure_tensor(image.detach()), 3.0, scale=1.0)
        (gradient,) = torch.autograd.grad((smoothed.sum() + washed.square().sum()), image)
        return [smoothed.detach(), washed.detach(), gradient]

    chosen = current().hardware_gathers
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # scattered gradients are summed in the threads' order
    try:
        set_hardware_gathers(True)
        assert current().hardware_gathers
        hardware = outputs()
        set_hardware_gathers(False)
        assert not current().hardware_gathers or "+avx512f" in current().features
        scalar = outputs()
    finally:
        set_hardware_gathers(chosen)
        torch.set_num_threads(threads)
    for a, b in zip(hardware, scalar):
        assert torch.equal(a, b)
