"""Figures drawn in worker processes while the report's other outputs are written.

A :class:`FigureJob` names a plotting function (``"module:function"``), its keyword arguments (data only: arrays,
numbers, strings) and the files it is saved to (:func:`reachirl.experiments.figures.save`: atomic, PNG or PDF
from the suffix). :func:`drawing` starts the jobs: with ``workers`` > 1 in that many local processes
(:mod:`reachirl.experiments.processes`), each drawing whole figures, the costliest first; otherwise in this process,
one after the other, when :meth:`Drawing.wait` is called. A figure is the same file whichever process draws it:
matplotlib with the same settings draws the same pixels. Leaving the ``with`` block on an error, or on Ctrl-C,
ends the workers at once (a figure they were writing is never left half written).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import importlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .processes import WorkersAhead

__all__ = ["FIGURE_MEMORY_GB", "Drawing", "FigureJob", "FigureWorkers", "draw", "drawing"]

#: memory (address space) of one figure worker, GB
FIGURE_MEMORY_GB = 4.0


@dataclass(frozen=True)
class FigureJob:
    """Draw ``plot(**kwargs)`` and save it to each of ``paths`` in turn (e.g. a PDF, then the PNG)."""

    plot: str  # "package.module:function", returning a matplotlib figure
    kwargs: dict = field(default_factory=dict)
    paths: tuple[Path, ...] = ()


def draw(job: FigureJob) -> tuple[Path, ...]:
    """Draw one figure and write its files; returns them."""
    from .figures import save

    module, _, name = job.plot.partition(":")
    fig = getattr(importlib.import_module(module), name)(**job.kwargs)
    for i, path in enumerate(job.paths):
        save(fig, path, close=i == len(job.paths) - 1)
    return job.paths


def _ready() -> None:
    """A figure worker's imports, before its first job."""
    importlib.import_module(f"{__package__}.figures")


class FigureWorkers(WorkersAhead):
    """``workers`` figure processes, started ahead of the figures (:meth:`start`: e.g. when the run's last units
    leave a core idle) so that their start and imports are done when the figures come. A ``with`` block ends
    them on leaving (an error, Ctrl-C, or figures never drawn); :func:`drawing` takes them over."""

    def __init__(self, workers: int) -> None:
        super().__init__(workers, lambda: FIGURE_MEMORY_GB, _ready)


class Drawing:
    """Figures being drawn; :meth:`wait` returns once every file is written (or raises the first error)."""

    def __init__(self, jobs: Sequence[FigureJob], workers: int, ahead: FigureWorkers | None = None) -> None:
        self._jobs = list(jobs)
        self._pool = ahead.take() if ahead is not None else None
        self._futures: list = []
        self._ended = None  # the pool wait() shut down (see close)
        if self._pool is None and workers > 1 and len(self._jobs) > 1:
            from .processes import local_executor

            self._pool = local_executor(min(workers, len(self._jobs)), FIGURE_MEMORY_GB, _ready)
        if self._pool is not None:
            self._futures = [self._pool.submit(draw, job) for job in self._jobs]

    def wait(self) -> list[Path]:
        """Every figure's files, once written; the first error of a figure is raised here (the other workers
        are ended)."""
        jobs, futures, self._jobs, self._futures = self._jobs, self._futures, [], []
        if self._pool is None:
            return [p for job in jobs for p in draw(job)]
        written = []
        try:
            for job, f in zip(jobs, futures, strict=True):
                try:
                    written += f.result()
                except cf.process.BrokenProcessPool:  # killed, or out of its memory: said as a unit's worker is
                    from .processes import worker_died

                    where = job.paths[0] if job.paths else None
                    raise worker_died(
                        f"drawing figure {where.name if where else job.plot}",
                        "the run's results are kept (rerun to draw it again)",
                        where.parent if where else None,
                    ) from None
        except BaseException:
            self.stop()
            raise
        # every figure is written: the workers end on their own (their interpreters' exit, a tenth of a second,
        # overlaps what the caller writes next; close() or Python's own exit joins them)
        self._pool.shutdown(wait=False)
        self._ended, self._pool = self._pool, None
        return written

    def close(self) -> None:
        """Once :meth:`wait` has returned: wait for the ended pool's manager thread, which ends with the workers
        (:meth:`reachirl.experiments.processes._Pool.join_manager`: no traceback at Python's exit)."""
        if self._ended is not None:
            self._ended.join_manager(10.0)
            self._ended = None

    def stop(self) -> None:
        """End the workers now (what they draw is not written)."""
        if self._pool is not None:
            from .processes import stop_workers

            stop_workers(self._pool)
            self._pool = None


@contextlib.contextmanager
def drawing(jobs: Sequence[FigureJob], workers: int = 1, ahead: FigureWorkers | None = None) -> Iterator[Drawing]:
    """Start drawing ``jobs`` (listed costliest first) in ``workers`` processes (those of ``ahead`` when it has
    started them); the block's end waits for them, an error or Ctrl-C in it ends them."""
    d = Drawing(jobs, workers, ahead)
    try:
        yield d
    except BaseException:
        d.stop()
        raise
    d.wait()
