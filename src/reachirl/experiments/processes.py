"""Local worker processes, for the units (:mod:`reachirl.experiments.runner`) and the figures
(:mod:`reachirl.experiments.rendering`): started with ``spawn``, bounded, and ended at once.

A worker ignores Ctrl-C (the coordinating process ends the workers), dies with its parent (even a SIGKILLed one)
and has its memory (address space) capped. :func:`stop_workers` cancels what has not started and terminates the
workers, without waiting for the work in progress.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
from collections.abc import Callable

__all__ = ["local_executor", "stop_workers", "worker_died", "worker_init"]


def worker_init(parent_pid: int, memory_gb: float, then: Callable[[], None] | None = None) -> None:
    """Bounds of a local worker: it dies with its parent (even a SIGKILLed one) and its memory is capped; then
    ``then()`` (e.g. imports the worker's modules before its first task)."""
    import signal

    from ..workers import die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the coordinator's business: it ends the workers
    die_with_parent(parent_pid)
    try:
        import resource

        limit = int(memory_gb * 1024**3)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    except (ImportError, ValueError, OSError):
        pass
    if then is not None:
        then()


class _Pool(cf.ProcessPoolExecutor):
    """A pool whose workers are started with Ctrl-C ignored: a spawned worker imports for a second or two before
    :func:`worker_init` runs, and a Ctrl-C to the terminal's process group then printed its traceback. An ignored
    signal stays ignored across ``exec``, and Python leaves it so; the pool starts its workers in ``submit``."""

    def submit(self, fn, /, *args, **kwargs):
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return super().submit(fn, *args, **kwargs)
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            return super().submit(fn, *args, **kwargs)
        finally:
            signal.signal(signal.SIGINT, previous)


def local_executor(workers: int, memory_gb: float, then: Callable[[], None] | None = None) -> cf.ProcessPoolExecutor:
    """A pool of ``workers`` bounded local processes (:func:`worker_init`; ``then``: a module-level function each
    runs once started)."""
    # spawn: never fork a process holding CasADi/IPOPT state or threads; workers import reachirl afresh
    ctx = multiprocessing.get_context("spawn")
    return _Pool(max_workers=workers, mp_context=ctx, initializer=worker_init, initargs=(os.getpid(), memory_gb, then))


def worker_died(doing: str, kept: str, path: object | None = None):
    """The error of a local worker that died while ``doing`` (e.g. ``"running unit <key>"``): killed (SIGKILL, the
    OOM killer), the run's circumstance, not a bug; an :class:`~reachirl.errors.InputError` (exit 2, one line)
    naming ``path`` and saying what is ``kept``."""
    from ..errors import InputError

    return InputError(f"a worker process died (killed, or out of memory) while {doing}; {kept}", path)


def stop_workers(ex: cf.ProcessPoolExecutor) -> None:
    """End the pool now: cancel what has not started and terminate the workers (a unit can run for minutes;
    waiting for it made Ctrl-C hang)."""
    # the pool's own table of its processes (no public API): the same object its manager thread adds a process
    # to, so a worker started while the pool shuts down is ended too
    table = getattr(ex, "_processes", None) or {}
    ex.shutdown(wait=False, cancel_futures=True)
    for _ in range(3):
        procs = [p for p in list(table.values()) if p.is_alive()]
        if not procs:
            break
        for p in procs:
            p.terminate()
        for p in procs:
            p.join(timeout=2.0)
            if p.is_alive():
                p.kill()  # cannot be ignored; reaped once the kernel has ended it (seconds on a loaded machine)
                p.join(timeout=15.0)
