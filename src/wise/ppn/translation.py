"""The image-to-image generator of WISE Sec. 5.2: ``N(O(I, P_L(I)))``.

A local PPN (or a fixed preset) gives the effect's parameter masks, the differentiable effect
renders the photo with them (the *effect stage*), and a post-processing CNN turns that into the
final image. Each part may be left out for the ablation of the paper's supplement: without a
PPN the effect runs at the preset, without an effect the CNN works on the photo (a CNN-only
baseline), without a CNN the effect stage is the result (a plain local model).
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from wise import effects
from wise.effects.base import Effect
from wise.effects.catalogue import NO_EFFECT
from wise.errors import WiseError
from wise.ppn.choices import NO_POST, POST_KINDS, PPN_KINDS
from wise.ppn.postprocess import DEFAULT_WIDTH, create_post
from wise.ppn.unet import LocalPPN

ARCHITECTURE = "translator"
"""The architecture name of a translator in model files."""


class Stages(NamedTuple):
    masks: torch.Tensor | None
    """``(B, P, H, W)`` painted masks or ``(B, P)`` preset values; None without an effect."""
    stage: torch.Tensor
    """The effect's output ``(B, 3, H, W)`` (the photo without an effect)."""
    result: torch.Tensor
    """The final image ``(B, 3, H, W)`` (the effect stage without a CNN)."""


class Translator(nn.Module):
    """``N(O(I, P_L(I)))`` with any of ``ppn``, ``effect`` and ``post`` left out (None).

    ``start`` (``(P,)`` normalized) is the preset the effect runs at without a PPN; it is
    stored with the weights. The effect has no weights; it is a submodule only so that it
    moves with the network between devices.

    ``forward(photo)``: ``(B, 3, H, W)`` in [0, 1] -> the final image ``(B, 3, H, W)``.
    """

    def __init__(
        self,
        effect: Effect | None,
        ppn: nn.Module | None,
        post: nn.Module | None,
        start: torch.Tensor | None = None,
    ) -> None:
        super().__init__()
        if effect is None and (ppn is not None or post is None):
            raise WiseError("without an effect a translator is a CNN alone: give it a post-processing network")
        if effect is not None and ppn is None and start is None:
            raise WiseError("an effect without a PPN runs at a preset: give the translator its start values")
        if effect is not None and ppn is None and post is None:
            raise WiseError("an effect at a fixed preset with no CNN after it has nothing to learn")
        self.effect, self.ppn, self.post = effect, ppn, post
        params = len(effect.param_specs) if effect is not None else 0
        values = torch.zeros(params) if start is None else start.detach().reshape(-1).float()
        if values.numel() != params:
            raise WiseError(f"start values for {params} parameters expected, got {values.numel()}")
        self.register_buffer("start", values)

    def masks(self, photo: torch.Tensor) -> torch.Tensor | None:
        """The painted masks ``(B, P, H, W)``, the preset ``(B, P)``, or None without an effect."""
        if self.effect is None:
            return None
        if self.ppn is not None:
            return self.ppn(photo)
        return self.start.to(photo.dtype).expand(photo.shape[0], -1)

    def finish(
        self,
        photo: torch.Tensor,
        masks: torch.Tensor | None,
        scale: float | None = None,
        origin: tuple[int, int] = (0, 0),
    ) -> Stages:
        """The effect stage and the final image of ``photo`` with ``masks`` (e.g. edited ones)."""
        stage = self.render_stage(photo, masks, scale, origin)
        return Stages(masks, stage, self.draw(stage))

    def render_stage(
        self,
        photo: torch.Tensor,
        masks: torch.Tensor | None,
        scale: float | None = None,
        origin: tuple[int, int] = (0, 0),
    ) -> torch.Tensor:
        """The effect's output (the photo itself without an effect)."""
        return photo if self.effect is None else self.effect(photo, masks, scale=scale, origin=origin)

    def draw(self, stage: torch.Tensor) -> torch.Tensor:
        """The CNN's image of the effect stage (the stage itself without a CNN)."""
        return stage if self.post is None else self.post(stage.clamp(0.0, 1.0))

    def stages(self, photo: torch.Tensor, scale: float | None = None, origin: tuple[int, int] = (0, 0)) -> Stages:
        return self.finish(photo, self.masks(photo), scale, origin)

    def forward(self, photo: torch.Tensor) -> torch.Tensor:
        return self.stages(photo).result


def translator_options(
    ppn: str = "local",
    post: str = NO_POST,
    post_width: int = DEFAULT_WIDTH,
    dropout: bool = False,
    **ppn_options: int,
) -> dict[str, object]:
    """The options a model file records for :func:`build_translator` (its ``network``)."""
    return {"ppn": ppn, "post": post, "post_width": post_width, "dropout": dropout, **ppn_options}


def build_translator(effect_name: str, options: dict, start: torch.Tensor | None = None) -> Translator:
    """An untrained translator of ``effect_name`` (or :data:`NO_EFFECT`) with ``options`` of
    :func:`translator_options`; ``start`` is the preset (``(P,)`` normalized) the PPN starts
    from, or the effect runs at without one."""
    options = dict(options)
    ppn_kind, post, post_width = (
        options.pop("ppn", "local"),
        options.pop("post", NO_POST),
        options.pop("post_width", DEFAULT_WIDTH),
    )
    dropout = bool(options.pop("dropout", False))
    if ppn_kind not in PPN_KINDS:
        raise WiseError(f"unknown PPN kind {ppn_kind!r}; use one of {', '.join(PPN_KINDS)}")
    if post not in POST_KINDS:
        raise WiseError(f"unknown post-processing network {post!r}; use one of {', '.join(POST_KINDS)}")
    effect = None if effect_name == NO_EFFECT else effects.create(effect_name).requires_grad_(False)
    values = None
    if effect is not None:
        values = effect.default_params() if start is None else start
    painter = None
    if effect is not None and ppn_kind == "local":
        painter = LocalPPN(len(effect.param_specs), start=values, **options)
    after = None if post == NO_POST else create_post(post, int(post_width), dropout)
    return Translator(effect, painter, after, values)
