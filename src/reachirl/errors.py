"""Errors that the command line turns into exit code 2 and a one-line message, and the guard that keeps a
signal (Ctrl-C, SIGTERM) an interrupt while a compiled solver runs."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator

__all__ = [
    "InputError",
    "NotFittedError",
    "Terminated",
    "clear_signals",
    "interrupt_pending",
    "note_signal",
    "raise_if_signalled",
    "signalled",
    "solver_interrupts",
    "track_signals",
]


class InputError(ValueError):
    """Bad input: a file, a line or frame, and what was expected.

    ``str(err)`` is the whole one-line message, e.g. ``"trials.npz: q has shape (3,), expected (n, 2)"``.
    """

    def __init__(self, message: str, path: object | None = None, where: str | None = None):
        parts = [str(path)] if path is not None else []
        if where:
            parts.append(str(where))
        self.path, self.where, self.reason = path, where, message
        text = ": ".join([*parts, message]) if parts else message
        # one line, whatever the input held (a field quoted from a garbled file may hold line breaks)
        super().__init__(text.replace("\r", "\\r").replace("\n", "\\n"))


class NotFittedError(ValueError, AttributeError, RuntimeError):
    """An estimator asked to predict or score (or for its fitted attributes' products) before ``fit``: the message
    says to call ``fit`` first. A ``ValueError`` and an ``AttributeError``, as scikit-learn's ``NotFittedError``
    (which its tools catch), and a ``RuntimeError``, as reachirl's error of it was before."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every ``finally`` runs (workers ended, finished units kept)."""


# signals caught by the innermost active solver_interrupts() of the main thread
_caught: list[int] = []
# every SIGINT/SIGTERM of the command so far (note_signal), whatever code was running when it arrived
_signalled: list[int] = []
_tracking: list = []  # [callback or None] while a command tracks its signals
_GUARDED = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGALRM") if hasattr(signal, n))


def track_signals(on: bool, on_signal=None) -> None:
    """Start (a command starts) or stop recording SIGINT/SIGTERM with :func:`note_signal`; both forget what was
    recorded. ``on_signal(signum)`` is called on each one recorded. Off by default: in a Python session a Ctrl-C
    is handled once and forgotten."""
    _tracking[:] = [on_signal] if on else []
    clear_signals()


def note_signal(signum: int) -> None:
    """Record that SIGINT or SIGTERM arrived, while :func:`track_signals` is on (the command line's handlers call
    this before they raise), so that an interrupt swallowed by compiled code still ends the command
    (:func:`raise_if_signalled`)."""
    if _tracking and signum in (signal.SIGINT, signal.SIGTERM):
        _signalled.append(signum)
        if _tracking[0] is not None:
            _tracking[0](signum)


def signalled() -> int | None:
    """The first SIGINT/SIGTERM recorded by :func:`note_signal` (None: none)."""
    return _signalled[0] if _signalled else None


def clear_signals() -> None:
    """Forget the recorded signals (a new command starts)."""
    _signalled.clear()
    _caught.clear()


def raise_if_signalled() -> None:
    """Raise :class:`Terminated` (SIGTERM) or ``KeyboardInterrupt`` (SIGINT) if one was recorded: called before
    a result is written, so that work done after an interrupt never becomes an output."""
    sig = signalled()
    if sig == signal.SIGTERM:
        raise Terminated()
    if sig == signal.SIGINT:
        raise KeyboardInterrupt


def interrupt_pending() -> bool:
    """Whether a signal arrived during the solve that :func:`solver_interrupts` guards (a solver's own
    per-iteration callback asks this to stop early)."""
    return bool(_caught) or bool(_signalled)


def _guarded(sig: int) -> bool:
    h = signal.getsignal(sig)
    if callable(h):
        return True  # the Ctrl-C handler, the CLI's SIGTERM handler, a unit's SIGALRM time limit
    return h == signal.SIG_DFL and sig in (signal.SIGINT, signal.SIGTERM)


def _redeliver(sig: int, previous) -> None:
    if callable(previous):
        previous(sig, None)  # raises: KeyboardInterrupt, Terminated, a time limit's error
        return
    signal.signal(sig, previous)  # SIG_DFL: end the process as the signal would have
    os.kill(os.getpid(), sig)


def unmuted_stderr():
    """``sys.stderr`` without the muting of :func:`solver_interrupts` (for the command's last word on a signal:
    a guard left open, such as one in a suspended generator, must not swallow it)."""
    stream = sys.stderr
    while isinstance(stream, _MutedAfter):
        stream = stream._stream
    return stream


class _MutedAfter:
    """``stream``, silent once ``caught`` holds a signal (what an abandoned solve prints is noise)."""

    def __init__(self, stream, caught: list[int]):
        self._stream, self._caught = stream, caught

    def write(self, text: str) -> int:
        return len(text) if self._caught or self._stream is None else self._stream.write(text)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _block():
    """Block the guarded signals (where the platform can); returns the mask to restore."""
    return signal.pthread_sigmask(signal.SIG_BLOCK, _GUARDED) if hasattr(signal, "pthread_sigmask") else None


def _unblock(mask) -> None:
    if mask is not None:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


@contextlib.contextmanager
def solver_interrupts(stop_solver: bool = True) -> Iterator[None]:
    """Around a call into a compiled solver: a signal that arrives meanwhile is raised when the call returns,
    through the handler that was in place before, so it ends the command (and the solve's result is never used).

    CasADi's solvers check Python's signals between iterations, but a raised ``KeyboardInterrupt`` only makes
    them stop and return a failed solve (the exception is swallowed); with ``stop_solver`` the guard's handler
    raises, so the solver stops at its next check. Crocoddyl's Python callbacks must never raise (boost::python
    aborts the process): with ``stop_solver=False`` the handler only records the signal, and the solver's
    iteration callback stops it when :func:`interrupt_pending`. The signals are blocked while the handlers are
    swapped, so none is lost between them. Outside the main thread, or for a signal that is ignored, nothing
    changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    armed = [True]  # False once the solve has returned: a late signal is only recorded, then redelivered below

    def handler(signum, frame):
        caught.append(signum)
        _caught.append(signum)
        note_signal(signum)
        if stop_solver and armed[0] and len(caught) == 1:
            raise KeyboardInterrupt

    mask = _block()
    try:
        previous = {sig: signal.signal(sig, handler) for sig in _GUARDED if _guarded(sig)}
        outer, stderr = list(_caught), sys.stderr
        _caught.clear()
        sys.stderr = _MutedAfter(stderr, caught)  # CasADi prints the swallowed "KeyboardInterrupt" there
    finally:
        _unblock(mask)
    try:
        yield
    finally:
        try:
            armed[0] = False  # a signal raised here must not skip the restoration below
        finally:
            _block()
            try:
                sys.stderr = stderr
                for sig, old in previous.items():
                    signal.signal(sig, old)
                _caught[:] = outer
            finally:
                _unblock(mask)
        if caught:
            _redeliver(caught[0], previous[caught[0]])
