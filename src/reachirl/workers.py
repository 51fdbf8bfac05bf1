"""Worker processes that die with the process that started them, even a SIGKILLed one (the units', the figures'
and ``synth``'s generation workers): an orphan would wait for work forever, holding its parent's output open."""

from __future__ import annotations

import os
import signal
import threading
import time

__all__ = ["die_with_parent"]


def die_with_parent(parent_pid: int) -> None:
    """End this worker when its parent ``parent_pid`` dies: Linux's parent-death signal, and everywhere else (or if
    the parent died before it was set) a thread polling the parent's id."""
    try:  # Linux: SIGKILL this process when the parent dies
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass

    def watch() -> None:
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(1.0)

    threading.Thread(target=watch, daemon=True, name="reachirl-parent-watch").start()
