"""Batches that do not depend on the number of processes.

Each epoch is one seeded permutation of the data set, cut into global batches of
``batch * world`` examples; process ``rank`` takes its contiguous share of every global
batch. Averaged over the processes (DDP), a step's gradient is then the gradient of the
same global batch a single process would see with ``batch * world`` examples.
"""

from __future__ import annotations

from collections.abc import Iterator

import torch
from torch.utils.data import Sampler


class GlobalBatchSampler(Sampler[list[int]]):
    """Index lists of ``batch`` examples for process ``rank`` of ``world``; incomplete global
    batches at the end of an epoch are dropped, so every process takes the same number of steps.

    ``fresh``: epoch ``e`` takes the indices ``e * length`` to ``(e + 1) * length - 1`` (a
    data set that draws a new example for every index), so no example is seen twice."""

    def __init__(
        self, length: int, batch: int, world: int = 1, rank: int = 0, seed: int = 0, fresh: bool = False
    ) -> None:
        if batch < 1 or world < 1 or not 0 <= rank < world:
            raise ValueError(f"invalid batch {batch}, world {world} or rank {rank}")
        if length < batch * world:
            raise ValueError(f"{length} examples make no global batch of {batch * world}")
        self.length, self.batch, self.world, self.rank, self.seed = length, batch, world, rank, seed
        self.fresh, self.epoch = fresh, 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return self.length // (self.batch * self.world)

    def __iter__(self) -> Iterator[list[int]]:
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch)
        order = torch.randperm(self.length, generator=generator).tolist()
        if self.fresh:
            order = [index + self.epoch * self.length for index in order]
        step = self.batch * self.world
        for start in range(0, len(self) * step, step):
            first = start + self.rank * self.batch
            yield order[first : first + self.batch]
