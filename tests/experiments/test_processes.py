"""Local worker processes: they run what they are given after their own set-up, and are ended at once."""

import concurrent.futures as cf
import functools
import os
import time

import pytest

from children import children_gone
from reachirl.errors import InputError
from reachirl.experiments.processes import local_executor, stop_workers


def test_a_worker_runs_its_setup_then_its_tasks():
    ex = local_executor(1, 4.0, then=os.getpid)  # any module-level function: run once at start
    try:
        assert ex.submit(os.getppid).result(timeout=60) == os.getpid()
    finally:
        stop_workers(ex)


def test_a_worker_whose_setup_fails_says_why_in_one_line(capfd):
    # its set-up raised in the pool's initializer: a traceback on stderr ("Exception in initializer"), then a pool
    # broken as if the worker had been killed ("a worker process died (killed, or out of memory)")
    ex = local_executor(1, 4.0, then=functools.partial(int, "seven"))
    try:
        for _ in range(2):  # every task says it, the worker stays
            with pytest.raises(InputError) as e:
                ex.submit(os.getpid).result(timeout=60)
            assert str(e.value) == (
                "a worker process could not start (ValueError: invalid literal for int() with base 10: 'seven')"
            )
    finally:
        stop_workers(ex)
    assert "Traceback" not in capfd.readouterr().err


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


def test_stopping_ends_the_pools_manager_thread_and_its_wakeup_pipe():
    # concurrent.futures' exit hook writes to the manager thread's wake-up pipe without its lock; a thread still
    # closing that pipe at exit made the write fail with an OSError traceback after "interrupted" (Python 3.11)
    for _ in range(5):
        ex = local_executor(2, 4.0)
        futures = [ex.submit(time.sleep, 60) for _ in range(3)]
        while not any(f.running() for f in futures):
            time.sleep(0.05)
        manager = ex._executor_manager_thread
        stop_workers(ex)
        assert not manager.is_alive()
        wakeup = cf.process._threads_wakeups.get(manager)
        assert wakeup is None or wakeup._closed, "the exit hook skips a closed pipe"


SCRIPT = """import sys

from reachirl.experiments import datasets
from reachirl.experiments.protocol import ProtocolConfig
from reachirl.experiments.runner import reproduce


def run():
    toy = datasets.toy(n_subjects=2, postures=("P2",), n_trials=3, n_nodes=20, seed=3)
    cfg = ProtocolConfig(sections=(1,), n_train=2, n_nodes=20, max_iter=1)
    reproduce(toy, cfg, sys.argv[1], workers=2, max_units=1)
    print("done")


"""


def _run_script(path, out):
    import subprocess
    import sys
    from pathlib import Path

    import reachirl

    env = {**os.environ, "PYTHONPATH": str(Path(reachirl.__file__).parents[1]), "OMP_NUM_THREADS": "1"}
    return subprocess.run(
        [sys.executable, str(path), str(out)], capture_output=True, text=True, env=env, timeout=600, check=False
    )


def test_a_script_starting_workers_outside_the_main_guard_is_told_to_protect_it(tmp_path):
    """A script calling reproduce(..., workers=2) from its top-level code: each spawned worker imported the script
    again, ran the call again and failed, and the user was told that a worker process died (killed, or out of
    memory). Refused now before any worker is started, naming the script's line and what to do; a script whose
    entry point is under `if __name__ == "__main__":` runs."""
    script = tmp_path / "unguarded.py"
    script.write_text(SCRIPT + "run()\n")
    res = _run_script(script, tmp_path / "out")
    assert res.returncode == 1 and "worker process died" not in res.stderr, res.stderr
    line = SCRIPT.count("\n") + 1  # the call to run()
    assert res.stderr.strip().splitlines()[-1] == (
        f"reachirl.errors.InputError: {script}: line {line} starts local worker processes from the script's top-level "
        'code, outside `if __name__ == "__main__":`; each worker imports the script again and would run it again. '
        'Put the script\'s entry point under `if __name__ == "__main__":`, or use workers=1 (runs in this process)'
    )
    assert not (tmp_path / "out").exists()  # before any work
    script = tmp_path / "guarded.py"
    script.write_text(SCRIPT + 'if __name__ == "__main__":\n    run()\n')
    res = _run_script(script, tmp_path / "out")
    assert res.returncode == 0 and res.stdout.strip() == "done", res.stderr
    assert list((tmp_path / "out" / "units").glob("*.json"))


def test_only_a_call_from_unguarded_top_level_code_is_refused(tmp_path, monkeypatch):
    """The check reads the main script's top-level statement that led to the call: inside an `if` testing
    __name__ it passes; anywhere else (a bare call, a `with` block) it is refused, naming the script. A package's
    __main__ (`python -m reachirl reproduce --workers 2`), which spawn never imports again, passes."""
    import sys
    import types

    import pytest

    from reachirl.errors import InputError
    from reachirl.experiments.processes import check_entry_point_guarded

    def run_as_main(source: str, spec: str | None = None) -> None:
        path = tmp_path / "script.py"
        path.write_text(source)
        module = types.ModuleType("__main__")
        module.__file__ = str(path)
        module.__spec__ = None if spec is None else types.SimpleNamespace(name=spec)
        module.check = check_entry_point_guarded
        monkeypatch.setitem(sys.modules, "__main__", module)
        exec(compile(source, str(path), "exec"), vars(module))

    run_as_main('x = 1\nif __name__ == "__main__":\n    check()\n')
    run_as_main('def main():\n    check()\n\n\nif __name__ == "__main__":\n    main()\n')
    run_as_main("check()\n", spec="reachirl.__main__")  # python -m reachirl: a worker never imports it again
    with pytest.raises(InputError, match=r"script\.py: line 1 starts"):  # python -m a module: imported again
        run_as_main("check()\n", spec="mymodule")
    with pytest.raises(InputError, match=r"script\.py: line 4 starts local worker processes .* or use workers=1"):
        run_as_main("import contextlib\n\nwith contextlib.nullcontext():\n    check()\n")
    with pytest.raises(InputError, match=r"script\.py: line 3 starts local worker processes .* or use n=1"):
        run_as_main('def main():\n    check("n")\nmain()\n')
