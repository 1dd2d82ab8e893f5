"""The tasks of ``wise data adaptive`` (:mod:`wise.train.adaptive`): per task the rule that finds
its region and the parameter it changes there, readable without PyTorch."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Mapping

from wise.errors import WiseError

if TYPE_CHECKING:
    import torch


@dataclass(frozen=True)
class Change:
    """The parameter a task changes for one effect, its real value inside the region, and the
    preset of the other parameters when it is not the effect's default (:func:`wise.train.adaptive.task_preset`)."""

    parameter: str
    inside: float
    preset: str | None = None


@dataclass(frozen=True)
class Task:
    """A synthetic task: the rule that finds the region, in one sentence, and per effect the
    parameter it changes there."""

    name: str
    rule_name: str
    """A function of :mod:`wise.train.regions`: ``(B, 3, H, W)`` in [0, 1] -> soft region
    ``(B, 1, H, W)`` in [0, 1]."""
    description: str
    changes: Mapping[str, Change]

    @property
    def rule(self) -> Callable[[torch.Tensor], torch.Tensor]:
        from wise.train import regions  # PyTorch, scikit-image

        return getattr(regions, self.rule_name)

    def change(self, effect: str) -> Change:
        """The change for ``effect``; refuses effects the task has no parameter for."""
        if effect not in self.changes:
            supported = ", ".join(sorted(self.changes))
            raise WiseError(
                f"the {self.name!r} task has no parameter for the effect {effect!r}; supported effects: {supported}"
            )
        return self.changes[effect]


TASKS: dict[str, Task] = {
    task.name: task
    for task in (
        Task(
            "contours",
            "low_contrast_region",
            "the region is where the local contrast (standard deviation) of the luminance is low compared with "
            "the rest of the photo, where edges are weak",
            {
                # the largest reachable strength: faint edges turn into lines, strong ones thicken
                "xdog": Change("contour", 2.8),
                "cartoon": Change("contour", 2.8),
                # pencil contours drawn where the washes alone would lose the weak edges
                "watercolor": Change("contour", 0.9),
            },
        ),
        Task(
            "details",
            "fine_texture_region",
            "the region is where fine texture (the luminance minus a slight blur) makes up much of the local "
            "luminance energy compared with the rest of the photo, as on grass, bark or fur",
            {
                # near the coarsest reachable abstraction: texture turns into a few blobs and strokes;
                # half-toned, so that the abstraction shows in the tones of the whole region, not
                # only where lines cross it
                "xdog": Change("details", 0.3, preset="pencil"),
                "cartoon": Change("details", 0.3),
            },
        ),
        Task(
            "background",
            "background_region",
            "the region is the background: everything but the subject, the subject being where colour saliency "
            "(Lab distance from the photo's mean colour), sharpness and a centre prior are high, holes filled",
            {
                # a brighter input fades most lines and black areas of the drawing away (a lower contour
                # alone leaves the black areas, which grow); half-toned, so that the whole background
                # pales, not only its lines
                "xdog": Change("brightness", 0.45, preset="sketch"),
                # no outlines: the background turns into soft colour areas
                "cartoon": Change("contour", 0.2),
            },
        ),
    )
}


def task_named(name: str) -> Task:
    if name not in TASKS:
        raise WiseError(f"unknown task {name!r}; tasks: {', '.join(TASKS)}")
    return TASKS[name]
