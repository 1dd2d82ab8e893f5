"""Adam (Kingma and Ba, "Adam: A Method for Stochastic Optimization", ICLR 2015) for the few
tensors of a parametric optimization: global parameters ``(1, P)`` or their masks.

The same update as ``torch.optim.Adam`` with its defaults, step for step. PyTorch's optimizers
import its compiler stack the first time one is made in a process: 0.7 s of ``wise predict``'s
refinement budget (8 s) on a 2-core CPU, paid by every call of the command.
"""

from __future__ import annotations

import math
from typing import Any, Iterable

import torch


class Adam:
    """``Adam(tensors, lr)``: ``zero_grad()``, then ``step()`` after each backward pass. The
    learning rate is ``param_groups[0]["lr"]``, where schedules set it, as on PyTorch's
    optimizers."""

    def __init__(
        self, params: Iterable[torch.Tensor], lr: float, betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8
    ) -> None:
        tensors = list(params)
        if not tensors:
            raise ValueError("Adam needs at least one tensor to optimize")
        if not (lr >= 0.0 and eps >= 0.0 and 0.0 <= betas[0] < 1.0 and 0.0 <= betas[1] < 1.0):
            raise ValueError(f"invalid Adam settings: lr {lr}, betas {betas}, eps {eps}")
        self.param_groups: list[dict[str, Any]] = [{"params": tensors, "lr": lr}]
        self.betas, self.eps = betas, eps
        self._steps = [0] * len(tensors)  # per tensor, counting only the steps it had a gradient in
        self._first_moments = [torch.zeros_like(t, memory_format=torch.preserve_format) for t in tensors]
        self._second_moments = [torch.zeros_like(t, memory_format=torch.preserve_format) for t in tensors]

    def zero_grad(self, set_to_none: bool = True) -> None:
        for tensor in self.param_groups[0]["params"]:
            if set_to_none:
                tensor.grad = None
            elif tensor.grad is not None:
                tensor.grad.zero_()

    @torch.no_grad()
    def step(self) -> None:
        beta1, beta2 = self.betas
        group = self.param_groups[0]
        moments = zip(self._first_moments, self._second_moments)
        for index, (tensor, (first, second)) in enumerate(zip(group["params"], moments)):
            if tensor.grad is None:
                continue
            self._steps[index] += 1
            steps = self._steps[index]
            step_size = group["lr"] / (1.0 - beta1**steps)
            second_correction = math.sqrt(1.0 - beta2**steps)
            gradient = tensor.grad
            first.lerp_(gradient, 1.0 - beta1)
            second.mul_(beta2).addcmul_(gradient, gradient, value=1.0 - beta2)
            denominator = (second.sqrt() / second_correction).add_(self.eps)
            tensor.addcdiv_(first, denominator, value=-step_size)
