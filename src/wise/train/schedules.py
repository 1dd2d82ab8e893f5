"""Learning-rate schedules of the training commands, as factors of the learning rate."""

from __future__ import annotations

import math

import torch

from wise.errors import WiseError
from wise.train.choices import LR_SCHEDULES

COSINE_FLOOR = 0.05
"""The cosine schedule's learning rate at the end of the run, as a share of ``lr``."""
LINEAR_DECAY_SHARE = 0.5
"""The linear schedule keeps ``lr`` for the first half of the run and then falls to 0 (pix2pix:
100 epochs at the rate, 100 decaying)."""


def lr_factor(schedule: str, progress: float) -> float:
    """The share of the learning rate at ``progress`` (0 to 1) of a run."""
    progress = min(1.0, max(0.0, progress))
    if schedule == "constant":
        return 1.0
    if schedule == "cosine":
        return COSINE_FLOOR + (1.0 - COSINE_FLOOR) * 0.5 * (1.0 + math.cos(math.pi * progress))
    if schedule == "linear":
        decay_start = 1.0 - LINEAR_DECAY_SHARE
        return 1.0 if progress <= decay_start else (1.0 - progress) / LINEAR_DECAY_SHARE
    raise WiseError(f"unknown learning-rate schedule {schedule!r}; use one of {', '.join(LR_SCHEDULES)}")


def scheduled(
    optimizer: torch.optim.Optimizer, schedule: str, total_steps: float
) -> torch.optim.lr_scheduler.LambdaLR | None:
    """A per-step scheduler of ``optimizer`` over ``total_steps`` steps (None when the rate
    stays constant or the length of the run is not known)."""
    if schedule == "constant" or not total_steps or total_steps == float("inf"):
        return None
    return torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: lr_factor(schedule, step / total_steps))
