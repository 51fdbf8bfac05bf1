"""Another process holding a folder, as a running reachirl command holds it (``reachirl.io.hold_folder``, or
``reading_folder`` with ``shared``), for the tests of commands refused while it runs; and whether a folder is free."""

import contextlib
import subprocess
import sys

_HOLD = (
    "import fcntl, os, sys, time; fcntl.flock(os.open(sys.argv[1], os.O_RDONLY), fcntl.{lock}); "
    "print(1, flush=True); time.sleep(120)"
)
_TRY = "import fcntl, os, sys; fcntl.flock(os.open(sys.argv[1], os.O_RDONLY), fcntl.LOCK_EX | fcntl.LOCK_NB)"


@contextlib.contextmanager
def held_elsewhere(folder, shared: bool = False):
    """``folder`` locked by another process for the block (exclusively: a command writing into it; ``shared``: a
    command reading it); the lock goes with that process, killed at the end."""
    code = _HOLD.format(lock="LOCK_SH" if shared else "LOCK_EX")
    holder = subprocess.Popen([sys.executable, "-c", code, str(folder)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "1"
        yield
    finally:
        holder.kill()
        holder.wait()


def is_free(folder) -> bool:
    """Whether another process could lock ``folder`` for writing now."""
    return subprocess.run([sys.executable, "-c", _TRY, str(folder)]).returncode == 0
