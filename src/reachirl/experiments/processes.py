"""Local worker processes, for the units (:mod:`reachirl.experiments.runner`) and the figures
(:mod:`reachirl.experiments.rendering`): started with ``spawn``, bounded, and ended at once.

A worker ignores Ctrl-C (the coordinating process ends the workers), dies with its parent (even a SIGKILLed one)
and has its memory (address space) capped. :func:`stop_workers` cancels what has not started and terminates the
workers, without waiting for the work in progress. ``spawn`` imports the main script again in each worker: a
script that would start the workers again there (its call outside ``if __name__ == "__main__":``) is refused
before they start (:func:`check_entry_point_guarded`).
"""

from __future__ import annotations

import concurrent.futures as cf
import functools
import multiprocessing
import os
from collections.abc import Callable

__all__ = [
    "WorkersAhead",
    "check_entry_point_guarded",
    "local_executor",
    "stop_workers",
    "worker_died",
    "worker_init",
]


#: in a worker process: why its set-up (``worker_init``'s ``then``) failed, which each of its tasks says
_start_failure: str | None = None


def worker_init(parent_pid: int, memory_gb: float, then: Callable[[], None] | None = None) -> None:
    """Bounds of a local worker: it dies with its parent (even a SIGKILLed one) and its memory is capped; then
    ``then()`` (e.g. imports the worker's modules before its first task). A ``then()`` that fails leaves the
    worker running, each task it is given raising the reason (:func:`_started`)."""
    global _start_failure
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
        try:
            then()
        except Exception as e:
            memory = f"; its memory limit is {memory_gb:g} GB" if isinstance(e, MemoryError) else ""
            _start_failure = f"{type(e).__name__}: {e}{memory}"


def _started(fn, /, *args, **kwargs):
    """``fn(*args, **kwargs)`` in a worker whose set-up succeeded; in one whose set-up failed, an
    :class:`~reachirl.errors.InputError` saying why (exit 2 and one line, as a worker that died)."""
    if _start_failure is not None:
        from ..errors import InputError

        raise InputError(f"a worker process could not start ({_start_failure})")
    return fn(*args, **kwargs)


class _Pool(cf.ProcessPoolExecutor):
    """A pool whose workers are started with Ctrl-C ignored: a spawned worker imports for a second or two before
    :func:`worker_init` runs, and a Ctrl-C to the terminal's process group then printed its traceback. An ignored
    signal stays ignored across ``exec``, and Python leaves it so; the pool starts its workers in ``submit``.
    After ``shutdown``, :meth:`join_manager` waits for the pool's manager thread."""

    _manager = None  # the manager thread, kept from shutdown(), which forgets it

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._manager = getattr(self, "_executor_manager_thread", None) or self._manager
        super().shutdown(wait=wait, cancel_futures=cancel_futures)

    def join_manager(self, timeout: float) -> None:
        """Wait (at most ``timeout`` s) for the manager thread of a pool shut down, which closes its wake-up pipe as
        it ends. Python's exit writes to that pipe while the thread may be closing it (concurrent.futures' exit
        hook, unlocked in Python 3.11: an OSError traceback); once the thread has ended, the write is skipped."""
        if self._manager is not None:
            self._manager.join(timeout=timeout)

    def submit(self, fn, /, *args, **kwargs):
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return super().submit(_started, fn, *args, **kwargs)
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            return super().submit(_started, fn, *args, **kwargs)
        finally:
            signal.signal(signal.SIGINT, previous)


def _unguarded_call_line() -> tuple[str, int] | None:
    """The script and line of the top-level statement of ``__main__`` that led to this call, when that statement is
    not inside an ``if`` testing ``__name__``: a spawned worker imports the main module again and would run it
    again. None when the main module has no source file (an interactive session, ``python -c``) or is a package's
    ``__main__`` (``python -m PACKAGE``: not imported again in a worker), when no top-level statement of it is on
    the stack (a call from another thread), or when its source cannot be read."""
    import ast
    import sys

    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if main is None or not path:
        return None
    name = getattr(getattr(main, "__spec__", None), "name", None)
    if name == "__main__" or (name or "").endswith(".__main__"):  # a package's __main__ (python -m PACKAGE)
        return None  # is not imported again in a spawned worker
    frame = sys._getframe(1)
    while frame is not None and not (frame.f_globals is vars(main) and frame.f_code.co_name == "<module>"):
        frame = frame.f_back
    if frame is None:
        return None
    line = frame.f_lineno
    try:
        with open(path, "rb") as f:
            tree = ast.parse(f.read(), filename=path)
    except (OSError, SyntaxError, ValueError):
        return None
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.If)
            and node.lineno <= line <= (node.end_lineno or node.lineno)
            and any(isinstance(n, ast.Name) and n.id == "__name__" for n in ast.walk(node.test))
        ):
            return None
    return str(path), line


def check_entry_point_guarded(option: str = "workers") -> None:
    """Before local worker processes are started: the main script does not start them from its top-level code
    outside ``if __name__ == "__main__":``. Workers are started with ``spawn``, which imports the main script
    again in each worker: such a call would run again there, and the workers fail as they start. Refused, an
    :class:`~reachirl.errors.InputError` naming the script and the line, saying to protect the entry point or to
    set ``option`` to 1 (run in this process)."""
    from ..errors import InputError

    found = _unguarded_call_line()
    if found is None:
        return
    path, line = found
    raise InputError(
        f"line {line} starts local worker processes from the script's top-level code, outside "
        f'`if __name__ == "__main__":`; each worker imports the script again and would run it again. Put the '
        f'script\'s entry point under `if __name__ == "__main__":`, or use {option}=1 (runs in this process)',
        path,
    )


def local_executor(workers: int, memory_gb: float, then: Callable[[], None] | None = None) -> cf.ProcessPoolExecutor:
    """A pool of ``workers`` bounded local processes (:func:`worker_init`; ``then``: a module-level function each
    runs once started); refused when the main script would start it again in each worker
    (:func:`check_entry_point_guarded`)."""
    check_entry_point_guarded()
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
    if isinstance(ex, _Pool):
        ex.join_manager(5.0)  # no traceback at exit after "interrupted"


class WorkersAhead:
    """``workers`` local processes started before their work (:meth:`start`), so that their start and
    ``ready(*args)`` (run once in each: its imports, what it loads) overlap what the caller does meanwhile.
    :meth:`take` hands the pool over to its work; a ``with`` block ends the processes on leaving if no work took
    them (an error, Ctrl-C, nothing to do)."""

    def __init__(self, workers: int, memory_gb: Callable[[], float], ready: Callable[..., None], *args) -> None:
        self.workers = int(workers)
        self.pool: cf.ProcessPoolExecutor | None = None
        self._memory_gb, self._ready = memory_gb, (functools.partial(ready, *args) if args else ready)

    def start(self) -> None:
        """Start the processes now (once; nothing with fewer than 2 workers: the work then runs in-process)."""
        if self.pool is not None or self.workers < 2:
            return
        self.pool = local_executor(self.workers, self._memory_gb(), self._ready)
        for _ in range(self.workers):  # one process is started per task submitted while none is idle
            self.pool.submit(int)

    def take(self) -> cf.ProcessPoolExecutor | None:
        """The started pool, handed over (None if not started)."""
        pool, self.pool = self.pool, None
        return pool

    def stop(self) -> None:
        if self.pool is not None:
            stop_workers(self.take())

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
