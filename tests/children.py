"""Child processes in tests: whether every one a test started has ended."""

import multiprocessing
import time


def children_gone(within: float = 5.0) -> bool:
    """No child process left alive: each was ended; on a loaded machine the kernel may take a moment to reap a
    killed one, so this waits up to ``within`` seconds."""
    deadline = time.monotonic() + within
    while multiprocessing.active_children():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True
