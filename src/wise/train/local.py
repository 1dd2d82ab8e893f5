"""Local parameter prediction trained as a conditional GAN through the effect (WISE Eq. 2),
and image-to-image translation with a post-processing CNN after it (Sec. 5.2).

The generator is ``G(I) = O(I, P_L(I))``: the U-Net :class:`wise.ppn.LocalPPN` paints the
parameter masks of photo ``I`` and the differentiable effect ``O`` renders ``I`` with them;
with a post-processing network ``N`` it is ``N(O(I, P_L(I)))``
(:class:`wise.ppn.translation.Translator`, whose parts may be left out for the ablation).
Its loss is ``α·L_GAN + β·‖G(I) − T‖₁ + γ·TV(P_L(I))`` against the target ``T``, with the
conditional PatchGAN of pix2pix as the discriminator; ``α = 0`` trains without it. An optional
``δ·‖P_L(I) − p₀‖₁`` keeps the masks at the start preset ``p₀`` where departing from it does not
bring the result closer to the target (flat areas, where many parameters change nothing).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import lightning as L
import torch
from torch.utils.data import DataLoader

from wise.filters.smoothing import annealed_temperature, smoothed_steps, softened_gradients
from wise.ppn.choices import NO_POST
from wise.ppn.postprocess import DEFAULT_WIDTH
from wise.ppn.translation import Stages, build_translator, translator_options
from wise.train.discriminator import PatchDiscriminator, adversarial_loss
from wise.train.losses import total_variation
from wise.train.pairs import PairDataset
from wise.train.schedules import scheduled

ADAM_BETAS = (0.5, 0.999)
"""pix2pix's Adam settings (with its learning rate 2e-4)."""
ANNEALED_SHARE = 0.5
"""Share of a run that keeps the effect's steps sharp at its end."""


class LocalGAN(L.LightningModule):
    """The generator (local PPN, effect, post-processing CNN) and (with ``gan_weight`` > 0)
    the discriminator.

    ``start`` is the ``(P,)`` normalized parameters the untrained network paints everywhere
    (e.g. the preset the targets depart from), and the preset the effect runs at with
    ``ppn_kind="preset"``. ``post`` names the CNN after the effect (``resnet``, ``unet`` or
    ``none``), ``post_width`` its first layer's channels and ``dropout`` pix2pix's dropout in
    it; ``effect="none"`` trains the CNN alone. ``anneal`` > 0 smooths the effect's steps in
    the training steps, from that temperature to 0 over the first half of the run;
    ``soft_gradients`` > 0 renders them exactly but passes surrogate gradients through them
    (:func:`wise.filters.smoothing.softened_gradients`).
    """

    def __init__(
        self,
        effect: str,
        start: list[float],
        network: Mapping[str, int],
        gan_loss: str = "lsgan",
        gan_weight: float = 1.0,
        l1_weight: float = 100.0,
        tv_weight: float = 1.0,
        preset_weight: float = 0.0,
        lr: float = 2e-4,
        lr_schedule: str = "linear",
        discriminator_width: int = 64,
        anneal: float = 0.0,
        soft_gradients: float = 0.0,
        post: str = NO_POST,
        post_width: int = DEFAULT_WIDTH,
        ppn_kind: str = "local",
        dropout: bool = False,
    ) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.automatic_optimization = False
        options = translator_options(ppn_kind, post, post_width, dropout, **dict(network))
        self.network = build_translator(effect, options, torch.tensor(start, dtype=torch.float32))
        self.effect = self.network.effect
        self.discriminator = PatchDiscriminator(discriminator_width) if gan_weight > 0 else None
        self.gan_loss, self.lr, self.lr_schedule, self.anneal = gan_loss, lr, lr_schedule, anneal
        self.soft_gradients = soft_gradients
        self.weights = {"gan": gan_weight, "l1": l1_weight, "tv": tv_weight, "preset": preset_weight}

    @property
    def generator(self) -> torch.nn.Module | None:
        """The local PPN (None when the effect runs at its preset or there is no effect)."""
        return self.network.ppn

    def forward(self, photo: torch.Tensor) -> torch.Tensor:
        return self.network(photo)

    def generate(self, batch: Mapping[str, Any]) -> Stages:
        """The masks, effect stage and final image of the batch's photos."""
        photo = batch["photo"]
        masks = self.network.masks(photo)
        masks = masks.float() if masks is not None else None
        scale = float(batch["scale"][0]) if torch.is_tensor(batch["scale"]) else float(batch["scale"])
        with torch.autocast(self.device.type, enabled=False):
            stage = self._stage(photo.float(), masks, scale, batch["origin"])
        return Stages(masks, stage, self.network.draw(stage))

    def _stage(
        self, photo: torch.Tensor, masks: torch.Tensor | None, scale: float, origins: torch.Tensor
    ) -> torch.Tensor:
        """The effect stage in full precision (the effect's steps need it; the CNNs do not)."""
        origins = origins.reshape(-1, 2)
        position_dependent = self.effect is not None and self.effect.position_dependent
        if not position_dependent or bool((origins == origins[:1]).all()):
            return self.network.render_stage(photo, masks, scale, (int(origins[0, 0]), int(origins[0, 1])))
        # Textures fixed to the paper: every crop where it lies.
        return torch.cat(
            [
                self.network.render_stage(photo[i : i + 1], masks[i : i + 1], scale, (int(y), int(x)))
                for i, (y, x) in enumerate(origins.tolist())
            ]
        )

    def temperature(self) -> float:
        total = self.trainer.estimated_stepping_batches if self._trainer is not None else 0
        if self.anneal <= 0.0 or not total or total == float("inf"):
            return 0.0
        return annealed_temperature(self.anneal, self.global_step / total, sharp_share=ANNEALED_SHARE)

    def training_step(self, batch: Mapping[str, Any], batch_index: int) -> None:
        optimizers = self.optimizers()
        generator_optimizer, discriminator_optimizer = (
            optimizers if isinstance(optimizers, list) else (optimizers, None)
        )
        photo, target = batch["photo"], batch["target"]
        with smoothed_steps(self.temperature()), softened_gradients(self.soft_gradients):
            masks, _, made = self.generate(batch)
            if self.discriminator is not None and discriminator_optimizer is not None:
                real = self.discriminator(photo, target)
                fake = self.discriminator(photo, made.detach())
                loss_d = 0.5 * (
                    adversarial_loss(self.gan_loss, real, True) + adversarial_loss(self.gan_loss, fake, False)
                )
                discriminator_optimizer.zero_grad(set_to_none=True)
                self.manual_backward(loss_d)
                discriminator_optimizer.step()
                self.log("train_d_loss", loss_d, on_step=True, on_epoch=False)
            l1 = (made - target).abs().mean()
            tv = self._mask_variation(masks)
            loss = self.weights["l1"] * l1 + self.weights["tv"] * tv
            if self.weights["preset"] > 0 and masks is not None and masks.dim() == 4:
                departure = (masks - self.network.start.view(1, -1, 1, 1)).abs().mean()
                loss = loss + self.weights["preset"] * departure
                self.log("train_departure", departure, on_step=True, on_epoch=False)
            if self.discriminator is not None:
                self.discriminator.requires_grad_(False)
                gan = adversarial_loss(self.gan_loss, self.discriminator(photo, made), True)
                self.discriminator.requires_grad_(True)
                loss = loss + self.weights["gan"] * gan
                self.log("train_gan", gan, on_step=True, on_epoch=False)
            generator_optimizer.zero_grad(set_to_none=True)
            self.manual_backward(loss)
            generator_optimizer.step()
        for schedule in self._schedules():
            schedule.step()
        self.log("train_loss", loss, prog_bar=True, on_step=True, on_epoch=False)
        self.log("train_l1", l1, on_step=True, on_epoch=False)
        self.log("train_tv", tv, on_step=True, on_epoch=False)

    @staticmethod
    def _mask_variation(masks: torch.Tensor | None) -> torch.Tensor:
        """TV of painted masks; 0 for a preset or no effect (nothing painted)."""
        if masks is None or masks.dim() != 4:
            return torch.zeros(())
        return total_variation(masks)

    def _schedules(self) -> list:
        schedules = self.lr_schedulers()
        if schedules is None:
            return []
        return schedules if isinstance(schedules, list) else [schedules]

    def validation_step(self, batch: Mapping[str, Any], batch_index: int) -> None:
        masks, _, made = self.generate(batch)
        size = batch["target"].shape[0]
        self.log("val_l1", (made - batch["target"]).abs().mean(), prog_bar=True, sync_dist=True, batch_size=size)
        self.log("val_tv", self._mask_variation(masks), sync_dist=True, batch_size=size)

    def configure_optimizers(self) -> Any:
        total = self.trainer.estimated_stepping_batches if self._trainer is not None else 0
        modules = [self.network] + ([self.discriminator] if self.discriminator is not None else [])
        optimizers = [torch.optim.Adam(m.parameters(), lr=self.lr, betas=ADAM_BETAS) for m in modules]
        schedules = [scheduled(o, self.lr_schedule, total) for o in optimizers]
        if schedules[0] is None:
            return optimizers
        return optimizers, [{"scheduler": s, "interval": "step"} for s in schedules]


class PairData(L.LightningDataModule):
    """Training pairs (jittered) and test pairs (whole, one at a time) for :class:`LocalGAN`.
    Each epoch draws other crops and flips (:meth:`PairDataset.set_epoch`)."""

    def __init__(self, train: PairDataset, test: PairDataset, batch: int, workers: int = 0) -> None:
        super().__init__()
        self.train_set, self.test_set, self.batch, self.workers = train, test, batch, workers

    def train_dataloader(self) -> DataLoader:
        epoch = self.trainer.current_epoch if self.trainer is not None else 0
        self.train_set.set_epoch(epoch)
        return DataLoader(
            self.train_set,
            batch_size=self.batch,
            shuffle=True,
            drop_last=len(self.train_set) >= self.batch,
            num_workers=self.workers,
            generator=torch.Generator().manual_seed(epoch),
        )

    def val_dataloader(self) -> DataLoader:
        return DataLoader(self.test_set, batch_size=1)
