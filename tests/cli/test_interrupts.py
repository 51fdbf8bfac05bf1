"""`reproduce` under Ctrl-C, SIGTERM and SIGKILL, through the console script: it ends within seconds (130 on
Ctrl-C, 143 on SIGTERM), keeps its finished units, leaves no worker process behind, and a rerun after kills at
seeded random times gives tables byte-identical to an uninterrupted run, with no temporary file left."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from recordings import preprocess, synth

pytestmark = pytest.mark.slow

REACHIRL = str(Path(sys.executable).with_name("reachirl"))
ARGS = [
    "--nodes",
    "40",
    "--max-iter",
    "10",
    "--sections",
    "1",
    "6",
    "--postures",
    "P1",
    "P2",
    "P3",
    "--workers",
    "2",
    "--no-progress",
]


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("interrupts")
    return preprocess(synth(d / "syn", ("P1", "P2", "P3"), trials=3), d / "trials.npz")


@pytest.fixture(scope="module")
def reference(data, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("reference")
    p = subprocess.run(
        [REACHIRL, "reproduce", "--data", str(data), "--out", str(out), *ARGS],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert p.returncode == 0, p.stderr
    return out


# A run long enough to be interrupted mid-way whatever the machine: bilevel units of 400 full-size DOC solves
# (a few seconds each), beside MO-IRL ones (MO-IRL fits can end within a second)
LONG_ARGS = [
    "--nodes",
    "100",
    "--max-iter",
    "10",
    "--sections",
    "1",
    "6",
    "--postures",
    "P1",
    "P2",
    "P3",
    "--method",
    "bilevel",
    "moirl",
    "--workers",
    "2",
    "--no-progress",
]


def _default_sigint() -> None:
    # Ctrl-C reaches a foreground process; a background job of a non-interactive shell (a CI script started
    # with `&`) inherits SIGINT ignored, and Python then never raises KeyboardInterrupt: restore the default
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(data: Path, out: Path, args=ARGS) -> psutil.Popen:
    return psutil.Popen(
        [REACHIRL, "reproduce", "--data", str(data), "--out", str(out), *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_default_sigint,
    )


def _wait_for_workers(p: psutil.Popen, n: int = 2, timeout: float = 60.0) -> list[psutil.Process]:
    """The worker processes once ``n`` run (``[]`` if the run ends first)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        try:
            kids = [c for c in p.children(recursive=True) if "spawn_main" in " ".join(c.cmdline())]
        except psutil.NoSuchProcess:
            kids = []
        if len(kids) >= n or p.poll() is not None:
            return kids
        time.sleep(0.2)
    pytest.fail("the workers never started")


def _gone(procs: list[psutil.Process], timeout: float) -> bool:
    _, alive = psutil.wait_procs(procs, timeout=timeout)
    return not alive


def _no_temporaries(out: Path) -> None:
    assert not [f for f in out.rglob(".*")], "temporary files left"


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupt_ends_quickly_keeps_units_and_workers(data, tmp_path, sig, code):
    out = tmp_path / "run"
    p = _start(data, out, LONG_ARGS)
    workers = _wait_for_workers(p)
    time.sleep(3.0)  # mid-run: some units done, others running
    assert p.poll() is None, "the run ended before the signal: the test would test nothing"
    t0 = time.monotonic()
    p.send_signal(sig)
    rc = p.wait(timeout=30)
    assert time.monotonic() - t0 < 5.0, "took too long to stop"
    err = p.stderr.read()
    assert rc == code, err
    assert ("interrupted" if sig == signal.SIGINT else "terminated") in err
    assert "Traceback" not in err, err
    assert _gone(workers, 5.0), "workers left running"
    _no_temporaries(out)


def test_sigkill_of_the_main_process_leaves_no_worker(data, tmp_path):
    p = _start(data, tmp_path / "run", LONG_ARGS)
    workers = _wait_for_workers(p)
    time.sleep(1.0)
    p.kill()
    p.wait(timeout=10)
    assert _gone(workers, 5.0), "orphaned workers"


def test_kills_at_random_times_then_rerun_give_the_same_tables(data, reference, tmp_path):
    out = tmp_path / "run"
    rng = random.Random(2024)
    for _ in range(3):
        p = _start(data, out)
        workers = _wait_for_workers(p, n=1)
        time.sleep(rng.uniform(0.5, 6.0))
        try:
            p.kill()
        except psutil.NoSuchProcess:  # it finished first
            pass
        p.wait(timeout=10)
        assert _gone(workers, 5.0), "orphaned workers"  # they die with their parent
    rerun = subprocess.run(
        [REACHIRL, "reproduce", "--data", str(data), "--out", str(out), *ARGS],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert rerun.returncode == 0, rerun.stderr
    for name in ("table.csv", "table.md"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    _no_temporaries(out)
    assert sorted(os.listdir(out / "units")) == sorted(os.listdir(reference / "units"))
