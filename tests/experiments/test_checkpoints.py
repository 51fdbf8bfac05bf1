"""Checkpoints of `reproduce` are verified before reuse: a damaged or mismatched unit is recomputed, never
reused, and temporary files left by a killed run are removed. Results never hold NaN or a bare null."""

import json
import re

import numpy as np
import pytest

from reachirl import ReachingTask, solve_doc
from reachirl.cli import main
from reachirl.data.trial import save_trials, trial_from_solution
from reachirl.experiments.runner import load_unit
from worker_deaths import killed

FEATURE_SCALE = np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])
KEY = "moirl-P2-s1"


@pytest.fixture(scope="module")
def trials_file(tmp_path_factory, arm):
    rng = np.random.default_rng(1)
    w = np.full((1, 7), 0.3) / FEATURE_SCALE
    trials = []
    for i in range(3):
        q0 = np.deg2rad([-20.0, 90.0]) + np.deg2rad(rng.normal(0, 2, 2))
        task = ReachingTask(arm, q0, 0.9 * arm.length, 0.7, n_nodes=20)
        sol = solve_doc(task, w)
        trials.append(trial_from_solution(sol, arm, task.target_x, subject="S1", posture="P2", trial_id=str(i)))
    path = tmp_path_factory.mktemp("ckpt") / "trials.npz"
    save_trials(path, trials)
    return path


def _reproduce(trials_file, out) -> dict:
    argv = [
        "reproduce",
        "--quick",
        "--data",
        str(trials_file),
        "--workers",
        "1",
        "--nodes",
        "20",
        "--max-iter",
        "1",
        "--sections",
        "1",
        "--n-train",
        "2",
        "--no-progress",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    return json.loads((out / "results.json").read_text())


@pytest.fixture(scope="module")
def first_run(trials_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    results = _reproduce(trials_file, out)
    assert results["run"]["computed"] == [KEY]
    return out, (out / "table.csv").read_bytes(), (out / "table.md").read_bytes()


def _nulls(obj, path=""):
    if isinstance(obj, dict):
        out = []
        for k, v in obj.items():
            if v is None and k in ("mean", "std", "summary") and "no_data" not in obj:
                out.append(f"{path}/{k}")
            out += _nulls(v, f"{path}/{k}")
        return out
    if isinstance(obj, list):
        return [p for i, v in enumerate(obj) for p in _nulls(v, f"{path}/{i}")]
    return []


def test_empty_splits_say_no_data_with_a_reason(first_run):
    import re

    out, _, table_md = first_run
    written = sorted(f for f in out.rglob("*") if f.is_file())
    assert {f.name for f in written} >= {"results.json", "table.csv", "table.md", "report.md", f"{KEY}.json"}
    for f in written:  # every result file the run wrote
        if f.suffix in (".json", ".csv", ".md"):
            text = f.read_text()
            assert not re.search(r"(?<![A-Za-z])(nan|NaN|inf|Infinity)(?![A-Za-z])", text), f
            if f.suffix == ".json":
                assert not _nulls(json.loads(text)), (f, _nulls(json.loads(text)))
        elif f.suffix == ".npz":
            with np.load(f, allow_pickle=False) as z:
                assert all(np.all(np.isfinite(z[k])) for k in z.files if z[k].dtype.kind == "f"), f
    results = json.loads((out / "results.json").read_text())
    iscv = results["tables"]["moirl"]["P2"]["iscv"]["1"]["q"]
    assert iscv["mean"] is None and iscv["n"] == 0
    assert iscv["no_data"].startswith("no inter-subject trials: the data has no other subject")
    assert "— means no data: no inter-subject trials" in table_md.decode()
    import csv

    rows = list(csv.DictReader((out / "table.csv").read_text().splitlines()))
    assert rows and all(r["iscv_1_mean"] == "" and r["iscv_1_n"] == "0" for r in rows)
    assert all("iscv: no inter-subject trials: the data has no other subject" in r["no_data"] for r in rows)


@pytest.mark.parametrize(
    ("damage", "what"),
    [
        (lambda js, npz: npz.write_bytes(npz.read_bytes()[: len(npz.read_bytes()) // 2]), "truncated NPZ"),
        (lambda js, npz: npz.write_bytes(b"garbage"), "garbage NPZ"),
        (lambda js, npz: npz.unlink(), "missing NPZ"),
        (lambda js, npz: js.write_text("[]"), "JSON holding []"),
        (lambda js, npz: js.write_text("null"), "JSON holding null"),
        (lambda js, npz: js.write_text('{"key": "moirl-P2-s1", "fing'), "truncated JSON"),
        (
            lambda js, npz: js.write_text(js.read_text().replace('"npz_sha256": "', '"npz_sha256": "0')),
            "NPZ other than the JSON's",
        ),
    ],
)
def test_a_damaged_checkpoint_is_recomputed(first_run, trials_file, tmp_path, damage, what):
    src, table_csv, table_md = first_run
    out = tmp_path / "run"
    import shutil

    shutil.copytree(src, out)
    js, npz = out / "units" / f"{KEY}.json", out / "units" / f"{KEY}.npz"
    fp = json.loads(js.read_text())["fingerprint"]
    assert load_unit(out, KEY, fp) is not None
    damage(js, npz)
    assert load_unit(out, KEY, fp) is None, what
    (out / "figures" / ".fig3_weights.png.ab3_x9zq.png").write_bytes(b"partial")  # left by a kill
    (out / "units" / f".{KEY}.json.k2j4h5g6.tmp").write_bytes(b"partial")
    results = _reproduce(trials_file, out)
    assert results["run"]["computed"] == [KEY], what
    assert (out / "table.csv").read_bytes() == table_csv
    assert (out / "table.md").read_bytes() == table_md
    assert not [f for f in out.rglob(".*")], "temporary files left"
    assert load_unit(out, KEY, fp) is not None


def test_an_intact_checkpoint_is_reused(first_run, trials_file, tmp_path):
    import shutil

    src, table_csv, _ = first_run
    out = tmp_path / "run"
    shutil.copytree(src, out)
    results = _reproduce(trials_file, out)
    assert results["run"]["reused"] == [KEY] and results["run"]["computed"] == []
    assert (out / "table.csv").read_bytes() == table_csv


def test_a_unit_over_its_time_limit_is_stopped(trials_file, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("REACHIRL_UNIT_TIMEOUT_S", "0.001")
    argv = [
        "reproduce",
        "--quick",
        "--data",
        str(trials_file),
        "--workers",
        "1",
        "--nodes",
        "20",
        "--max-iter",
        "1",
        "--sections",
        "1",
        "--no-progress",
        "--out",
        str(tmp_path / "run"),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith(
        f"unit {KEY} ran longer than 0.001 s; finished units are kept (rerun to resume), "
        "raise the limit with REACHIRL_UNIT_TIMEOUT_S"
    )
    monkeypatch.setenv("REACHIRL_UNIT_TIMEOUT_S", "nan")
    assert main(argv) == 2
    assert "REACHIRL_UNIT_TIMEOUT_S=nan: expected a positive number" in capsys.readouterr().err


def test_a_time_limit_that_a_library_turned_into_its_own_error_is_still_the_time_limit(monkeypatch):
    """The alarm's exception can be raised inside a library that replaces it with its own (numpy's "'axis' must
    be None, an integer or a tuple of integers" made a timed-out unit an internal error, once): after the alarm,
    any error is the time limit; before it, an error stays itself."""
    import time

    from reachirl.experiments import runner
    from reachirl.experiments.protocol import ProtocolConfig, make_units

    unit = make_units(["P2"], ProtocolConfig(sections=(1,)))[0]

    def replaced(unit, split, job):  # a library that catches whatever interrupts it and raises its own error
        try:
            time.sleep(5.0)
        except runner.UnitTimeoutError:
            raise TypeError("'axis' must be None, an integer or a tuple of integers") from None

    monkeypatch.setattr(runner, "run_named_unit", replaced)
    with pytest.raises(runner.UnitTimeoutError, match=rf"unit {unit.key} ran longer than 0.05 s"):
        runner._run_unit_bounded(unit, None, 0.05)

    def broken(unit, split, job):
        raise TypeError("a bug of the unit's own")

    monkeypatch.setattr(runner, "run_named_unit", broken)
    with pytest.raises(TypeError, match="a bug of the unit's own"):
        runner._run_unit_bounded(unit, None, 60.0)


def test_an_interrupted_runs_temporaries_are_removed_wherever_it_writes(tmp_path):
    """Atomic writes' temporaries (``.<name>.<8 random>.<ext>``) that a killed run left, in every folder a run
    writes, are removed; files that only look alike are kept."""
    from reachirl.experiments.runner import clean_stale_temporaries

    left = [
        tmp_path / ".table.csv.ab12cd_3.tmp",
        tmp_path / "units" / ".moirl-P2-s8.json.zz99yy88.tmp",
        tmp_path / "figures" / ".fig2_prediction.png.tnvvlevp.png",
        tmp_path / "models" / ".moirl-P2-s8.json.k2j4h6g8.tmp",
        tmp_path / "predictions" / "moirl-P2-s6" / ".index.csv.agxgukg_.tmp",
    ]
    kept = [tmp_path / "predictions" / "moirl-P2-s6" / "index.csv", tmp_path / "figures" / ".keep", tmp_path / "a.tmp"]
    for f in (*left, *kept):
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text("x")
    assert sorted(clean_stale_temporaries(tmp_path)) == sorted(left)
    assert all(f.exists() for f in kept) and not any(f.exists() for f in left)


def test_a_worker_memory_cap_too_small_to_start_is_refused(tmp_path, monkeypatch, capsys):
    from reachirl.cli import main

    monkeypatch.setenv("REACHIRL_UNIT_MEMORY_GB", "0.01")
    assert main(["reproduce", "--quick", "--workers", "2", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("REACHIRL_UNIT_MEMORY_GB=0.01: expected a positive number, at least 1"), err
    assert len(err.splitlines()) == 1


def test_a_units_log_messages_name_it(caplog):
    """Several units log to one stderr: a fit's warning must say which unit it is about."""
    import logging

    from reachirl.experiments.runner import naming_unit

    log = logging.getLogger("reachirl.irl.moirl")
    with caplog.at_level(logging.WARNING), naming_unit("moirl-P4-s1"):
        log.warning("stopped after one step (merit %.1f %% below w0's)", 21.4)
    log.warning("after the unit")
    assert caplog.messages == ["moirl-P4-s1: stopped after one step (merit 21.4 % below w0's)", "after the unit"]


def test_a_workers_last_resort_names_the_unit(monkeypatch, capsys):
    """In a worker process nothing configures logging: its messages reach stderr by the last-resort handler."""
    import logging

    from reachirl.experiments.runner import naming_unit

    monkeypatch.setattr(logging.root, "handlers", [])
    with naming_unit("moirl-P2-s8"):
        logging.getLogger("reachirl.irl.moirl").warning("no weight samples: a degenerate rollout")
    assert capsys.readouterr().err == "moirl-P2-s8: no weight samples: a degenerate rollout\n"


def test_units_run_in_threads_each_name_their_own_messages(caplog):
    """Dask runs several units at once in one worker's threads: each message names the unit of its thread."""
    import logging
    import threading

    from reachirl.experiments.runner import naming_unit

    log = logging.getLogger("reachirl.irl.moirl")
    inside, done = threading.Barrier(2), threading.Barrier(2)

    def unit(key):
        with naming_unit(key):
            inside.wait()  # both units entered before either logs
            log.warning("from %s", key)
            done.wait()

    with caplog.at_level(logging.WARNING):
        threads = [threading.Thread(target=unit, args=(k,)) for k in ("unit-A", "unit-B")]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert sorted(caplog.messages) == ["unit-A: from unit-A", "unit-B: from unit-B"]


def test_a_killed_unit_worker_is_named_with_its_unit_and_a_rerun_resumes(trials_file, tmp_path, monkeypatch, capsys):
    """It was an internal error (exit 1, 'BrokenProcessPool' or 'a worker process died'): a killed worker is the
    run's circumstance, not a bug."""
    from reachirl.experiments import runner

    monkeypatch.setattr(runner, "_run_unit_bounded", killed)  # what the (spawned) worker is given to run
    out = tmp_path / "run"
    argv = ["reproduce", "--quick", "--data", str(trials_file), "--workers", "2", "--nodes", "20"]
    argv += ["--max-iter", "1", "--sections", "1", "--n-train", "2", "--no-progress", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"reachirl reproduce: error: {out}: a worker process died (killed, or out of memory) while running unit "
        f"{KEY}; finished units are kept (rerun to resume)"
    ]
    monkeypatch.undo()
    assert main(argv) == 0
    assert json.loads((out / "results.json").read_text())["run"]["computed"] == [KEY]


def test_a_killed_figure_worker_is_named_with_its_figure_and_a_rerun_draws_it(
    trials_file, tmp_path, monkeypatch, capsys
):
    """It was an internal error (exit 1, "RuntimeError: a figure worker process died ..."): a killed worker is the
    run's circumstance, said as a unit's worker is."""
    from reachirl.experiments import rendering

    out = tmp_path / "run"
    argv = ["reproduce", "--quick", "--data", str(trials_file), "--workers", "2", "--nodes", "20"]
    argv += ["--max-iter", "1", "--sections", "1", "--n-train", "2", "--no-progress", "--out", str(out)]
    monkeypatch.setattr(rendering, "draw", killed)  # what the (spawned) figure worker is given to draw
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert re.fullmatch(
        rf"reachirl reproduce: error: {re.escape(str(out / 'figures'))}: a worker process died \(killed, or out of "
        r"memory\) while drawing figure fig\w+\.png; the run's results are kept \(rerun to draw it again\)",
        err[0],
    ), err
    assert not (out / "table.csv").exists()  # written last: the run is unfinished
    monkeypatch.undo()
    assert main(argv) == 0
    results = json.loads((out / "results.json").read_text())
    assert results["run"]["computed"] == [] and results["run"]["reused"] == [KEY]  # the units were kept
    assert list((out / "figures").glob("*.png"))


def test_results_list_the_computed_units_in_the_units_order_not_as_workers_finished_them(
    trials_file, tmp_path, monkeypatch
):
    from reachirl.experiments import runner

    real = runner.run_units

    def finished_backwards(units, *args, **kwargs):  # as two workers may finish them
        s = real(units, *args, **kwargs)
        return runner.RunSummary(s.results, s.computed[::-1], s.reused, s.stopped_early)

    monkeypatch.setattr(runner, "run_units", finished_backwards)
    argv = ["reproduce", "--quick", "--data", str(trials_file), "--workers", "1", "--nodes", "20", "--max-iter", "1"]
    argv += ["--sections", "1", "2", "--n-train", "2", "--no-progress", "--out", str(tmp_path / "out")]
    assert main(argv) == 0
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    assert results["run"]["computed"] == ["moirl-P2-s2", "moirl-P2-s1"]


def test_an_experimental_table_spelling_out_a_methods_own_value_keys_the_same_units():
    """[experimental] merit = "normalised" (MO-IRL's own) gave other unit keys than no table, so a run resumed from
    a file that spelt the defaults out computed every unit again; a value that changes the method still keys
    others, and what is a default is the method's: MaxEnt keeps every trajectory (memory None), MO-IRL one."""
    from reachirl.experiments.protocol import ProtocolConfig, make_units

    def options(experimental: dict) -> list:
        config = ProtocolConfig(sections=(8,), methods=("moirl", "maxent"), experimental=experimental)
        return [u.estimator_options for u in make_units(["P2"], config)]

    plain = options({})
    moirl, maxent = options({"merit": "normalised", "w0": 0.05, "memory": 1})
    assert moirl == plain[0] and maxent != plain[1]
    assert dict(dict(maxent)["experimental"]) == {"memory": 1}
    assert options({"merit": "state"})[0] != plain[0]
