"""A look: one effect with its parameters or a model, ready to stylize any number of images.

:class:`LookSpec` says what to render (plain data, so it can be sent to another process or
machine); :class:`Look` is the loaded form (the effect, the parameters and the model, held once)
whose :meth:`Look.render` stylizes one image. ``wise apply`` renders every image, of one
picture, a folder, a video or a Ray cluster, through it, so each result equals the one
image rendered alone.

How the parameters are chosen:

- no model: ``params`` (a parameter file), else ``preset``, else the effect's defaults, then the
  ``settings`` (real units; with local masks a setting fills the whole mask);
- a local model that paints masks (``wise train local``, ``builtin:TASK``): the model paints
  each image's masks at its working size, exactly as ``wise predict`` does, then the settings;
  ``params`` and ``preset`` are refused (the masks are the model's job);
- a translator (a local model with a CNN after the effect): with ``params`` or ``preset`` the
  effect runs at them and the CNN follows; without, the model paints its own masks first, as
  ``wise predict`` does. Its result has the model's working size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from wise import effects
from wise.batch.spec import LookSpec, Settings
from wise.effects.base import Effect
from wise.errors import WiseError
from wise.paramfile import load_params
from wise.ppn.modelfile import model_info, model_path
from wise.ppn.predictor import LocalPredictor
from wise.ppn.translation import NO_EFFECT
from wise.render import render


@dataclass
class Rendered:
    """One stylized image ``(1, 3, H, W)`` and the parameters it was rendered with (``(1, P)``
    global values or ``(1, P, h, w)`` masks; None for a model without an effect)."""

    image: torch.Tensor
    params: torch.Tensor | None = field(default=None)


def check_settings(effect: Effect, settings: Settings) -> list[tuple[int, float]]:
    """``(name, real value)`` pairs as ``(parameter index, normalized value)``, each checked."""
    checked = []
    for name, value in settings:
        spec = effect.spec(name)
        if not math.isfinite(value):
            raise WiseError(f"--set {name}={value}: the value must be a finite number")
        if not spec.in_range(value):
            raise WiseError(f"--set {name}={value:g}: outside the range [{spec.min:g}, {spec.max:g}] of {name}")
        checked.append((effect.param_names.index(name), spec.to_normalized(value)))
    return checked


def _with_settings(params: torch.Tensor, settings: list[tuple[int, float]]) -> torch.Tensor:
    if not settings:
        return params
    params = params.clone()
    for index, value in settings:
        params[:, index] = value
    return params


class Look:
    """The loaded form of a :class:`LookSpec`: every file is read and every name checked here,
    before any image is touched."""

    def __init__(self, spec: LookSpec) -> None:
        self.spec = spec
        self.device = torch.device(spec.device)
        self.predictor = self._predictor()
        if spec.effect == NO_EFFECT:  # a CNN alone
            if self.predictor is None:
                raise WiseError("the effect 'none' is a CNN alone: pass its --model (of 'wise train local none')")
            if spec.params or spec.preset or spec.settings:
                raise WiseError("the effect 'none' has no parameters; leave out --params, --preset and --set")
            self.effect, self.settings, self.paints, self.params = None, [], True, None
            return
        options = {} if spec.kernel_size is None else {"kernel_size": spec.kernel_size}
        self.effect = effects.create(spec.effect, **options).to(self.device).eval()
        self.settings = check_settings(self.effect, spec.settings)
        self.paints = self.predictor is not None and not (self.predictor.translates and (spec.params or spec.preset))
        self.params = None if self.paints else self._given_params()

    def _predictor(self) -> LocalPredictor | None:
        spec = self.spec
        if spec.model is None:
            return None
        kind = model_info(model_path(spec.model, spec.effect), spec.effect).kind
        if kind != "local":
            raise WiseError(
                f"--model {spec.model}: a global model re-creates a stylized example of each photo; "
                "use 'wise predict' with --target, or a local model here"
            )
        predictor = LocalPredictor(spec.model, spec.effect, self.device)
        if not predictor.translates and (spec.params or spec.preset):
            option = "--params" if spec.params else "--preset"
            raise WiseError(f"--model {spec.model}: a local model paints the masks of each image; leave out {option}")
        return predictor

    def _given_params(self) -> torch.Tensor:
        spec = self.spec
        if spec.params:
            params = load_params(spec.params, self.effect)
        elif spec.preset:
            params = self.effect.preset(spec.preset).unsqueeze(0)
        else:
            params = self.effect.default_params().unsqueeze(0)
        return _with_settings(params, self.settings)

    @torch.no_grad()
    def masks(self, image: torch.Tensor) -> torch.Tensor | None:
        """The masks a painting model predicts for ``image`` (settings applied); None otherwise."""
        if not self.paints:
            return None
        masks = self.predictor(image)
        return None if masks is None else _with_settings(masks, self.settings)

    @torch.no_grad()
    def render(self, image: torch.Tensor, masks: torch.Tensor | None = None) -> Rendered:
        """Stylize ``image`` ``(1, 3, H, W)`` in [0, 1]. ``masks`` replaces what a painting model
        would predict (e.g. masks smoothed over a video's frames)."""
        if self.paints and masks is None:
            masks = self.masks(image)
        params = masks if self.paints else self.params
        if self.predictor is not None and self.predictor.translates:
            made = self.predictor.finish(image, params)
            return Rendered(made.result, made.masks)
        return Rendered(render(self.effect, image, params, device=self.device), params)
