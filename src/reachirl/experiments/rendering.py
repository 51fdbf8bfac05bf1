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

import contextlib
import importlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["FIGURE_MEMORY_GB", "Drawing", "FigureJob", "draw", "drawing"]

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


class Drawing:
    """Figures being drawn; :meth:`wait` returns once every file is written (or raises the first error)."""

    def __init__(self, jobs: Sequence[FigureJob], workers: int) -> None:
        self._jobs = list(jobs)
        self._pool = None
        self._futures: list = []
        if workers > 1 and len(self._jobs) > 1:
            from .processes import local_executor

            self._pool = local_executor(min(workers, len(self._jobs)), FIGURE_MEMORY_GB, _ready)
            self._futures = [self._pool.submit(draw, job) for job in self._jobs]

    def wait(self) -> list[Path]:
        """Every figure's files, once written; the first error of a figure is raised here (the other workers
        are ended)."""
        jobs, futures, self._jobs, self._futures = self._jobs, self._futures, [], []
        if self._pool is None:
            return [p for job in jobs for p in draw(job)]
        try:
            written = [p for f in futures for p in f.result()]
        except BaseException:
            self.stop()
            raise
        self._pool.shutdown(wait=True)
        self._pool = None
        return written

    def stop(self) -> None:
        """End the workers now (what they draw is not written)."""
        if self._pool is not None:
            from .processes import stop_workers

            stop_workers(self._pool)
            self._pool = None


@contextlib.contextmanager
def drawing(jobs: Sequence[FigureJob], workers: int = 1) -> Iterator[Drawing]:
    """Start drawing ``jobs`` (listed costliest first) in ``workers`` processes; the block's end waits for
    them, an error or Ctrl-C in it ends them."""
    d = Drawing(jobs, workers)
    try:
        yield d
    except BaseException:
        d.stop()
        raise
    d.wait()
