"""Stylize a batch on Ray: the images of :func:`wise.batch.run.run_jobs` rendered by a pool of
Ray actors, on this machine or across a cluster, with the same results.

The batch is a Ray Data pipeline: the jobs whose outputs are missing become rows, and each
actor of the pool loads the look once and reads, renders and writes one image per row with
:func:`~wise.batch.run.stylize_one` (atomic writes, a failed image reported by name while the
batch goes on). Outcomes stream back to this process for the progress bar, the summary and
the ``--log`` file. An output that exists is skipped (``overwrite`` renders it again), so a
stopped run resumes where it left off.

Without an address, ``wise apply ... --ray`` starts Ray on this machine with all its cores
and stops it at the end. To use an existing cluster:

1. install ``wise[ray]`` (the same version) on every node;
2. make the inputs and the output folder visible at the same path on every node, e.g. on a
   shared filesystem (each node reads and writes the files itself; paths are sent absolute);
3. start the cluster: ``ray start --head`` on one node, then
   ``ray start --address HOST:6379`` on the others;
4. run ``wise apply EFFECT INPUTS... -o OUT --ray --ray-address HOST:6379`` from a node of
   the cluster (add ``--ray-gpus-per-worker 1`` to give each actor a GPU).

The cluster is left running. On the CPU there is one actor per few cores
(:func:`placement`); with GPUs, one actor per ``gpus_per_worker`` of the cluster's GPUs, and
the actors render on their GPU. Ctrl-C stops the pipeline; the files written are complete,
and an image cut off while being written leaves no output (at most a hidden temporary file
next to it, removed when Ray ran on this machine).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import socket
import sys
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator, Sequence

from wise.batch.inputs import Job
from wise.batch.look import Look, LookSpec
from wise.batch.run import DONE, FAILED, JsonLog, Outcome, Summary, pending, stylize_one
from wise.errors import WiseError
from wise.interrupt import ctrl_c
from wise.io import MAX_PIXELS_ENV
from wise.io.common import one_line
from wise.ppn.modelfile import BUILTIN_PREFIX
from wise.threads import usable_cores

if TYPE_CHECKING:
    import numpy as np

MISSING_RAY = '--ray needs Ray: pip install "wise[ray]"'
"""The one-line error when Ray (with Ray Data) is not installed."""

FORWARDED_ENVIRONMENT = (MAX_PIXELS_ENV, "WISE_KERNELS")
"""Variables of this process that the actors get too (the pixel limit, the kernel choice)."""

TASK_RETRIES = 2
"""Times an image is tried again on a restarted actor after its worker died (a lost node, a
crash, the memory monitor); then it is reported as failed and the batch goes on."""

LOST = "its Ray worker stopped while rendering it (a crash, out of memory or a lost node); run the command again"

CONNECT_SECONDS = 10.0
"""How long ``--ray-address`` may take to answer before the run stops with an error."""

MAX_BLOCKS = 4096
"""Most rows the jobs are split into: one job per block up to this, so outcomes stream back one
by one; beyond, a few jobs per block."""

LEFTOVER_SECONDS = 1.0
LEFTOVER_POLL = 0.1
"""After a run cut short, the temporary files of the writes cut off are removed for this long,
every :data:`LEFTOVER_POLL` seconds: the actors are killed as the pipeline closes (or Ray shuts
down), and one can still be ending its write when that returns."""


def require_ray() -> Any:
    """The ``ray`` module with Ray Data, or :class:`WiseError` saying how to install it."""
    try:
        import ray
        import ray.data  # noqa: F401 (the pipeline needs the data extra)
    except ImportError:
        raise WiseError(MISSING_RAY) from None
    return ray


@dataclass(frozen=True)
class Placement:
    """How the batch is spread: ``actors`` workers, each with ``threads`` PyTorch threads (and as
    many CPUs reserved) and ``gpus`` GPUs, rendering on ``device``."""

    actors: int
    threads: int
    gpus: float
    device: str


def _check_options(gpus: float, workers: int | None) -> float:
    """``gpus_per_worker`` checked, and ``workers``."""
    if workers is not None and workers < 1:
        raise WiseError(f"workers={workers}: at least one Ray actor is needed")
    if not math.isfinite(gpus) or gpus < 0:
        raise WiseError(f"--ray-gpus-per-worker {gpus:g}: must be 0 (CPU) or more")
    if gpus > 1 and gpus != int(gpus):
        raise WiseError(f"--ray-gpus-per-worker {gpus:g}: a fraction of one GPU or a whole number of GPUs")
    return float(gpus)


def placement(
    device: str,
    gpus_per_worker: float,
    workers: int | None,
    cpus: float,
    largest_node_cpus: float,
    gpus: float,
) -> Placement:
    """The actors for a look rendering on ``device`` on a cluster of ``cpus`` CPUs (the largest
    node has ``largest_node_cpus``) and ``gpus`` GPUs.

    With GPUs (``gpus_per_worker`` > 0, or 1 when the look asks for ``cuda``): one actor per
    ``gpus_per_worker`` of the cluster's GPUs, one CPU thread each, rendering on its GPU. On the
    CPU: actors of one PyTorch thread per 8 cores of the cluster (at least 1, at most 4, no more
    than a node has), as many as the cores allow; fewer threads per process render small
    images faster, while more processes hold more images in memory at once. ``workers`` fixes
    the number of actors, which then share the cores.
    """
    per_actor = _check_options(gpus_per_worker, workers)
    if per_actor == 0 and device.startswith("cuda"):
        per_actor = 1.0
    whole_cpus = max(1, int(cpus))
    if per_actor > 0:
        if gpus < per_actor:
            have = f"{gpus:g} GPUs" if gpus else "no GPU"
            raise WiseError(
                f"the actors need {per_actor:g} GPU each but the Ray cluster has {have}; "
                "add GPU nodes, or render on the CPU (--device cpu without --ray-gpus-per-worker)"
            )
        actors = workers if workers is not None else max(1, int(gpus / per_actor + 1e-9))
        return Placement(actors, 1, per_actor, "cuda")
    largest = max(1, int(largest_node_cpus))
    if workers is not None:
        threads = max(1, min(largest, whole_cpus // workers))
        return Placement(workers, threads, 0.0, device)
    threads = max(1, min(4, whole_cpus // 8, largest))
    return Placement(max(1, whole_cpus // threads), threads, 0.0, device)


class _Stylizer:
    """A Ray Data actor: the look loaded once, then one image read, rendered and written per row."""

    def __init__(self, spec: LookSpec, quality: int, threads: int) -> None:
        import torch

        torch.set_num_threads(threads)
        self.look = Look(spec)
        self.quality = quality

    def __call__(self, batch: dict[str, np.ndarray]) -> dict[str, list]:
        result: dict[str, list] = {"index": [], "status": [], "seconds": [], "error": []}
        for index, source, output, params in zip(batch["index"], batch["source"], batch["output"], batch["params"]):
            job = Job(Path(str(source)), Path(str(output)), Path(str(params)) if params else None)
            outcome = stylize_one(self.look, job, self.quality)
            result["index"].append(int(index))
            result["status"].append(outcome.status)
            result["seconds"].append(float(outcome.seconds))
            result["error"].append(outcome.error or "")
        return result


def _map(dataset: Any, fn: type, **options: Any) -> Any:
    """``dataset.map_batches(fn, **options)`` with :data:`TASK_RETRIES` retries of a task whose
    actor died (Ray Data's default, retrying for ever, never ends on an image that crashes its
    worker). That option is an extra Ray argument, deprecated by Ray Data: where it is refused,
    the default stands."""
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*ray_remote_args.*")
            return dataset.map_batches(fn, max_task_retries=TASK_RETRIES, **options)
    except TypeError:
        return dataset.map_batches(fn, **options)


def _actor_pool(ray: Any, actors: int) -> Any:
    """``actors`` actors (no idle one), each rendering one image at a time: an actor that dies
    then takes only its own image down, and the images queued behind it are not lost with it.
    Older Rays without the option queue a few per actor."""
    try:
        return ray.data.ActorPoolStrategy(size=actors, max_tasks_in_flight_per_actor=1)
    except TypeError:
        return ray.data.ActorPoolStrategy(size=actors)


def _check_reachable(address: str) -> None:
    """A clear error at once for a ``HOST:PORT`` where nothing listens (Ray itself retries for
    minutes); other forms (``auto``) are left to Ray."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_SECONDS).close()
    except OSError as error:
        raise WiseError(
            f"--ray-address {address}: no Ray cluster answers there ({error.strerror or one_line(error)}); "
            "start one with 'ray start --head' and give its HOST:PORT"
        ) from None


def _connect(ray: Any, address: str | None) -> None:
    """Ray started on this machine (``address`` None) or the cluster at ``address`` joined, unless
    this process is connected already."""
    if ray.is_initialized():
        return
    quiet = {"logging_level": logging.ERROR, "log_to_driver": False}
    if address is None:
        ray.init(num_cpus=usable_cores(), include_dashboard=False, **quiet)
        return
    _check_reachable(address)
    try:
        ray.init(address=address, **quiet)
    except (ConnectionError, RuntimeError, ValueError) as error:
        raise WiseError(
            f"--ray-address {address}: cannot join a Ray cluster there ({one_line(error)}); "
            "start one with 'ray start --head' and give its HOST:PORT"
        ) from None


@contextlib.contextmanager
def _data_settings(ray: Any) -> Iterator[None]:
    """Ray Data set up for the run, and back as it was after: no progress bars or messages of its
    own (our progress bar and summary say what happens; its log file keeps them), and a block
    whose worker died after its retries skipped rather than stopping the batch (its images
    are reported as failed)."""
    context = ray.data.DataContext.get_current()
    wanted = {"enable_progress_bars": False, "print_on_execution_start": False, "max_errored_blocks": -1}
    saved = {name: getattr(context, name) for name in wanted if hasattr(context, name)}  # older Rays lack some
    for name in saved:
        setattr(context, name, wanted[name])
    handlers = [h for h in logging.getLogger("ray.data").handlers if isinstance(h, logging.StreamHandler)]
    levels = [h.level for h in handlers]
    for handler in handlers:
        handler.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for handler, level in zip(handlers, levels):
            handler.setLevel(level)
        for name, value in saved.items():
            setattr(context, name, value)


def _cluster(ray: Any) -> tuple[float, float, float]:
    """The cluster's CPUs, the CPUs of its largest node, and its GPUs."""
    total = ray.cluster_resources()
    nodes = [node.get("Resources", {}) for node in ray.nodes() if node.get("Alive")]
    largest = max((node.get("CPU", 0.0) for node in nodes), default=total.get("CPU", 1.0))
    return total.get("CPU", 1.0), largest, total.get("GPU", 0.0)


def _rows(todo: Sequence[Job]) -> list[dict[str, Any]]:
    """The jobs as rows of plain values; absolute paths, since the actors do not share this
    process's working folder."""
    return [
        {
            "index": index,
            "source": os.path.abspath(job.source),
            "output": os.path.abspath(job.output),
            "params": "" if job.params is None else os.path.abspath(job.params),
        }
        for index, job in enumerate(todo)
    ]


def _for_actors(spec: LookSpec, device: str) -> LookSpec:
    """``spec`` rendering on ``device``, its files named by absolute paths."""
    model = spec.model
    if model is not None and not model.startswith(BUILTIN_PREFIX):
        model = os.path.abspath(model)
    params = None if spec.params is None else os.path.abspath(spec.params)
    return replace(spec, device=device, model=model, params=params)


def _as_given(error: str, job: Job) -> str:
    """An actor's error message with the paths as the jobs give them (the actors get them absolute)."""
    for path in (job.source, job.output, job.params):
        if path is not None:
            error = error.replace(os.path.abspath(path), str(path))
    return error


def _close(rows: Iterator[Any]) -> None:
    close = getattr(rows, "close", None)
    if close is not None:
        close()


def _remove_temporaries(jobs: Sequence[Job]) -> None:
    """The hidden temporary files (of :func:`wise.io.atomic_path`) that writes cut off by the end
    of the actors left next to ``jobs``' outputs, removed for :data:`LEFTOVER_SECONDS`."""
    if not jobs:
        return
    deadline = time.monotonic() + LEFTOVER_SECONDS
    while True:
        for job in jobs:
            for path in (job.output, job.params):
                if path is None or not path.parent.is_dir():
                    continue
                for leftover in path.parent.glob(f".{path.name}.*.tmp"):
                    try:
                        leftover.unlink()
                    except OSError:
                        pass
        if time.monotonic() >= deadline:
            return
        time.sleep(LEFTOVER_POLL)


def run_on_ray(
    spec: LookSpec,
    jobs: Sequence[Job],
    *,
    address: str | None = None,
    gpus_per_worker: float = 0.0,
    workers: int | None = None,
    quality: int = 95,
    overwrite: bool = False,
    log: JsonLog | None = None,
    progress: bool = False,
) -> Summary:
    """Stylize ``jobs`` with the look ``spec`` on Ray actors (see the module): on a Ray instance
    started here (``address`` None; stopped at the end) or the cluster at ``address``.

    ``gpus_per_worker`` gives each actor that share of a GPU (a look on ``cuda`` gets 1);
    ``workers`` fixes the number of actors (default: :func:`placement`). ``quality``,
    ``overwrite``, ``log`` and ``progress`` are those of :func:`~wise.batch.run.run_jobs`, and
    so is the :class:`Summary` returned. The look is loaded here first, so a bad name or file
    raises :class:`WiseError` before Ray starts.
    """
    ray = require_ray()
    began = time.perf_counter()
    Look(replace(spec, device="cpu"))  # every name and file checked, on any driver
    _check_options(gpus_per_worker, workers)
    summary = Summary()

    def finish(outcome: Outcome) -> None:
        summary.add(outcome)
        if log is not None:
            log.write(outcome)

    todo = pending(jobs, overwrite, finish)
    if todo:
        summary.interrupted = _run_pipeline(
            ray, spec, todo, finish, address=address, gpus_per_worker=gpus_per_worker, workers=workers,
            quality=quality, progress=progress,
        )  # fmt: skip
    summary.remaining = len(todo) - summary.done - len(summary.failed)
    summary.seconds = time.perf_counter() - began
    return summary


def _run_pipeline(
    ray: Any,
    spec: LookSpec,
    todo: list[Job],
    finish: Callable[[Outcome], None],
    *,
    address: str | None,
    gpus_per_worker: float,
    workers: int | None,
    quality: int,
    progress: bool,
) -> bool:
    """Render ``todo`` on Ray, each outcome passed to ``finish`` as it arrives; whether Ctrl-C
    stopped it."""
    from tqdm import tqdm

    reported = [False] * len(todo)
    interrupted = False
    bar = tqdm(total=len(todo), unit="img", disable=not progress, file=sys.stderr, dynamic_ncols=True)
    owns = address is None and not ray.is_initialized()
    with ctrl_c() as interrupt, contextlib.ExitStack() as stack:
        try:
            _connect(ray, address)
            where = placement(spec.device, gpus_per_worker, workers, *_cluster(ray))
            stack.enter_context(_data_settings(ray))
            environment = {name: os.environ[name] for name in FORWARDED_ENVIRONMENT if name in os.environ}
            blocks = min(len(todo), MAX_BLOCKS)
            try:
                dataset = ray.data.from_items(_rows(todo), override_num_blocks=blocks)
            except TypeError:  # older Rays name it parallelism
                dataset = ray.data.from_items(_rows(todo), parallelism=blocks)
            dataset = _map(
                dataset,
                _Stylizer,
                fn_constructor_args=(_for_actors(spec, where.device), quality, where.threads),
                batch_size=1,
                batch_format="numpy",
                compute=_actor_pool(ray, min(where.actors, blocks)),
                num_cpus=where.threads,
                num_gpus=where.gpus,
                runtime_env={"env_vars": environment} if environment else None,
            )
            rows = iter(dataset.iter_rows())
            try:
                for row in rows:
                    index = int(row["index"])
                    job = todo[index]
                    status = DONE if row["status"] == DONE else FAILED
                    reported[index] = True
                    error = None if status == DONE else _as_given(str(row["error"]), job)
                    finish(Outcome(str(job.source), str(job.output), status, float(row["seconds"]), error))
                    bar.update(1)
            finally:
                _close(rows)
            for index, job in enumerate(todo):  # the blocks of workers that died
                if not reported[index]:
                    reported[index] = True
                    finish(Outcome(str(job.source), str(job.output), FAILED, 0.0, f"{job.source}: {LOST}"))
                    bar.update(1)
        except KeyboardInterrupt:
            interrupted = True
        except ray.exceptions.RayError as error:
            raise WiseError(f"the Ray pipeline failed: {one_line(error)}") from None
        finally:
            interrupt.hold()  # a second Ctrl-C does not cut the shutdown short
            bar.close()
            if owns:
                ray.shutdown()
            # on a cluster it joined too: closing the pipeline kills the actors mid-write
            _remove_temporaries([job for job, done in zip(todo, reported) if not done])
    return interrupted
