"""``wise.batch.stylize``: the Python entry point of ``wise apply`` over many images, on this
machine (:mod:`wise.batch.run`) or on Ray (:mod:`wise.batch.distributed`)."""

from __future__ import annotations

import os
from typing import Iterable, Sequence

from wise.batch.inputs import plan
from wise.batch.look import Look, LookSpec
from wise.batch.run import JsonLog, Summary, run_jobs


def stylize(
    inputs: Sequence[str | os.PathLike[str]] | str | os.PathLike[str],
    out: str | os.PathLike[str],
    effect: str | LookSpec,
    *,
    preset: str | None = None,
    params: str | os.PathLike[str] | None = None,
    settings: dict[str, float] | Iterable[tuple[str, float]] = (),
    model: str | os.PathLike[str] | None = None,
    device: str = "cpu",
    kernel_size: int | None = None,
    format: str = "png",
    quality: int = 95,
    save_params: bool = False,
    workers: int = 2,
    overwrite: bool = False,
    log: str | os.PathLike[str] | None = None,
    progress: bool = False,
    ray: bool = False,
    ray_address: str | None = None,
    ray_gpus_per_worker: float = 0.0,
) -> Summary:
    """Stylize images, folders (recursively) and glob patterns into the folder ``out``, keeping
    each image's path relative to its input folder; see :mod:`wise.batch`.

    ``effect`` is an effect name with the look given by the keyword arguments (as ``wise
    apply``'s options), or a whole :class:`LookSpec`. With ``ray``, the images are rendered by
    actors of a Ray cluster (:mod:`wise.batch.distributed`). Returns the :class:`Summary`; a
    failed image is in ``summary.failed``, not raised. Bad arguments raise
    :class:`~wise.errors.WiseError` before any image is read.
    """
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    if isinstance(effect, LookSpec):
        spec = effect
    else:
        pairs = tuple(settings.items()) if isinstance(settings, dict) else tuple(settings)
        spec = LookSpec(
            effect, preset=preset, params=None if params is None else str(params), settings=pairs,
            model=None if model is None else str(model), kernel_size=kernel_size, device=device,
        )  # fmt: skip
    jobs = plan([str(i) for i in inputs], out, format, save_params)
    journal = JsonLog(log)
    try:
        if ray:
            from wise.batch.distributed import run_on_ray

            return run_on_ray(
                spec, jobs, address=ray_address, gpus_per_worker=ray_gpus_per_worker, quality=quality,
                overwrite=overwrite, log=journal, progress=progress,
            )  # fmt: skip
        return run_jobs(Look(spec), jobs, workers=workers, quality=quality, overwrite=overwrite, log=journal,
                        progress=progress)  # fmt: skip
    finally:
        journal.close()
