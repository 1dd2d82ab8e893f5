"""The parametric optimizations' Adam: PyTorch's update, without its import of the compiler stack."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

from wise.optimize.adam import Adam


@pytest.mark.parametrize("shape", [(1, 12), (1, 5, 8, 8)])
def test_the_steps_are_torchs_adam(shape: tuple[int, ...]) -> None:
    generator = torch.Generator().manual_seed(0)
    start = torch.rand(shape, generator=generator)
    ours, theirs = start.clone().requires_grad_(True), start.clone().requires_grad_(True)
    mine, reference = Adam([ours], lr=0.05), torch.optim.Adam([theirs], lr=0.05)
    for step in range(30):
        gradient = torch.randn(shape, generator=generator) * (10.0 if step % 7 == 0 else 0.1)
        for optimizer, tensor in ((mine, ours), (reference, theirs)):
            optimizer.zero_grad(set_to_none=True)
            (tensor * gradient).sum().backward()
            optimizer.step()
        if step == 10:  # a schedule lowers the rate in between
            mine.param_groups[0]["lr"] = reference.param_groups[0]["lr"] = 0.01
    assert torch.equal(ours, theirs), "the same operations in the same order: the same bits"
    assert not torch.equal(ours, start)


def test_a_tensor_without_gradient_stays_and_bad_settings_are_refused() -> None:
    still = torch.ones(3, requires_grad=True)
    optimizer = Adam([still], lr=0.1)
    optimizer.step()
    assert torch.equal(still, torch.ones(3))
    # a tensor that has a gradient only from the fourth step on counts its steps from there, as in PyTorch
    ours = [torch.ones(2, requires_grad=True) for _ in range(2)]
    theirs = [torch.ones(2, requires_grad=True) for _ in range(2)]
    mine, reference = Adam(ours, lr=0.1), torch.optim.Adam(theirs, lr=0.1)
    for step in range(8):
        for optimizer, (first, late) in ((mine, ours), (reference, theirs)):
            optimizer.zero_grad()
            loss = (first * 3.0).sum() + ((late**2).sum() if step >= 3 else 0.0)
            loss.backward()
            optimizer.step()
    assert torch.equal(ours[0], theirs[0]) and torch.equal(ours[1], theirs[1])
    assert not torch.equal(ours[1], torch.ones(2))
    with pytest.raises(ValueError, match="lr"):
        Adam([still], lr=-1.0)
    with pytest.raises(ValueError, match="at least one"):
        Adam([], lr=0.1)


def test_a_refinement_does_not_import_the_compiler_stack() -> None:
    """In a fresh process, as ``wise predict`` runs: the import took 0.7 s of its budget."""
    script = (
        "import sys, torch, wise\n"
        "from wise.optimize.refine import refine\n"
        "effect = wise.effects.create('xdog')\n"
        "photo = torch.rand(1, 3, 64, 64)\n"
        "refine(effect, photo, photo, effect.default_params()[None], budget=3.0, max_iterations=3)\n"
        "print('torch._dynamo' in sys.modules)\n"
    )
    printed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert printed.returncode == 0, printed.stderr[-2000:]
    assert printed.stdout.strip() == "False"
