"""Stylize many images in one process: the look loaded once, images read ahead of the render
and written behind it by worker threads.

Every result is written atomically (complete or absent). An output that exists is skipped, so
running the same command again resumes (``overwrite`` renders again). An image that cannot be
read, is too large or fails to render is reported by name and the batch goes on. Ctrl-C stops
within seconds: the images being written are finished, nothing half-written is left.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from typing import Callable, Sequence, TextIO

import torch

from wise.batch.inputs import Job
from wise.batch.look import Look, Rendered
from wise.errors import WiseError
from wise.interrupt import ctrl_c
from wise.io import read_image, write_image
from wise.io.common import one_line
from wise.paramfile import save_params

DONE, SKIPPED, FAILED = "done", "skipped", "failed"


@dataclass
class Outcome:
    """What happened to one input: ``status`` is ``done``, ``skipped`` (its output existed) or
    ``failed`` (``error`` says why)."""

    input: str
    output: str
    status: str
    seconds: float = 0.0
    error: str | None = None


@dataclass
class Summary:
    """The outcome of a batch: counts, the failed inputs, and whether Ctrl-C stopped it."""

    done: int = 0
    skipped: int = 0
    failed: list[Outcome] = field(default_factory=list)
    remaining: int = 0
    interrupted: bool = False
    seconds: float = 0.0

    def add(self, outcome: Outcome) -> None:
        if outcome.status == DONE:
            self.done += 1
        elif outcome.status == SKIPPED:
            self.skipped += 1
        else:
            self.failed.append(outcome)

    @property
    def ok(self) -> bool:
        return not self.failed and not self.interrupted

    def line(self) -> str:
        """One line for the end of a run, e.g. ``18 written, 2 skipped (already there), 1 failed``."""
        parts = [f"{self.done} written", f"{self.skipped} skipped (already there)", f"{len(self.failed)} failed"]
        if self.interrupted:
            parts.append(f"{self.remaining} not reached (interrupted; run the same command to finish)")
        rate = f"; {self.done / self.seconds:.2f} images/s" if self.done and self.seconds > 0 else ""
        return ", ".join(parts) + f" in {self.seconds:.1f} s{rate}"


def is_complete(job: Job) -> bool:
    """Whether the job's files exist (written atomically, an existing file is a complete one)."""
    return job.output.is_file() and (job.params is None or job.params.is_file())


def pending(jobs: Sequence[Job], overwrite: bool, skipped: Callable[[Outcome], None]) -> list[Job]:
    """The jobs to render: all with ``overwrite``, else those whose files are not complete; each
    job left out is passed to ``skipped``."""
    todo: list[Job] = []
    for job in jobs:
        if not overwrite and is_complete(job):
            skipped(Outcome(str(job.source), str(job.output), SKIPPED))
        else:
            todo.append(job)
    return todo


def write(job: Job, rendered: Rendered, look: Look, quality: int) -> None:
    """The job's files, each atomically; the parameter file first, so that an image that
    exists always has its parameters."""
    if job.params is not None and rendered.params is not None and look.effect is not None:
        job.params.parent.mkdir(parents=True, exist_ok=True)
        save_params(job.params, look.effect, rendered.params)
    job.output.parent.mkdir(parents=True, exist_ok=True)
    write_image(rendered.image, job.output, quality=quality)


def _error_text(error: BaseException) -> str:
    if isinstance(error, WiseError):
        return one_line(error)
    if isinstance(error, (MemoryError, torch.cuda.OutOfMemoryError)):
        return "out of memory; render it alone, on the CPU or with a lower --max-pixels"
    return f"{type(error).__name__}: {one_line(error)}"


def stylize_one(look: Look, job: Job, quality: int = 95) -> Outcome:
    """Read, render and write one job; a failure is returned, not raised (Ctrl-C is raised)."""
    began = time.perf_counter()
    try:
        rendered = look.render(read_image(job.source))
        write(job, rendered, look, quality)
    except Exception as error:  # noqa: BLE001 (each input's failure is reported and the batch goes on)
        return Outcome(str(job.source), str(job.output), FAILED, time.perf_counter() - began, _error_text(error))
    return Outcome(str(job.source), str(job.output), DONE, time.perf_counter() - began)


class JsonLog:
    """``--log FILE``: one JSON object per input and line, flushed as each input ends. The file
    is created with the first line, so a run refused before its work leaves none."""

    def __init__(self, path: str | os.PathLike[str] | None) -> None:
        self.path = path
        self.file: TextIO | None = None

    def write(self, outcome: Outcome) -> None:
        if self.path is None:
            return
        if self.file is None:
            self.file = open(self.path, "w", encoding="utf-8")
        record = asdict(outcome)
        record["seconds"] = round(record["seconds"], 4)
        self.file.write(json.dumps(record) + "\n")
        self.file.flush()

    def close(self) -> None:
        if self.file is not None:
            self.file.close()


def _progress(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="img", disable=not enabled or total == 0, file=sys.stderr, dynamic_ncols=True)


def run_jobs(
    look: Look,
    jobs: Sequence[Job],
    *,
    workers: int = 2,
    quality: int = 95,
    overwrite: bool = False,
    log: JsonLog | None = None,
    progress: bool = True,
    report: Callable[[Outcome], None] | None = None,
) -> Summary:
    """Stylize ``jobs`` with ``look`` in this process: ``workers`` threads read images ahead of
    the render and write results behind it; the render runs here, with PyTorch's threads."""
    summary = Summary()
    began = time.perf_counter()

    def finish(outcome: Outcome) -> None:
        summary.add(outcome)
        if log is not None:
            log.write(outcome)
        if report is not None and outcome.status == FAILED:
            report(outcome)

    todo = pending(jobs, overwrite, finish)
    bar = _progress(len(todo), progress)
    pool = ThreadPoolExecutor(max_workers=max(1, workers), thread_name_prefix="wise-batch")
    reads: deque[tuple[Job, Future, float]] = deque()
    writes: deque[tuple[Job, Future, float]] = deque()
    ahead = max(1, workers)
    queued = iter(todo)

    def read_more() -> None:
        while len(reads) < ahead:
            job = next(queued, None)
            if job is None:
                return
            reads.append((job, pool.submit(read_image, job.source), time.perf_counter()))

    def collect_writes(block: bool) -> None:
        while writes and (block or writes[0][1].done() or len(writes) > ahead):
            job, future, started = writes.popleft()
            error = future.exception()
            status, text = (DONE, None) if error is None else (FAILED, _error_text(error))
            finish(Outcome(str(job.source), str(job.output), status, time.perf_counter() - started, text))
            bar.update(1)

    with ctrl_c() as interrupt:
        try:
            read_more()
            while reads:
                job, future, started = reads.popleft()
                read_more()
                try:
                    rendered = look.render(future.result())
                except KeyboardInterrupt:
                    raise
                except Exception as error:  # noqa: BLE001 (reported by name; the batch goes on)
                    finish(Outcome(str(job.source), str(job.output), FAILED, time.perf_counter() - started,
                                   _error_text(error)))  # fmt: skip
                    bar.update(1)
                    continue
                writes.append((job, pool.submit(write, job, rendered, look, quality), started))
                collect_writes(block=False)
        except KeyboardInterrupt:
            summary.interrupted = True
        interrupt.hold()  # the writes under way finish; a second Ctrl-C does not cut them
        for _, future, _ in reads:
            future.cancel()
        collect_writes(block=True)
        pool.shutdown(wait=True, cancel_futures=True)
        bar.close()
    summary.remaining = len(todo) - summary.done - len(summary.failed)
    summary.seconds = time.perf_counter() - began
    return summary
