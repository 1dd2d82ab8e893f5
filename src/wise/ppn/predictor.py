"""Trained models ready to predict: ``Predictor(model, effect)(photo, example)`` (global
parameters) and ``LocalPredictor(model, effect)(photo)`` (parameter masks).

They resize the images to the model's working size before the network's one forward pass;
the commands that predict (``wise predict``, the benchmarks) share them.
"""

from __future__ import annotations

import os

import torch
import torch.nn.functional as F

from wise import effects
from wise.effects.base import window_scale
from wise.ppn.modelfile import BUILTIN_PREFIX, load_model, resolve_model
from wise.ppn.translation import NO_EFFECT, Stages, Translator


def at_short_side(image: torch.Tensor, short_side: int) -> torch.Tensor:
    """``image`` resized so that its short side is ``short_side`` (area filter when reducing)."""
    height, width = image.shape[-2:]
    factor = short_side / min(height, width)
    if factor == 1.0:
        return image
    shape = (max(1, round(height * factor)), max(1, round(width * factor)))
    return F.interpolate(image, size=shape, mode="area" if factor < 1 else "bilinear").clamp(0.0, 1.0)


class Predictor:
    """A loaded model: ``predictor(photo, example)`` -> normalized global parameters ``(B, P)``."""

    def __init__(self, model: str | os.PathLike[str] | None, effect: str, device: torch.device | str = "cpu") -> None:
        path = resolve_model(model, effect, "global")
        self.network, self.info = load_model(path, effect, "global")
        self.network.to(device)
        self.device = torch.device(device)
        self.effect = effects.create(self.info.effect)
        if model is None:
            self.info.source = f"builtin:{effect}"
        elif str(model).startswith(BUILTIN_PREFIX):
            self.info.source = str(model)

    @torch.no_grad()
    def __call__(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        size = self.info.size
        small_photo = at_short_side(photo, size).to(self.device)
        small_example = at_short_side(example, size).to(self.device)
        predicted = self.network(small_photo, small_example).float().cpu()
        if len(self.info.parameters) == len(self.effect.param_names):
            return predicted
        # a model made before parameters were added: those take their defaults
        full = self.effect.default_params()[None].expand(predicted.shape[0], -1).clone()
        full[:, [self.effect.param_names.index(name) for name in self.info.parameters]] = predicted
        return full


class LocalPredictor:
    """A loaded local model: ``predictor(photo)`` -> normalized parameter masks ``(B, P, h, w)``
    at the model's working size (the short side it was trained at; the effect enlarges them
    to the picture it renders).

    A translator (a model with a post-processing CNN, a fixed preset or no effect;
    :mod:`wise.ppn.translation`) also gives its stages, :meth:`stages`, and re-runs the
    effect and the CNN on edited masks, :meth:`finish`: both at the working size, the scale
    its CNN learned."""

    def __init__(self, model: str | os.PathLike[str], effect: str, device: torch.device | str = "cpu") -> None:
        path = resolve_model(model, effect, "local")
        self.network, self.info = load_model(path, effect, "local")
        self.network.to(device)
        self.device = torch.device(device)
        self.effect = None if self.info.effect == NO_EFFECT else effects.create(self.info.effect).to(device)
        if str(model).startswith(BUILTIN_PREFIX):
            self.info.source = str(model)

    @property
    def translates(self) -> bool:
        return isinstance(self.network, Translator)

    @torch.no_grad()
    def __call__(self, photo: torch.Tensor) -> torch.Tensor | None:
        """Masks ``(B, P, h, w)``; a translator's may be its preset ``(B, P)`` or None (no effect)."""
        small = at_short_side(photo, self.info.size).to(self.device)
        masks = self.network.masks(small) if self.translates else self.network(small)
        return None if masks is None else masks.float().cpu()

    @torch.no_grad()
    def stages(self, photo: torch.Tensor) -> Stages:
        """Masks, effect stage and final image of ``photo`` at the working size."""
        return self.finish(photo, self(photo))

    @torch.no_grad()
    def finish(self, photo: torch.Tensor, masks: torch.Tensor | None) -> Stages:
        """Effect stage and final image of ``photo`` at the working size with ``masks`` (any size)."""
        small = at_short_side(photo, self.info.size).to(self.device)
        scale = window_scale(*small.shape[-2:])  # the scale training rendered at
        if not self.translates:
            stage = self.effect(small, masks.to(self.device), scale=scale)
            return Stages(masks, stage.cpu(), stage.cpu())
        made = self.network.finish(small, None if masks is None else masks.to(self.device), scale)
        return Stages(masks, made.stage.float().cpu(), made.result.float().cpu())
