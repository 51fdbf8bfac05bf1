"""A worker killed as it runs (SIGKILL, or the OOM killer), for the tests of what a run says and keeps then."""

import os
import signal


def killed(*args, **kwargs):
    """Put in place of what a (spawned) worker is given to run: the worker process dies at once."""
    os.kill(os.getpid(), signal.SIGKILL)
