"""Run the protocol's units in local processes or on a Dask cluster, with atomic checkpoints.

Each unit's result goes to ``OUT/units/<key>.json`` (with its predictions in ``<key>.npz``), written atomically
by the coordinating process as soon as the unit finishes: the NPZ first, then the JSON, which marks the unit
done. A rerun into the same folder reuses every unit whose JSON carries the same fingerprint (the unit's
parameters and trials), so killing a run loses only the units in progress.

Units are pure functions of their inputs (:func:`reachirl.experiments.protocol.run_unit`), so local processes,
the in-process path (``workers=1``) and Dask give the same numbers.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import contextvars
import logging
import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import hold_folder, remove_temporaries
from .processes import WorkersAhead, check_entry_point_guarded, local_executor, stop_workers, worker_died
from .protocol import Split, Unit
from .results import RunResult, RunSummary, is_table_unit, load_unit, load_unit_arrays, save_unit, unit_paths
from .truth_solves import run_unit_and_truth

__all__ = [
    "RunResult",
    "RunSummary",
    "UnitWorkers",
    "load_unit",
    "load_unit_arrays",
    "reproduce",
    "run_units",
    "unit_paths",
]

log = logging.getLogger(__name__)


def clean_stale_temporaries(out_dir: Path) -> list[Path]:
    """Remove the temporary files of atomic writes (``.<name>.<random>.tmp`` or ``….png``) that a killed run
    left in ``out_dir``, ``units/``, ``figures/``, ``models/`` and each unit's ``predictions/<key>/``. Returns what
    was removed."""
    exports = sorted(p for p in (out_dir / "predictions").glob("*") if p.is_dir())
    folders = (out_dir, out_dir / "units", out_dir / "figures", out_dir / "models", *exports)
    removed = [f for folder in folders for f in remove_temporaries(folder)]
    if removed:
        log.info("removed %d temporary file(s) left by an interrupted run", len(removed))
    return removed


#: memory (address space) of one local worker process, GB; REACHIRL_UNIT_MEMORY_GB overrides it
UNIT_MEMORY_GB = 8.0
#: wall-clock time of one unit in a local worker, s; REACHIRL_UNIT_TIMEOUT_S overrides it (a full-size unit
#: takes minutes; a pathological one ran for 40 minutes and 16 GB before the inputs were bounded)
UNIT_TIMEOUT_S = 4 * 3600


_UNIT: contextvars.ContextVar[str | None] = contextvars.ContextVar("reachirl_unit", default=None)


class _NamingUnit(logging.Filter):
    """Prefixes each log record with the unit being run where it was logged (:data:`_UNIT`, per thread and task:
    Dask runs several units at once in one worker's threads), once, however many handlers it passes."""

    def filter(self, record: logging.LogRecord) -> bool:
        key = _UNIT.get()
        if key is not None and getattr(record, "reachirl_unit", None) is None:
            record.reachirl_unit = key
            record.msg = f"{key.replace('%', '%%') if record.args else key}: {record.msg}"
        return True


_NAMING = _NamingUnit()


@contextlib.contextmanager
def naming_unit(key: str):
    """Within it, every log message (e.g. a failed solve) logged by this thread names the unit
    ``key``: several units log to the same stderr, in workers whose messages reach it through Python's
    last-resort handler. The filter stays on the handlers; outside a unit it changes nothing."""
    for h in {*logging.getLogger().handlers, logging.lastResort}:
        if h is not None:
            h.addFilter(_NAMING)  # once: a Filterer keeps a filter once
    token = _UNIT.set(key)
    try:
        yield
    finally:
        _UNIT.reset(token)


def run_named_unit(unit: Unit, split: Split, job: Mapping | None = None) -> dict:
    """:func:`~reachirl.experiments.truth_solves.run_unit_and_truth` with its log messages naming the unit. The
    fit's own warnings are not logged: they are in the unit's result (``warnings``), which reaches the user from
    the checkpoint whether the unit ran here, in a worker or on Dask, or was reused (``reproduce`` lists them at
    the end, ``report.md`` in its notes)."""
    from ..irl.base import caller_shows_fit_warnings

    with naming_unit(unit.key), caller_shows_fit_warnings():
        return run_unit_and_truth(unit, split, job)


class UnitTimeoutError(Exception):
    """A unit ran longer than its time limit."""


def _run_unit_bounded(unit: Unit, split: Split, timeout_s: float, truth_job=None) -> dict:
    """:func:`run_unit` (and its solves under the true weights, with ``truth_job``:
    :func:`~reachirl.experiments.truth_solves.run_unit_and_truth`) in a local worker, stopped by SIGALRM after
    ``timeout_s``: :class:`UnitTimeoutError`, whatever exception the unit's code turned the alarm's into."""
    import signal

    said = f"unit {unit.key} ran longer than {timeout_s:g} s"
    expired = []

    def expire(signum, frame):
        expired.append(True)
        raise UnitTimeoutError(said)

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        return run_named_unit(unit, split, truth_job)
    except Exception:
        if expired:  # the alarm's error, or one a library raised in its place (numpy's "'axis' must be None, an
            # integer or a tuple of integers", seen in a test)
            raise UnitTimeoutError(said) from None
        raise
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _env_float(name: str, default: float, least: float = 0.0) -> float:
    try:
        v = float(os.environ.get(name, default))
    except ValueError:
        raise InputError(f"environment variable {name}={os.environ[name]!r}: expected a number") from None
    if not (v > 0 and v >= least and v < float("inf")):
        at_least = f", at least {least:g}" if least else ""
        raise InputError(f"environment variable {name}={v:g}: expected a positive number{at_least}")
    return v


#: the smallest memory cap (GB) a worker can work under: Python, NumPy, SciPy and CasADi's compiled solvers take
#: most of it before the first unit (measured: under 0.5 GB the imports and a small fit fail; under 1 GB they run)
MIN_UNIT_MEMORY_GB = 1.0


def _unit_memory_gb() -> float:
    return _env_float("REACHIRL_UNIT_MEMORY_GB", UNIT_MEMORY_GB, MIN_UNIT_MEMORY_GB)


def unit_executor(workers: int) -> cf.ProcessPoolExecutor:
    """Local worker processes for units (and `sensitivity`'s refits), each capped at `REACHIRL_UNIT_MEMORY_GB`."""
    return local_executor(workers, _unit_memory_gb())


def _unit_ready(n_nodes: int) -> None:
    """A unit worker's start: the modules a unit runs and the DOC solvers of ``n_nodes`` intervals."""
    from ..doc.casadi import preload
    from .truth_solves import run_unit_and_truth  # noqa: F401 - the modules a unit runs

    preload(n_nodes)


class UnitWorkers(WorkersAhead):
    """The units' ``workers`` local processes, started before the data are loaded (:meth:`start`), each importing
    what a unit runs and loading the DOC solvers of ``n_nodes`` intervals meanwhile; :func:`run_units` takes them
    over (``ahead``). A ``with`` block ends them on leaving if no unit ran (an error, Ctrl-C, every unit reused)."""

    def __init__(self, workers: int, n_nodes: int) -> None:
        super().__init__(workers, _unit_memory_gb, _unit_ready, int(n_nodes))


def _dask_client(address: str):
    try:
        from dask.distributed import Client
    except ImportError as e:  # pragma: no cover
        raise InputError(f"--scheduler needs dask.distributed ({e})") from None
    client = Client.__new__(Client)  # a handle on it even when its connection fails: closed here, not at exit
    try:
        client.__init__(address, timeout="15s", set_as_default=False)
        return client
    except Exception as e:  # OSError, TimeoutError, ValueError, a protocol whose package is missing, ...
        # a client left to the garbage collector closes at exit: 30 s later, with a traceback on stderr
        with contextlib.suppress(Exception):
            client.close(timeout=5)
        raise InputError(
            f"cannot connect to the Dask scheduler ({type(e).__name__}: {str(e)[:200]})", address
        ) from None


def run_units(
    units: Sequence[Unit],
    splits: dict[str, Split],
    out_dir: str | Path,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    max_units: int | None = None,
    on_start: Callable[[int, int], None] | None = None,
    on_done: Callable[[str, dict, bool], None] | None = None,
    truth_jobs: Mapping[str, dict] | None = None,
    ahead: WorkersAhead | None = None,
) -> RunSummary:
    """Run (or reuse) every unit; ``splits`` maps a unit's ``split_key`` (its posture, or (posture, training
    subject) for an all-pairs unit) to its :class:`Split`. ``truth_jobs`` maps the keys of the units whose workers
    also solve under the true weights to what they solve (:func:`reachirl.experiments.truth_solves.truth_jobs`):
    they do it after the unit, and the checkpoint keeps it. ``ahead``: local workers started before the run
    (:class:`UnitWorkers`), which run the units in place of new ones.

    ``on_start(n_total, n_reused)`` is called once, ``on_done(key, result, reused)`` per unit. ``max_units``
    stops after that many *new* units (for tests and for splitting a long run).
    """
    out_dir = Path(out_dir)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    results: dict[str, dict] = {}
    todo: list[tuple[Unit, str]] = []
    reused: list[str] = []
    for u in units:
        fp = u.fingerprint(splits[u.split_key])
        res = load_unit(out_dir, u.key, fp)
        if res is not None:
            results[u.key] = res
            reused.append(u.key)
        else:
            todo.append((u, fp))
    limit = len(todo) if max_units is None else max(0, min(int(max_units), len(todo)))
    # connected before on_start (which clears an earlier run's outputs and writes run.toml): a scheduler that cannot
    # be reached changes nothing on disk
    client = _dask_client(scheduler) if scheduler is not None and limit > 0 else None
    try:
        if on_start:
            on_start(len(units), len(reused))
        for k in reused:
            if on_done:
                on_done(k, results[k], True)
    except BaseException:
        if client is not None:
            client.close()
        raise
    stopped = limit < len(todo)
    todo = todo[:limit] if scheduler is None and workers <= 1 else todo
    computed: list[str] = []

    fingerprints = {u.key: fp for u, fp in todo}
    truth_jobs = dict(truth_jobs or {})

    def finish(payload: dict) -> None:
        # the coordinator's fingerprint: a remote worker may hash other source files
        payload["result"]["fingerprint"] = fingerprints[payload["result"]["key"]]
        if isinstance(payload["result"].get("model_info"), dict):  # as the unit's models/<key>.json names it
            payload["result"]["model_info"]["run"] = str(out_dir.resolve())
        res = save_unit(out_dir, payload)
        results[res["key"]] = res
        computed.append(res["key"])
        if on_done:
            on_done(res["key"], res, False)

    if not todo or limit == 0:
        return RunSummary(results, computed, reused, stopped)
    if scheduler is None and workers <= 1:
        import threading

        timeout = _env_float("REACHIRL_UNIT_TIMEOUT_S", UNIT_TIMEOUT_S)
        bounded = threading.current_thread() is threading.main_thread()  # SIGALRM needs the main thread
        for u, _ in todo:
            try:
                job = truth_jobs.get(u.key)
                payload = (
                    _run_unit_bounded(u, splits[u.split_key], timeout, job)
                    if bounded
                    else run_named_unit(u, splits[u.split_key], job)
                )
            except UnitTimeoutError as e:
                raise InputError(
                    f"{e}; finished units are kept (rerun to resume), raise the limit with REACHIRL_UNIT_TIMEOUT_S",
                    out_dir,
                ) from None
            finish(payload)
    elif scheduler is None:
        timeout = _env_float("REACHIRL_UNIT_TIMEOUT_S", UNIT_TIMEOUT_S)
        ex = (ahead.take() if ahead is not None else None) or unit_executor(min(workers, len(todo)))
        try:
            futures = {
                ex.submit(_run_unit_bounded, u, splits[u.split_key], timeout, truth_jobs.get(u.key)): u.key
                for u, _ in todo
            }
            for f in cf.as_completed(futures):
                try:
                    payload = f.result()
                except UnitTimeoutError as e:
                    raise InputError(
                        f"{e}; finished units are kept (rerun to resume), raise the limit with REACHIRL_UNIT_TIMEOUT_S",
                        out_dir,
                    ) from None
                except MemoryError:
                    raise InputError(
                        f"unit {futures[f]} needed more than the worker's memory limit; raise it "
                        f"with REACHIRL_UNIT_MEMORY_GB",
                        out_dir,
                    ) from None
                except cf.process.BrokenProcessPool:  # killed (SIGKILL, the OOM killer): the run's, not a bug
                    raise worker_died(
                        f"running unit {futures[f]}", "finished units are kept (rerun to resume)", out_dir
                    ) from None
                finish(payload)
                if len(computed) >= limit:
                    break
        except BaseException:
            stop_workers(ex)  # Ctrl-C, SIGTERM or an error: end now, keep the finished units
            raise
        else:
            stop_workers(ex)
    else:
        from dask.distributed import as_completed

        try:
            futures = [
                client.submit(
                    run_named_unit,
                    u,
                    splits[u.split_key],
                    truth_jobs.get(u.key),
                    key=f"reachirl-{u.key}-{fp}",
                    pure=False,
                )
                for u, fp in todo
            ]
            try:
                with _dask_reconnects_unlogged():
                    for f in as_completed(futures, loop=client.loop):
                        finish(f.result())
                        if len(computed) >= limit:
                            break
            finally:
                with contextlib.suppress(Exception):  # a scheduler gone: nothing left to cancel
                    client.cancel(futures)
        except Exception as e:
            if client.status == "running" and "scheduler-connection-lost" not in str(e):
                raise
            # the scheduler went away mid-run (ended, restarted, its machine or the network down): a failure of
            # the cluster, not of a unit; the units finished so far are checkpointed
            raise InputError(
                f"lost the connection to the Dask scheduler ({type(e).__name__}); {len(computed)} unit(s) of this "
                "run were finished and are kept: rerun to resume",
                scheduler,
            ) from None
        finally:
            with _dask_reconnects_unlogged():
                client.close()
    return RunSummary(results, computed, reused, stopped)


@contextlib.contextmanager
def _dask_reconnects_unlogged():
    """Within it, the Dask client's own log of its attempts to reconnect to a lost scheduler (a traceback per
    attempt, on stderr) is left out, unless reachirl logs its details (``-v``): the run says in one line that the
    scheduler was lost."""
    if logging.getLogger().isEnabledFor(logging.INFO):
        yield
        return
    dask_log = logging.getLogger("distributed")
    level = dask_log.level
    # Dask logs some of these under a logger named after its module alone ("utils"), which reaches the root's
    # handlers: those are left out by where they were logged
    handlers = {*logging.getLogger().handlers, logging.lastResort} - {None}
    for h in handlers:
        h.addFilter(_not_from_dask)
    dask_log.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        dask_log.setLevel(level)
        for h in handlers:
            h.removeFilter(_not_from_dask)


def _not_from_dask(record: logging.LogRecord) -> bool:
    return "distributed" not in Path(record.pathname).parts


def check_thresholds(units: Sequence[Unit], splits: Mapping, source) -> None:
    """Before any work: each rollout of an observed unit must see trials cut at one onset threshold
    (:func:`~reachirl.doc.observation.common_threshold`), the rollouts grouped as MO-IRL groups them
    (:func:`reachirl.irl.moirl.rollout_groups`); otherwise an :class:`InputError` naming ``source``."""
    from ..doc.observation import common_threshold
    from ..irl.moirl import rollout_groups

    for u in units:
        rollout = dict(u.estimator_options).get("rollout", "per_task")
        if not u.observe or rollout == "per_demo":
            continue
        train = list(splits[u.split_key].train)
        of = rollout_groups(train, rollout)
        for group in ([t for t, g in zip(train, of, strict=True) if g == r] for r in dict.fromkeys(of.tolist())):
            try:
                common_threshold(group)
            except InputError as e:
                subjects = ", ".join(dict.fromkeys(t.subject for t in group))
                postures = ", ".join(dict.fromkeys(t.posture for t in group))
                raise InputError(f"{subjects} {postures}: {e.reason}", source) from None


def reproduce(
    dataset,
    config,
    out_dir: str | Path,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    max_units: int | None = None,
    data_s: float = 0.0,
    on_start: Callable[[int, int], None] | None = None,
    on_done: Callable[[str, dict, bool], None] | None = None,
    out_option: str = "out_dir",
    ahead: WorkersAhead | None = None,
) -> RunResult:
    """Run (or resume) the whole protocol on ``dataset`` (:class:`~reachirl.experiments.datasets.Dataset`),
    checkpointing each unit under ``out_dir/units/``, and return the :class:`RunResult`: in this process
    (``workers=1``), in ``workers`` local processes, or on the Dask scheduler at ``scheduler``. Nothing
    else is written here: :func:`reachirl.experiments.report.write_outputs` writes the tables, figures and report
    (``result.stopped`` is true when ``max_units`` cut the run short; rerun to finish). ``out_option``: what named
    ``out_dir`` to the caller (the argument; the command line's ``--out``), in the error of a folder that another
    command is writing into. With ``workers`` > 1 (and no ``scheduler``), a main script that calls it from its
    top-level code outside ``if __name__ == "__main__":`` is refused before any work
    (:func:`~reachirl.experiments.processes.check_entry_point_guarded`): each spawned worker would run it again.
    ``ahead``: the local workers, started before the data were loaded (:class:`UnitWorkers`).
    """
    from .pairs import pair_splits, pair_training_subjects
    from .protocol import (
        code_fingerprint,
        make_units,
        resolve_postures,
        resolve_train_subject,
        split_trials,
        transfer_splits,
    )
    from .truth_solves import truth_jobs

    # before anything: a number of workers that is not one failed mid-run, after the output folder was made
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise InputError(
            f"workers must be a number of worker processes, at least 1 (1 runs in this process), got {workers!r}"
        )
    if workers > 1 and scheduler is None:  # spawned workers import the main script again: never a rerun of it
        check_entry_point_guarded()
    trials = list(dataset.trials)
    if not trials:
        raise InputError("no trials to run the protocol on", dataset.source)
    try:  # what the data cannot give the protocol (a posture, a subject, a side) is the data's: named with it
        postures = resolve_postures(trials, config)
        subject = resolve_train_subject(trials, config)
        splits = {p: split_trials(trials, p, config) for p in postures}
        splits.update(pair_splits(trials, postures, config))  # --iscv all-pairs: every other training subject
        if config.posture_transfer:
            splits.update(transfer_splits(splits, postures))
    except InputError as e:
        if e.path is not None:
            raise
        raise InputError(e.reason, dataset.source) from None
    split_sizes = {s: {p: len(splits[p].sets()[s]) for p in postures} for s in ("train", "cv", "iscv")}
    units = [u for u in make_units(postures, config, pair_training_subjects(trials, config)) if u.split_key in splits]
    check_thresholds(units, splits, dataset.source)
    out_dir = Path(out_dir)
    # one run at a time in a folder, from before its first change to it until the process ends (or the command
    # releases it): a second would remove this one's temporaries and outputs and mix its checkpoints with them
    hold_folder(out_dir, out_option)
    clean_stale_temporaries(out_dir)

    def start(total: int, reused: int) -> None:
        # the folder is made once the run starts (its scheduler reached): a run that fails before leaves none
        out_dir.mkdir(parents=True, exist_ok=True)
        hold_folder(out_dir, out_option)
        if on_start:
            on_start(total, reused)

    t0 = time.perf_counter()
    summary = run_units(
        units,
        splits,
        out_dir,
        workers=workers,
        scheduler=scheduler,
        max_units=max_units,
        on_start=start,
        on_done=on_done,
        truth_jobs=truth_jobs(units, splits, getattr(dataset, "truth", None), config.methods[0]),
        ahead=ahead,
    )
    main = {k: r for k, r in summary.results.items() if is_table_unit(r)}
    transfer = {k: r for k, r in summary.results.items() if r["unit"].get("held_out_posture") is not None}
    pairs = {k: r for k, r in summary.results.items() if k not in main and k not in transfer}
    summary = RunSummary(main, summary.computed, summary.reused, summary.stopped_early)
    order = {u.key: i for i, u in enumerate(units)}
    run_info = {
        "code_fingerprints": {m: code_fingerprint(m, config.backend) for m in config.methods},
        "n_units": len(units),
        # in the units' order, not the order the workers finished them in: the same run, the same results.json
        "computed": sorted(summary.computed, key=order.__getitem__),
        "reused": summary.reused,
        "executor": f"dask ({scheduler})"
        if scheduler
        else ("in-process" if workers <= 1 else f"{workers} local processes"),
    }
    return RunResult(
        out_dir=out_dir,
        dataset=dataset,
        config=config,
        postures=postures,
        train_subject=subject,
        split_sizes=split_sizes,
        summary=summary,
        timing={"data_s": data_s, "units_wall_s": time.perf_counter() - t0},
        run_info=run_info,
        pairs=pairs,
        transfer=transfer,
    )
