"""The protocol (splits, units), the tables' conventions, the runner's checkpoints and Dask.

Data: a tiny in-memory virtual data set (2 subjects × P2, P4 × 4 DOC reaches on 40 knots).
"""

import json

import numpy as np
import pytest

from reachirl.errors import InputError
from reachirl.experiments import datasets, tables
from reachirl.experiments.protocol import ProtocolConfig, make_units, run_unit, split_trials
from reachirl.experiments.report import write_outputs
from reachirl.experiments.runner import load_unit, reproduce, run_units

FAST = {"n_train": 3, "n_cv": 3, "n_iscv": 3, "n_nodes": 40, "max_iter": 3}


@pytest.fixture(scope="session")
def toy():
    return datasets.toy(n_subjects=2, postures=("P2", "P4"), n_trials=4, n_nodes=40, seed=0)


def _config(**kw):
    return ProtocolConfig(**(FAST | {"sections": (1, 3)} | kw))


def test_split_is_seeded_disjoint_and_shared_across_sections(toy):
    cfg = _config()
    a = split_trials(toy.trials, "P2", cfg)
    b = split_trials(toy.trials, "P2", cfg)
    assert [t.id for t in a.train] == [t.id for t in b.train]
    assert len(a.train) == 3 and len(a.cv) == 1 and len(a.iscv) == 3
    assert {t.subject for t in a.train + a.cv} == {"S01"} and {t.subject for t in a.iscv} == {"S02"}
    assert not {t.id for t in a.train} & {t.id for t in a.cv}
    others = {tuple(t.id for t in split_trials(toy.trials, "P2", _config(seed=s)).train) for s in range(6)}
    assert len(others) > 1  # the seed matters


def test_other_side_split(toy):
    from dataclasses import replace

    trials = [replace(t, side="left") if t.trial_id.endswith(("T03", "T04")) else t for t in toy.trials]
    s = split_trials(trials, "P4", _config(cv="other-side", n_train=None, n_cv=None))
    assert {t.side for t in s.train} == {"right"} and {t.side for t in s.cv} == {"left"}
    assert {t.subject for t in s.train + s.cv} == {"S01"}


def test_bad_protocol_inputs(toy):
    from reachirl.experiments.protocol import resolve_postures, resolve_train_subject

    with pytest.raises(InputError, match="unknown posture"):
        resolve_postures(toy.trials, _config(postures=("P9",)))
    with pytest.raises(InputError, match="unknown training subject"):
        resolve_train_subject(toy.trials, _config(train_subject="nobody"))
    with pytest.raises(InputError, match="sections"):
        _config(sections=(0,))
    with pytest.raises(InputError, match="unknown method"):
        _config(methods=("magic",))
    # a side the training subject has no trials of is named, with the sides it has
    with pytest.raises(
        InputError, match=r"no training trials of subject 'S01' \(left arm; its trials of this posture: right\)"
    ):
        split_trials(toy.trials, "P4", _config(train_side="left"))
    with pytest.raises(InputError, match=r"\(left arm; its trials of this posture: right\)"):
        split_trials(toy.trials, "P4", _config(cv="other-side", train_side="left"))


def test_units_order_and_keys():
    units = make_units(["P2", "P4"], _config(sections=(1, 8)))
    assert [u.key for u in units] == ["moirl-P2-s8", "moirl-P4-s8", "moirl-P2-s1", "moirl-P4-s1"]


@pytest.mark.parametrize("observe", [True, False])
def test_every_unit_predicts_as_its_estimator_fits(observe):
    """A unit observes its trials exactly when its estimator fits observed rollouts: MO-IRL and MaxEnt take the
    protocol's observe and merit; bilevel and KKT fit whole reaches, so their units predict whole reaches."""
    from reachirl.experiments.protocol import make_estimator

    cfg = _config(
        sections=(2,),
        methods=("moirl", "maxent", "bilevel", "kkt"),
        experimental={"observe": observe, "merit": "state"},
    )
    for unit in make_units(["P2"], cfg):
        est = make_estimator(unit)
        assert unit.observe is bool(getattr(est, "observe", False)), unit.key
        assert unit.observe is (observe and unit.method in ("moirl", "maxent")), unit.key
        if unit.method in ("moirl", "maxent"):
            assert est.merit == "state"


def test_the_runs_max_iter_is_moirls_and_maxents_not_bilevels():
    """reproduce's max_iter (30 unless given) limits MO-IRL's and MaxEnt's iterations; bilevel (which takes a
    max_iter of its own, `reachirl fit --max-iter`'s) stops at its DOC-solve budget as the report says."""
    from reachirl.experiments.protocol import make_estimator

    cfg = _config(sections=(2,), methods=("moirl", "maxent", "bilevel"), max_iter=7)
    got = {u.method: make_estimator(u).max_iter for u in make_units(["P2"], cfg)}
    assert got == {"moirl": 7, "maxent": 7, "bilevel": None}


def test_run_unit_is_pure(toy):
    cfg = _config(sections=(2,), max_iter=2)
    split = split_trials(toy.trials, "P4", cfg)
    (unit,) = make_units(["P4"], cfg)
    a, b = run_unit(unit, split), run_unit(unit, split)
    ra, rb = a["result"], b["result"]
    assert ra["weights"] == rb["weights"] and ra["fingerprint"] == rb["fingerprint"]
    assert [t["rmse_deg"] for t in ra["sets"]["iscv"]["trials"]] == [
        t["rmse_deg"] for t in rb["sets"]["iscv"]["trials"]
    ]


def test_seed_all_row_convention():
    # the seed's ALL row is the mean ± population SD of the per-posture means (q1, training, 1 section)
    means = [tables.SEED_TABLE[p]["train"][1]["q1"]["mean"] for p in ("P1", "P2", "P3", "P4", "P5")]
    assert np.mean(means) == pytest.approx(tables.SEED_TABLE["ALL"]["train"][1]["q1"]["mean"], abs=0.01)
    assert np.std(means) == pytest.approx(tables.SEED_TABLE["ALL"]["train"][1]["q1"]["std"], abs=0.01)
    assert tables.SEED_TABLE["ALL"]["iscv"][8]["q"] == {"mean": 8.19, "std": 2.93}


def test_build_table_all_rows():
    def unit(p, vals):
        trials = [{"id": str(i), "rmse_deg": {"q1": v, "q2": v, "q": v}, "converged": True} for i, v in enumerate(vals)]
        return {
            "key": p,
            "unit": {"method": "moirl", "posture": p, "sections": 1},
            "sets": {s: {"trials": trials} for s in ("train", "cv", "iscv")},
        }

    res = {"a": unit("A", [1.0, 3.0]), "b": unit("B", [5.0, 5.0, 5.0, 5.0])}
    t = tables.build_table(res, "moirl", ["A", "B"], [1])
    assert t["ALL"]["train"][1]["q"]["mean"] == pytest.approx(3.5)  # (2 + 5) / 2
    assert t["ALL"]["train"][1]["q"]["std"] == pytest.approx(1.5)
    assert t[tables.ALL_TRIALS]["train"][1]["q"]["mean"] == pytest.approx(24 / 6)
    csv_text = tables.to_csv({"moirl": t}, ["A", "B"], [1])
    assert csv_text.splitlines()[0].startswith("method,posture,joint,train_1_mean,train_1_std,train_1_n")


def test_all_row_over_one_posture_with_trials_gives_the_trials_spread():
    # two postures run, but only A has ISCV trials (no other subject recorded B): the ALL row is A's trials,
    # not A's mean ± 0 (an SD over one posture mean)
    def unit(p, iscv):
        def trials(vals):
            return [
                {"id": str(i), "rmse_deg": {"q1": v, "q2": v, "q": v}, "converged": True} for i, v in enumerate(vals)
            ]

        sets = {"train": trials([1.0, 2.0]), "cv": trials([1.0]), "iscv": trials(iscv)}
        return {
            "key": p,
            "unit": {"method": "moirl", "posture": p, "sections": 1},
            "sets": {s: {"trials": v} for s, v in sets.items()},
        }

    res = {"a": unit("A", [1.0, 3.0]), "b": unit("B", [])}
    t = tables.build_table(res, "moirl", ["A", "B"], [1])
    assert t["ALL"]["iscv"][1]["q"]["mean"] == pytest.approx(2.0)
    assert t["ALL"]["iscv"][1]["q"]["std"] == pytest.approx(1.0)
    assert t["ALL"]["train"][1]["q"]["std"] == pytest.approx(0.0)  # two posture means, equal: a real 0


def test_checkpoints_resume_and_reject_other_inputs(toy, tmp_path):
    cfg = _config(sections=(1,), max_iter=2)
    splits = {p: split_trials(toy.trials, p, cfg) for p in ("P2", "P4")}
    units = make_units(["P2", "P4"], cfg)
    first = run_units(units, splits, tmp_path, workers=1, max_units=1)
    assert first.stopped_early and len(first.computed) == 1
    second = run_units(units, splits, tmp_path, workers=1)
    assert second.reused == first.computed and len(second.computed) == 1
    key = units[0].key
    assert load_unit(tmp_path, key, units[0].fingerprint(splits["P2"])) is not None
    assert load_unit(tmp_path, key, "another-fingerprint") is None  # other inputs: recomputed, not reused
    # a torn write (no JSON) is not a finished unit
    (tmp_path / "units" / f"{key}.json").unlink()
    assert load_unit(tmp_path, key) is None


def test_dask_equals_local(toy, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    cfg = _config(sections=(1, 2), postures=("P4",), max_iter=2)
    local = reproduce(toy, cfg, tmp_path / "local", workers=1)
    write_outputs(local)
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        remote = reproduce(toy, cfg, tmp_path / "dask", scheduler=cluster.scheduler_address)
    write_outputs(remote)
    assert remote.summary.computed and not remote.summary.reused
    assert (tmp_path / "local" / "table.csv").read_bytes() == (tmp_path / "dask" / "table.csv").read_bytes()
    for key in local.summary.results:
        a = json.loads((tmp_path / "local" / "units" / f"{key}.json").read_text())
        b = json.loads((tmp_path / "dask" / "units" / f"{key}.json").read_text())
        assert a["weights"] == b["weights"] and a["sets"] == b["sets"]
        assert (tmp_path / "local" / "units" / f"{key}.npz").read_bytes() == (
            tmp_path / "dask" / "units" / f"{key}.npz"
        ).read_bytes()


def test_dataset_load_errors(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        datasets.load(tmp_path / "missing.npz")
    with pytest.raises(InputError, match="manifest"):
        datasets.load(tmp_path)  # a folder without manifest.csv


def test_check_thresholds_groups_rollouts_as_moirl_does():
    # rollout = "mean": a posture-transfer unit's one rollout spans the other postures' trials, which a file merged
    # from two `preprocess --threshold` runs (one per posture) cut at two thresholds; MO-IRL would refuse it mid-run
    from dataclasses import replace

    from reachirl.experiments.protocol import transfer_splits
    from reachirl.experiments.runner import check_thresholds

    postures = ["P1", "P2", "P4"]
    toy = datasets.toy(n_subjects=2, postures=tuple(postures), n_trials=4, n_nodes=20, seed=5)
    trials = [replace(t, onset_threshold=0.05 if t.posture == "P2" else 0.1) for t in toy.trials]
    for rollout, refused in (("mean", True), ("per_task", False), ("per_demo", False)):
        cfg = _config(sections=(1,), rollout=rollout, posture_transfer=True)
        splits = {p: split_trials(trials, p, cfg) for p in postures}
        splits.update(transfer_splits(splits, postures))
        units = make_units(postures, cfg)
        if refused:
            with pytest.raises(InputError, match=r"^data\.npz: S01 P2, P4: .*different onset thresholds"):
                check_thresholds(units, splits, "data.npz")
        else:
            check_thresholds(units, splits, "data.npz")
        check_thresholds([u for u in units if u.held_out_posture is None], splits, "data.npz")  # one posture each


def test_unreachable_scheduler_changes_nothing_on_disk(toy, tmp_path, monkeypatch, capsys):
    # the scheduler is reached before on_start, which clears an earlier run's outputs and writes run.toml
    from reachirl.experiments import runner

    def unreachable(address):
        raise InputError("cannot connect to the Dask scheduler (OSError: refused)", address)

    monkeypatch.setattr(runner, "_dask_client", unreachable)
    cfg = _config(sections=(1,))
    splits = {p: split_trials(toy.trials, p, cfg) for p in ("P2", "P4")}
    started = []
    with pytest.raises(InputError, match="cannot connect to the Dask scheduler"):
        run_units(
            make_units(["P2", "P4"], cfg),
            splits,
            tmp_path,
            scheduler="tcp://127.0.0.1:1",
            on_start=lambda total, reused: started.append(total),
        )
    assert started == [] and list(tmp_path.iterdir()) == []
    # nor is an output folder made for the run left behind; one that existed is left as it was
    from reachirl.cli import main
    from reachirl.data.trial import save_trials

    with pytest.raises(InputError, match="cannot connect to the Dask scheduler"):
        reproduce(toy, cfg, tmp_path / "new" / "out", scheduler="tcp://127.0.0.1:1")
    assert list(tmp_path.iterdir()) == []
    data = save_trials(tmp_path / "trials.npz", toy.trials)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("the user's")
    for out in (tmp_path / "new" / "out", mine):
        capsys.readouterr()
        argv = ["reproduce", "--data", str(data), "--out", str(out), "--scheduler", "tcp://127.0.0.1:1", "--quick"]
        assert main([*argv, "--sections", "1", "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "tcp://127.0.0.1:1: cannot connect to the Dask scheduler" in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "trials.npz"]
    assert [p.name for p in mine.iterdir()] == ["notes.txt"] and (mine / "notes.txt").read_text() == "the user's"


def test_scheduler_that_fails_to_connect_is_one_line_at_once(tmp_path):
    # a tls:// address without a TLS configuration fails inside Client(); the half-made client, left to the garbage
    # collector, closed at exit 30 s later with a traceback on stderr
    import subprocess
    import sys

    pytest.importorskip("dask.distributed")
    code = (
        "from reachirl.errors import InputError\n"
        "from reachirl.experiments.runner import _dask_client\n"
        "try:\n"
        "    _dask_client('tls://127.0.0.1:1')\n"
        "except InputError as e:\n"
        "    print(e.reason)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert done.returncode == 0
    assert done.stdout.startswith("cannot connect to the Dask scheduler (TypeError: TLS expects")
    assert done.stderr == ""


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"sections": (1.5,)}, r"^--sections must be positive integers, got \[1\.5\]$"),
        ({"seed": -1}, r"^seed must be an integer in \[0, 4294967295\], got -1$"),
        ({"max_iter": 0}, r"^max_iter must be an integer in \[1, 10000\], got 0$"),
        ({"n_train": "a"}, r"^n_train must be an integer >= 1, got 'a'$"),
        ({"n_nodes": 3, "sections": (1,)}, r"^n_nodes must be an integer in \[4, 1000\], got 3$"),
        ({"backend": "ipopt"}, r"^backend must be one of casadi, crocoddyl, got 'ipopt'$"),
    ],
)
def test_a_protocol_config_names_a_bad_count_seed_or_backend(kwargs, match):
    # 1.5 sections were read as 1; the others were taken and failed in every unit (or, for n_train="a", in int())
    with pytest.raises(InputError, match=match):
        ProtocolConfig(**kwargs)


def test_a_dask_scheduler_lost_mid_run_is_said_in_one_line_and_the_finished_units_kept(toy, tmp_path, capsys):
    """The scheduler gone after the first unit: an InputError naming it (no internal error, no traceback of the
    client's attempts to reconnect on stderr), the unit finished before it checkpointed, and a rerun resumes."""
    distributed = pytest.importorskip("dask.distributed")
    cfg = _config(sections=(1, 2), postures=("P4",), max_iter=2)
    splits = {p: split_trials(toy.trials, p, cfg) for p in ("P4",)}
    units = make_units(["P4"], cfg)
    cluster = distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    )
    try:
        with pytest.raises(InputError, match=r"lost the connection to the Dask scheduler .*1 unit\(s\) of this run"):
            run_units(units, splits, tmp_path, scheduler=cluster.scheduler_address, on_done=lambda *a: cluster.close())
    finally:
        cluster.close()
    assert "Traceback" not in capsys.readouterr().err
    again = run_units(units, splits, tmp_path, workers=1)
    assert len(again.reused) == 1 and len(again.computed) == 1


def test_a_run_into_a_folder_another_command_writes_into_names_the_argument_not_the_cli_option(toy, tmp_path):
    # from Python there is no --out: the message names the argument that named the folder
    from folder_locks import held_elsewhere

    out = tmp_path / "run"
    out.mkdir()
    with held_elsewhere(out):
        with pytest.raises(
            InputError,
            match=r"^\S+/run: out_dir: another reachirl command is writing into this folder now; wait for it to end, "
            r"or choose another out_dir$",
        ):
            reproduce(toy, _config(sections=(1,)), out)
    assert list(out.iterdir()) == []


def test_units_run_on_the_workers_started_ahead(toy, tmp_path, monkeypatch):
    """``reproduce``'s unit workers, started before the data are loaded (:class:`UnitWorkers`): ``run_units``
    takes them over and starts none of its own, with the same results as its own workers'; workers no unit took
    are ended when their ``with`` block ends."""
    from children import children_gone
    from reachirl.experiments import runner

    cfg = _config(sections=(1,), max_iter=2)
    splits = {p: split_trials(toy.trials, p, cfg) for p in ("P2", "P4")}
    units = make_units(["P2", "P4"], cfg)
    own = run_units(units, splits, tmp_path / "own", workers=2)
    with runner.UnitWorkers(2, cfg.n_nodes) as ahead:
        ahead.start()
        monkeypatch.setattr(runner, "unit_executor", lambda n: pytest.fail("run_units started workers of its own"))
        taken = run_units(units, splits, tmp_path / "ahead", workers=2, ahead=ahead)
        assert ahead.pool is None, "taken over"
    assert children_gone()
    assert sorted(taken.computed) == sorted(own.computed) == sorted(u.key for u in units)
    for key, res in own.results.items():
        assert np.array_equal(taken.results[key]["weights"], res["weights"])

    with runner.UnitWorkers(2, cfg.n_nodes) as idle:  # every unit reused: nothing takes them
        idle.start()
        again = run_units(units, splits, tmp_path / "ahead", workers=2, ahead=idle)
        assert again.reused and not again.computed and idle.pool is not None
    assert idle.pool is None and children_gone()


def test_a_splits_trials_are_hashed_once_for_all_its_units(toy, monkeypatch):
    """Every section count's unit of a split fingerprints the same trials: they are hashed once per split (a
    study's split holds hundreds), and a split of other trials still gives other fingerprints."""
    from dataclasses import replace

    from reachirl.experiments import protocol

    hashed = []
    real = protocol.fingerprint
    monkeypatch.setattr(protocol, "fingerprint", lambda trials: hashed.append(len(trials)) or real(trials))
    cfg = _config(sections=(1, 3, 8))
    split = split_trials(toy.trials, "P2", cfg)
    units = [u for u in make_units(["P2"], cfg) if u.split_key == "P2"]
    fps = [u.fingerprint(split) for u in units]
    assert len(units) == 3 and len(set(fps)) == 3  # the units differ by their sections
    assert hashed == [3, 1, 3]  # train, CV and ISCV, once
    moved = replace(split, iscv=(replace(split.iscv[0], target_x=split.iscv[0].target_x + 1e-3), *split.iscv[1:]))
    assert all(u.fingerprint(moved) != fp for u, fp in zip(units, fps, strict=True))
