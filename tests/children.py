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


def interrupted_while_syncing(argv: list, temporary: str, marker, folder, timeout: float = 120.0) -> tuple[int, str]:
    """Run ``reachirl ARGV`` in a child whose sync of an atomic write's temporary (``temporary``: a predicate's
    source on its ``path``, such as ``"path.name.startswith('.out.json.')"``) never returns, swallowing every signal
    as compiled code can; once it is there (``marker`` touched) and a hidden temporary is in ``folder``, send
    SIGINT. Returns the child's exit code and its stderr."""
    import signal
    import subprocess
    import sys
    from pathlib import Path

    script = (
        "import sys, time\n"
        "from pathlib import Path\n"
        "from reachirl import io\n"
        "from reachirl.cli import main\n"
        "sync = io._fsync\n"
        "def stuck(path):\n"
        f"    if {temporary}:\n"
        f"        Path({str(marker)!r}).touch()\n"
        "        for _ in range(600):  # a minute, whatever the signals\n"
        "            try:\n"
        "                time.sleep(0.1)\n"
        "            except KeyboardInterrupt:\n"
        "                pass\n"
        "    sync(path)\n"
        "io._fsync = stuck\n"
        f"sys.exit(main({[str(a) for a in argv]!r}))\n"
    )
    p = subprocess.Popen(
        [sys.executable, "-c", script],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a background job inherits SIGINT ignored
    )
    try:
        deadline = time.monotonic() + timeout
        while not Path(marker).exists() and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert Path(marker).exists(), p.stderr.read() if p.poll() is not None else "the write was never reached"
        assert [f.name for f in Path(folder).glob(".*") if f.is_file()], "no temporary: the test would test nothing"
        p.send_signal(signal.SIGINT)
        rc = p.wait(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    return rc, p.stderr.read()
