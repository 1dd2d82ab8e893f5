"""What an optimization is asked for and where its results go, free of numerical libraries (the
command line checks its arguments with them before PyTorch loads; the optimization itself:
:mod:`wise.optimize.parametric`, :mod:`wise.optimize.run`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from wise.errors import WiseError

LOSSES = ("l1-lab", "l1", "l2", "nst")
MODES = ("local", "global")
MASK_SOFT_GRADIENTS = 0.5
"""Surrogate-gradient softness of the steps in per-pixel descent by default
(:func:`wise.filters.smoothing.softened_gradients`): a pixel inked black lies on the flat end of
the XDoG threshold, so its masks get no gradient that would take the ink away; through a ramp
widened this much they do. Global values see enough pixels on the slope to need none
(BENCHMARKS.md, "Ink that per-pixel descent can take away")."""
PYRAMIDS: dict[int, tuple[tuple[int, float, float], ...]] = {
    1: ((1, 1.0, 1.0),),
    2: ((2, 0.4, 1.0), (1, 0.6, 0.1)),
    3: ((4, 2 / 7, 1.0), (2, 2 / 7, 0.5), (1, 3 / 7, 0.1)),
}
"""Coarse-to-fine schedules by number of levels: (reduction of the working size, share of
the iterations, factor on the learning rate) per level, coarsest first."""

NST_METHODS = ("onnx", "gatys")
RESULT_FILES = ("params.safetensors", "result.png", "metrics.json", "report.html", "optimization.gif")
"""What :func:`wise.optimize.run.run` writes into its folder, the resumable parameter file first."""
TARGET_FILE = "target.png"
"""The neural style transfer reference :func:`wise.optimize.run.transfer` adds."""


def init_is_file(init: str) -> bool:
    """Whether ``--init`` names a parameter file rather than a preset."""
    return init.endswith(".safetensors") or Path(init).exists()


DEFAULT_BUDGET = 8.0
"""Seconds of refinement by default: with the interpreter's start, the prediction and the
final rendering, ``wise predict`` then stays within about 15 s at 512 px on a 2-core CPU."""


@dataclass
class Settings:
    """How to optimize; see :mod:`wise.optimize.parametric`."""

    mode: str = "local"
    iterations: int = 350
    lr: float = 0.1
    loss: str = "l1-lab"
    tv_weight: float = 0.0
    vgg_weights: str | None = None
    """VGG-19 weights (safetensors) for the ``nst`` loss; default location when None."""
    levels: int = 3
    """Pyramid levels of :func:`wise.optimize.parametric.pyramid` (1: every iteration at the working size)."""
    time_limit: float | None = None
    """Seconds the iterations and the final render may take (None: all of them are run): no
    iteration starts that could end later, judged by the longest iteration and render so far;
    annealing then follows the time spent as well as the iterations done, whichever is
    further along."""
    anneal: float = 0.0
    """Step temperature at the first iteration (0 to 1), lowered to 0 by
    :func:`wise.filters.smoothing.annealed_temperature` (graduated non-convexity); 0: none."""
    held: tuple[str, ...] = ()
    """Parameters descent leaves where they are (read off the example in closed form,
    :mod:`wise.optimize.inversion`): their gradient is set to zero."""
    soft_gradients: float | None = None
    """Surrogate-gradient softness of the steps (0 to 1, :func:`wise.filters.smoothing.softened_gradients`):
    the look renders exactly, its steps pass gradients as wider ramps. None: :data:`MASK_SOFT_GRADIENTS`
    for per-pixel masks, 0 for global values."""

    at_reference: bool = False
    """Render as :func:`wise.render.render` does (:class:`wise.render.Look`): a picture whose short
    side is below the reference enlarged to it and reduced back, the look the user's render
    shows; the commands fit that. False: at the picture's own scale, as ``effect(content,
    params)`` renders (a working copy, where iterations on a small picture cost its own pixels)."""

    final_lr: float | None = None
    """The learning rate at the end as a share of ``lr``, reached along a half cosine over the
    progress (iterations or time, as the annealing): the noise of random crops then settles
    instead of moving the answer at the last iterations. None: the paper's schedule."""

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise WiseError(f"unknown mode {self.mode!r}; use one of {', '.join(MODES)}")
        if self.loss not in LOSSES:
            raise WiseError(f"unknown loss {self.loss!r}; use one of {', '.join(LOSSES)}")
        if self.iterations < 1:
            raise WiseError(f"iterations must be at least 1, got {self.iterations}")
        if not self.lr > 0:
            raise WiseError(f"the learning rate must be positive, got {self.lr}")
        if self.tv_weight < 0:
            raise WiseError(f"the total-variation weight must be at least 0, got {self.tv_weight}")
        if self.final_lr is not None and not 0 < self.final_lr <= 1:
            raise WiseError(f"the final learning rate share must be in (0, 1], got {self.final_lr}")
        if self.time_limit is not None and not self.time_limit > 0:
            raise WiseError(f"the time limit must be positive, got {self.time_limit}")
        if not 0.0 <= self.anneal <= 1.0:
            raise WiseError(f"the annealing temperature must be from 0 to 1, got {self.anneal}")
        if self.levels not in PYRAMIDS:
            raise WiseError(f"levels must be one of {', '.join(map(str, PYRAMIDS))}, got {self.levels}")
        if self.soft_gradients is None:
            self.soft_gradients = MASK_SOFT_GRADIENTS if self.mode == "local" else 0.0
        if not 0.0 <= self.soft_gradients <= 1.0:
            raise WiseError(f"the gradient softness must be from 0 to 1, got {self.soft_gradients}")


RECOVER_ITERATIONS = 600
"""Iterations of a trial of ``wise bench recover``, all levels and crops (300 left watercolor's
fine parameters short of the truth: 28.5 dB against 35.2 dB on the same trials)."""
INIT_DEFAULTS = "defaults"
INIT_PPN = "ppn"


def parse_init(init: str) -> tuple[str, str | None]:
    """``defaults``, ``ppn`` (the built-in model) or ``ppn:MODEL`` -> (kind, model file or None)."""
    kind, _, model = init.partition(":")
    if kind == INIT_DEFAULTS and not model:
        return kind, None
    if kind == INIT_PPN:
        return kind, model or None
    raise WiseError(f"--init {init!r}: use {INIT_DEFAULTS}, {INIT_PPN} or {INIT_PPN}:MODEL")
