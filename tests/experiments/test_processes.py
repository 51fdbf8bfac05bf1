"""Local worker processes: they run what they are given after their own set-up, and are ended at once."""

import concurrent.futures as cf
import os
import time

from children import children_gone
from reachirl.experiments.processes import local_executor, stop_workers


def test_a_worker_runs_its_setup_then_its_tasks():
    ex = local_executor(1, 4.0, then=os.getpid)  # any module-level function: run once at start
    try:
        assert ex.submit(os.getppid).result(timeout=60) == os.getpid()
    finally:
        stop_workers(ex)


def test_stopping_ends_a_busy_worker_at_once():
    ex = local_executor(2, 4.0)
    futures = [ex.submit(time.sleep, 60) for _ in range(3)]
    while not any(f.running() for f in futures):
        time.sleep(0.05)
    t0 = time.perf_counter()
    stop_workers(ex)
    assert time.perf_counter() - t0 < 10 and children_gone()
    # not started: never runs (cancelled, or, if the pool had already queued it for a worker, failed with the pool)
    last = futures[-1]
    assert last.cancelled() or isinstance(last.exception(timeout=10), cf.process.BrokenProcessPool)
