"""The base class of all effects: declared parameters, presets, stage checkpointing."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, ClassVar, Mapping

import torch
from torch import nn

from wise import params as P
from wise.effects.catalogue import Entry
from wise.effects.recompute import recompute
from wise.errors import WiseError, size_text
from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.params import ParamSpec

LEAST_WINDOW_SCALE = 1.0


def window_scale(height: int, width: int) -> float:
    """The effect's scale (pixels per reference pixel) at which a picture of ``height`` × ``width``
    is rendered where it must stay that small (training pairs, a model's working size): its short
    side over the reference's 512, but at least :data:`LEAST_WINDOW_SCALE`.

    At its own scale a 256-pixel picture would halve every structure of an effect and XDoG's
    finest would fall under a pixel (no lines; ``wise apply`` renders such a picture at the
    reference size and reduces it instead). At the reference scale it is drawn as a window of a
    reference-size picture: the look users see, for the same pixels and so at no extra cost."""
    return max(min(height, width) / REFERENCE_SHORT_SIDE, LEAST_WINDOW_SCALE)


@dataclass(frozen=True)
class RenderContext:
    """Where the image being rendered sits in the whole picture.

    ``scale`` is pixels per reference pixel of the whole picture (its short side / 512), so
    that a tile is filtered exactly like the same region of the whole image; ``origin`` is the
    (y, x) pixel of the tile's top-left corner in the whole picture, for position-dependent
    textures.
    """

    scale: float
    origin: tuple[int, int] = (0, 0)
    guide: torch.Tensor | None = None
    """This tile's crop of the whole picture's :meth:`Effect.guide`, when the renderer made it
    beforehand; ``None``: the effect computes it from the tile."""
    medium: float | None = None
    """Pixels per reference pixel of the medium's own texture (bristles, paint relief, pigment,
    paper grain); ``None``: ``scale``. A picture rendered enlarged and then reduced gets textures
    enlarged as much, so that they keep at least their reference size in the pixels shown."""

    @property
    def medium_scale(self) -> float:
        return self.scale if self.medium is None else self.medium


class Effect(nn.Module):
    """A differentiable stylization pipeline with declared parameters.

    Subclasses set ``name``, ``param_specs`` and ``presets`` (real units) and
    implement :meth:`render`, which receives each parameter in real units as a
    ``(B, 1, 1, 1)`` (global) or ``(B, 1, H, W)`` (local) tensor.

    Args:
        kernel_size: D, the number of bilinear samples on each side of a pixel in the
            structure-adaptive filters (quality/speed trade-off; memory does not grow with D).
        checkpoint: recompute each pipeline stage during backward instead of keeping
            its intermediate tensors (less memory, a little more time).
    """

    name: ClassVar[str]
    param_specs: ClassVar[tuple[ParamSpec, ...]]
    presets: ClassVar[Mapping[str, Mapping[str, float]]] = {}
    tile_pixels: ClassVar[int] = 9_000_000
    """Most pixels of a padded tile when a large picture is rendered in tiles: bounds the memory
    of a render to a few GB (fewer for effects that keep more intermediate images per pixel)."""
    guide_channels: ClassVar[int] = 0
    """Channels of the effect's :meth:`guide` (0: the effect has none)."""
    guide_tile_pixels: ClassVar[int] = 9_000_000
    """Most pixels of a padded tile of the :meth:`guide` (a few stages: little memory per pixel)."""
    position_dependent: ClassVar[bool] = False
    """Whether the look depends on where a tile sits in the picture (textures fixed to the
    paper), so that tiles with other origins must be rendered apart."""
    added_params: ClassVar[tuple[str, ...]] = ()
    """Parameters added after the effect's first release: a parameter file made before them
    lacks them and loads with their defaults (:func:`wise.paramfile.load_params` says so)."""
    searched_params: ClassVar[tuple[str, ...]] = ()
    """Parameters whose gradient does not lead to their value from afar (a zero gradient at a
    bound, a structure too fine for reduced copies): optimization of global parameters tries a
    grid of each (:func:`wise.optimize.search.coordinate_search`) before its fine iterations."""

    def __init__(self, kernel_size: int = 3, checkpoint: bool = False) -> None:
        super().__init__()
        if not isinstance(kernel_size, int) or kernel_size < 1:
            raise WiseError(f"kernel size must be a positive integer, got {kernel_size!r}")
        self.kernel_size = kernel_size
        self.checkpoint = checkpoint

    @property
    def param_names(self) -> list[str]:
        return [s.name for s in self.param_specs]

    def spec(self, name: str) -> ParamSpec:
        return self.declarations().spec(name)

    @classmethod
    def declarations(cls) -> Entry:
        """The effect's parameters and presets as the catalogue holds them."""
        return Entry(cls.name, "", cls.param_specs, cls.presets)

    def default_params(self) -> torch.Tensor:
        """The defaults as a ``(P,)`` normalized tensor."""
        return P.from_dict(self.param_specs, {})

    def preset(self, name: str) -> torch.Tensor:
        """A preset as a ``(P,)`` normalized tensor."""
        self.declarations().check_preset(name)
        return P.from_dict(self.param_specs, self.presets[name])

    def params_from_dict(self, values: Mapping[str, float], preset: str | None = None) -> torch.Tensor:
        """A ``(P,)`` normalized tensor from real values; the rest from ``preset`` or the defaults."""
        base = self.presets[preset] if preset is not None else None
        if preset is not None and preset not in self.presets:
            self.preset(preset)  # raises the error naming the known presets
        return P.from_dict(self.param_specs, values, base=base)

    def params_to_dict(self, params: torch.Tensor) -> dict[str, float]:
        return P.to_dict(self.param_specs, params)

    def forward(
        self,
        image: torch.Tensor,
        params: torch.Tensor,
        *,
        scale: float | None = None,
        origin: tuple[int, int] = (0, 0),
        guide: torch.Tensor | None = None,
        medium: float | None = None,
    ) -> torch.Tensor:
        """Stylize ``image`` (B, 3, H, W) in [0, 1] with normalized ``params`` (B, P) or (B, P, h, w).

        ``scale`` and ``origin`` describe the whole picture when ``image`` is one tile of it
        (see :class:`RenderContext`); by default the image is the whole picture. ``guide`` is
        the tile's crop of :meth:`guide` made on the whole picture (only for effects that have one);
        ``medium`` the scale of the medium's texture where it is not ``scale``.
        """
        values, context = self._prepare(image, params, scale, origin)
        return self.render(image, values, RenderContext(context.scale, context.origin, guide, medium))

    def guide(
        self,
        image: torch.Tensor,
        params: torch.Tensor,
        *,
        scale: float | None = None,
        origin: tuple[int, int] = (0, 0),
    ) -> torch.Tensor:
        """The smooth fields of the picture that the pipeline reads far around each pixel (the
        flow of oil paint), ``(B, guide_channels, H, W)``. A renderer in tiles makes them once
        (in tiles of their own, with :meth:`guide_halo`) and hands each tile its crop, so the
        tiles of the rest need only :meth:`halo`. Arguments as :meth:`forward`."""
        values, context = self._prepare(image, params, scale, origin)
        return self.render_guide(image, values, context)

    def render_guide(self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext) -> torch.Tensor:
        """The guide's stages, on parameters in real units."""
        raise NotImplementedError(f"effect {self.name!r} has no guide")

    def guide_halo(self, scale: float) -> int:
        """How many pixels around a tile :meth:`guide` reads at ``scale`` (an upper bound)."""
        raise NotImplementedError(f"effect {self.name!r} has no guide")

    def real_values(
        self, image: torch.Tensor, params: torch.Tensor, scale: float | None = None
    ) -> tuple[dict[str, torch.Tensor], RenderContext]:
        """The parameters in real units as :meth:`render` reads them, and the context of
        ``image`` as a whole picture: for code that runs single stages of the pipeline."""
        return self._prepare(image, params, scale, (0, 0))

    def _prepare(
        self, image: torch.Tensor, params: torch.Tensor, scale: float | None, origin: tuple[int, int]
    ) -> tuple[dict[str, torch.Tensor], RenderContext]:
        if not isinstance(image, torch.Tensor) or image.dim() != 4 or image.shape[1] != 3:
            shape = tuple(image.shape) if isinstance(image, torch.Tensor) else type(image).__name__
            raise WiseError(f"image must be a (B, 3, H, W) tensor, got {shape}")
        if not image.is_floating_point():
            raise WiseError(f"image must be a float tensor in [0, 1], got {image.dtype}")
        if min(image.shape[-2:]) < 8:
            raise WiseError(
                f"image is too small ({size_text(image.shape[-1], image.shape[-2])} pixels); "
                "both sides must be at least 8 pixels"
            )
        params = P.check_params(params, self.param_specs, image.shape[0]).to(image)
        values = P.real_maps(params, self.param_specs, tuple(image.shape[-2:]))
        if scale is None:
            scale = min(image.shape[-2:]) / REFERENCE_SHORT_SIDE
        return values, RenderContext(scale, origin)

    def render(self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext) -> torch.Tensor:
        """The pipeline, on parameters in real units (see the class docstring)."""
        raise NotImplementedError

    def halo(self, scale: float) -> int:
        """How many pixels around a tile the pipeline reads at ``scale`` (an upper bound), given
        the tile's crop of the :meth:`guide` where the effect has one."""
        raise NotImplementedError

    def stage(self, fn: Callable[..., torch.Tensor], *args: object, **kwargs: object) -> torch.Tensor:
        """Run one pipeline stage, checkpointed when ``self.checkpoint`` is set."""
        if self.checkpoint:
            return recompute(fn, *args, **kwargs)
        return fn(*args, **kwargs)

    @staticmethod
    def recomputed(fn: Callable[..., torch.Tensor], *args: object, **kwargs: object) -> torch.Tensor:
        """Run a cheap pointwise stage and recompute it during backward rather than keeping
        its many intermediate tensors."""
        return recompute(fn, *args, **kwargs)
