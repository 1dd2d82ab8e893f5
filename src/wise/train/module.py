"""Lightning modules of global parameter prediction: the network with its loss, and the data."""

from __future__ import annotations

from typing import Any

import lightning as L
import torch
from torch.utils.data import DataLoader

from wise import effects, ppn
from wise.effects.base import window_scale
from wise.filters.smoothing import annealed_temperature, smoothed_steps, softened_gradients
from wise.train.data import ExampleDataset
from wise.train.losses import prediction_loss
from wise.train.sampler import GlobalBatchSampler
from wise.train.schedules import scheduled

ANNEALED_SHARE = 0.5
"""Share of a training run that keeps the effect's steps sharp at its end."""


class GlobalPPN(L.LightningModule):
    """A global parameter prediction network trained with one of the losses of
    :data:`wise.train.losses.LOSSES`.

    Image-space losses compare the effect rendered with the predicted parameters against the
    example's ``target``, the effect rendered with the true ones from the same photo at the
    network's size (the whole picture ``size`` pixels) when the example was made, so the true
    parameters have zero loss up to the target's 8-bit steps. The effect always runs in
    float32 (outside mixed precision).

    ``anneal`` > 0 smooths the effect's steps in the training steps of image-space losses,
    from that temperature down to 0 over the first half of the run (graduated non-convexity,
    :mod:`wise.filters.smoothing`); validation always measures the look itself.
    ``soft_gradients`` > 0 keeps the look but passes surrogate gradients through the steps.
    ``param_weight`` > 0 adds that much of the parameter L1 to an image-space loss: where several
    parameters make nearly the same look, it tells the network which of them the example had.
    """

    def __init__(
        self,
        effect: str,
        architecture: str,
        loss: str,
        lr: float,
        size: int,
        anneal: float = 0.0,
        lr_schedule: str = "constant",
        soft_gradients: float = 0.0,
        param_weight: float = 0.0,
    ) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.anneal, self.lr_schedule, self.soft_gradients = anneal, lr_schedule, soft_gradients
        self.param_weight = param_weight
        self.effect = effects.create(effect).requires_grad_(False)
        self.network = ppn.create(architecture, len(self.effect.param_specs))
        self.loss_kind, self.lr = loss, lr
        self.scale = window_scale(size, size)

    def forward(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        return self.network(photo, example)

    def _losses(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        photo, example, truth = batch["photo"], batch["example"], batch["params"]
        predicted = self.network(photo, example).float()
        with torch.autocast(self.device.type, enabled=False):
            if self.loss_kind.startswith("image"):
                target = batch["target"]
                loss = prediction_loss(self.loss_kind, predicted, truth, self.effect, photo, target, scale=self.scale)
                if self.param_weight:
                    loss = loss + self.param_weight * prediction_loss("param-l1", predicted, truth)
            else:
                loss = prediction_loss(self.loss_kind, predicted, truth)
        return loss, (predicted.detach() - truth).abs().mean()

    def temperature(self) -> float:
        """The step temperature of the present training step."""
        total = self.trainer.estimated_stepping_batches if self._trainer is not None else 0
        if self.anneal <= 0.0 or not total or total == float("inf"):
            return 0.0
        return annealed_temperature(self.anneal, self.global_step / total, sharp_share=ANNEALED_SHARE)

    def training_step(self, batch: dict[str, torch.Tensor], batch_index: int) -> torch.Tensor:
        with smoothed_steps(self.temperature()), softened_gradients(self.soft_gradients):
            loss, param_l1 = self._losses(batch)
        self.log("train_loss", loss, prog_bar=True, on_step=True, on_epoch=False)
        self.log("train_param_l1", param_l1, on_step=True, on_epoch=False)
        return loss

    def validation_step(self, batch: dict[str, torch.Tensor], batch_index: int) -> None:
        loss, param_l1 = self._losses(batch)
        size = batch["photo"].shape[0]
        self.log("val_loss", loss, prog_bar=True, sync_dist=True, batch_size=size)
        self.log("val_param_l1", param_l1, sync_dist=True, batch_size=size)

    def configure_optimizers(self) -> Any:
        optimizer = torch.optim.Adam(self.network.parameters(), lr=self.lr)
        total = self.trainer.estimated_stepping_batches if self._trainer is not None else 0
        schedule = scheduled(optimizer, self.lr_schedule, total)
        if schedule is None:
            return optimizer
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": schedule, "interval": "step"}}


class ExampleData(L.LightningDataModule):
    """Training and validation examples; each process takes its share of every global batch
    (:class:`GlobalBatchSampler`), so results do not depend on the number of processes.

    ``workers`` > 0 renders the batches of a fresh training stream in that many worker
    processes while the steps run (each example is the same wherever it is rendered); a fixed
    set and the validation set are rendered in the training process, which keeps them.
    """

    def __init__(
        self, train: ExampleDataset, validation: ExampleDataset, batch: int, seed: int, workers: int = 0
    ) -> None:
        super().__init__()
        self.train_set, self.validation_set, self.batch, self.seed = train, validation, batch, seed
        self.workers = workers

    def _loader(self, dataset: ExampleDataset, seed: int, workers: int = 0) -> DataLoader:
        world = self.trainer.world_size if self.trainer is not None else 1
        rank = self.trainer.global_rank if self.trainer is not None else 0
        batches = min(self.batch, len(dataset) // world)
        sampler = GlobalBatchSampler(len(dataset), batches, world, rank, seed, fresh=dataset.fresh)
        if workers == 0:
            return DataLoader(dataset, batch_sampler=sampler)
        return DataLoader(dataset, batch_sampler=sampler, num_workers=workers, persistent_workers=True)

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.train_set, self.seed, self.workers if self.train_set.fresh else 0)

    def val_dataloader(self) -> DataLoader:
        return self._loader(self.validation_set, self.seed + 1)
