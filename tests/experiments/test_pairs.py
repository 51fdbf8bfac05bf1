"""``reachirl reproduce --iscv all-pairs``: every ordered pair of subjects, on a 3-subject toy trials file,
through the real console script."""

import csv
import json

import numpy as np
import pytest

from reachirl.cli import main
from reachirl.data.trial import save_trials
from reachirl.errors import InputError
from reachirl.experiments import datasets
from reachirl.experiments.pairs import COLUMNS
from reachirl.experiments.protocol import ProtocolConfig

ARGS = ["--sections", "1", "--nodes", "20", "--max-iter", "2", "--n-train", "2", "--workers", "1", "--no-progress"]


@pytest.fixture(scope="module")
def three_subjects(tmp_path_factory):
    d = tmp_path_factory.mktemp("three")
    ds = datasets.toy(n_subjects=3, postures=("P2",), n_trials=3, n_nodes=20, seed=3)
    save_trials(d / "trials.npz", ds.trials)
    return d / "trials.npz"


@pytest.fixture(scope="module")
def pairs_run(three_subjects, tmp_path_factory, cli):
    out = tmp_path_factory.mktemp("pairs") / "run"
    proc = cli("reproduce", "--data", three_subjects, "--iscv", "all-pairs", "--out", out, *ARGS)
    assert proc.returncode == 0, proc.stderr
    return out


def _rows(out):
    with open(out / "iscv_pairs.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_every_ordered_pair_with_the_units_numbers(pairs_run):
    rows = _rows(pairs_run)
    assert list(rows[0]) == list(COLUMNS)
    p2 = [r for r in rows if r["posture"] == "P2"]
    assert sorted((r["train_subject"], r["test_subject"]) for r in p2) == [
        (a, b) for a in ("S01", "S02", "S03") for b in ("S01", "S02", "S03")
    ]
    assert {r["posture"] for r in rows} == {"P2", "ALL"}
    for r in p2:  # diagonal: the 3 - 2 training trials left for CV; off-diagonal: every trial of the test subject
        assert int(r["n"]) == (1 if r["train_subject"] == r["test_subject"] else 3)
    # a row is the mean and population SD of the unit's per-trial RMSEs of that test subject
    unit = json.loads((pairs_run / "units" / "moirl-P2-s1-tS02.json").read_text())
    assert unit["unit"]["train_subject"] == "S02" and unit["has_arrays"] is False
    v = [e["rmse_deg"]["q"] for e in unit["sets"]["iscv"]["trials"] if e["id"].startswith("S03")]
    row = next(r for r in p2 if r["train_subject"] == "S02" and r["test_subject"] == "S03")
    assert float(row["rmse_q_mean_deg"]) == pytest.approx(np.mean(v), abs=1e-4)
    assert float(row["rmse_q_sd_deg"]) == pytest.approx(np.std(v), abs=1e-4)
    cv = [e["rmse_deg"]["q"] for e in unit["sets"]["cv"]["trials"]]
    diag = next(r for r in p2 if r["train_subject"] == r["test_subject"] == "S02")
    assert float(diag["rmse_q_mean_deg"]) == pytest.approx(np.mean(cv), abs=1e-4)
    # the weights differ per training subject (they are learned, not shared)
    w1 = json.loads((pairs_run / "units" / "moirl-P2-s1.json").read_text())["weights"]
    assert w1 != unit["weights"] or unit["flag"] == "w0"
    figs = {p.name for p in (pairs_run / "figures").iterdir()}
    assert {"iscv_pairs_moirl_s1.png", "iscv_vs_cv_moirl.png"} <= figs
    assert "All-pairs inter-subject validation" in (pairs_run / "report.md").read_text()


def test_main_table_unchanged_and_resume(pairs_run, three_subjects, tmp_path, capsys):
    one = tmp_path / "one"
    assert main(["reproduce", "--data", str(three_subjects), "--out", str(one), *ARGS]) == 0
    assert (one / "table.csv").read_text() == (pairs_run / "table.csv").read_text()
    assert not (one / "iscv_pairs.csv").exists()
    before = (pairs_run / "iscv_pairs.csv").read_text()
    capsys.readouterr()
    assert (
        main(["reproduce", "--data", str(three_subjects), "--iscv", "all-pairs", "--out", str(pairs_run), *ARGS]) == 0
    )
    assert "3 unit(s) already done" in capsys.readouterr().err
    assert (pairs_run / "iscv_pairs.csv").read_text() == before


def test_bad_options(three_subjects, cli, capsys):
    with pytest.raises(InputError, match="--iscv must be one of"):
        ProtocolConfig(iscv="some")
    with pytest.raises(InputError, match="cannot be combined with --data"):
        datasets.load(three_subjects, n_subjects=4)
    with pytest.raises(InputError, match="at least 2 subjects"):
        datasets.load(None, n_subjects=1)
    proc = cli("reproduce", "--data", three_subjects, "--subjects", "4", "--out", "x", "--no-progress")
    assert proc.returncode == 2 and "cannot be combined with --data" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main(["reproduce", "--iscv", "every", "--out", "x"])
    assert e.value.code == 2
    assert "argument --iscv: invalid choice: 'every' (choose from 'one', 'all-pairs')" in capsys.readouterr().err


def test_one_subject_has_no_pairs_and_the_report_says_so(tmp_path):
    ds = datasets.toy(n_subjects=2, postures=("P2",), n_trials=3, n_nodes=20, seed=3)
    one = tmp_path / "one.npz"
    save_trials(one, [t for t in ds.trials if t.subject == ds.trials[0].subject])
    out = tmp_path / "run"
    assert main(["reproduce", "--data", str(one), "--iscv", "all-pairs", "--out", str(out), *ARGS]) == 0
    report = (out / "report.md").read_text()
    assert "Not run: it needs at least two subjects, and this data has 1." in report
    assert not (out / "iscv_pairs.csv").exists() and not list((out / "figures").glob("iscv_*"))
    assert "1 sections" not in report and "1 section" in report  # one section is said in the singular


@pytest.mark.slow
def test_all_pairs_dask_equals_local_processes(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    from reachirl.experiments.report import write_outputs
    from reachirl.experiments.runner import reproduce

    toy = datasets.toy(n_subjects=3, postures=("P2", "P4"), n_trials=3, n_nodes=20, seed=4)
    cfg = ProtocolConfig(sections=(1, 2), n_train=2, n_nodes=20, max_iter=2, iscv="all-pairs")
    local = reproduce(toy, cfg, tmp_path / "local", workers=2)
    write_outputs(local)
    assert len(local.pairs) == 2 * 2 * 2  # 2 more training subjects × 2 postures × 2 section counts
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        remote = reproduce(toy, cfg, tmp_path / "dask", scheduler=cluster.scheduler_address)
    write_outputs(remote)
    for name in ("table.csv", "iscv_pairs.csv"):
        assert (tmp_path / "local" / name).read_bytes() == (tmp_path / "dask" / name).read_bytes()


def test_a_study_the_data_cannot_have_is_said_on_the_terminal_not_claimed_written(tmp_path, capsys):
    # one subject, one posture: --iscv all-pairs and --posture-transfer write no CSV; the closing line claimed
    # iscv_pairs.csv as written and said nothing of the posture transfer
    ds = datasets.toy(n_subjects=2, postures=("P2",), n_trials=3, n_nodes=20, seed=3)
    one = tmp_path / "one.npz"
    save_trials(one, [t for t in ds.trials if t.subject == ds.trials[0].subject])
    out = tmp_path / "run"
    argv = ["reproduce", "--data", str(one), "--iscv", "all-pairs", "--posture-transfer", "--out", str(out), *ARGS]
    assert main(argv) == 0
    said = " ".join(capsys.readouterr().out.split())
    assert not (out / "iscv_pairs.csv").exists() and not (out / "posture_transfer.csv").exists()
    assert "all-pairs ISCV in" not in said and "posture transfer in" not in said
    assert "no all-pairs ISCV (iscv_pairs.csv not written): it needs at least two subjects" in said
    assert "no posture transfer (posture_transfer.csv not written): it needs at least two postures" in said


def test_a_failed_prediction_is_counted_in_its_pair_not_averaged_in(tmp_path):
    """A prediction whose DOC failed is a count (``doc_failures``), never a number in a pair's mean, as in the main
    table; a pair whose every prediction failed has no mean (an empty cell), and report.md says how many failed."""
    from types import SimpleNamespace

    from reachirl.experiments.pairs import pair_rows, to_csv, write_pairs

    def unit(train, iscv):
        trials = [
            {"id": f"{s}/P2/right/T{i}", "rmse_deg": {"q": q}, "converged": ok} for i, (s, q, ok) in enumerate(iscv)
        ]
        own = {"id": f"{train}/P2/right/T9", "rmse_deg": {"q": 1.0}, "converged": True}
        unit = {"method": "moirl", "posture": "P2", "sections": 1, "train_subject": train}
        return {"unit": unit, "sets": {"cv": {"trials": [own]}, "iscv": {"trials": trials}}}

    subjects = ("S01", "S02", "S03")
    trials = [SimpleNamespace(id=f"{s}/P2/right/T{i}", subject=s) for s in subjects for i in range(4)]
    run = SimpleNamespace(
        dataset=SimpleNamespace(trials=trials, subjects=list(subjects)),
        config=SimpleNamespace(methods=("moirl",), sections=(1,)),
        postures=["P2"],
        train_subject="S01",
        out_dir=tmp_path,
        # S01 on S02: 2.0 converged, 50.0 failed (its number must not count); S01 on S03: every prediction failed
        results={"a": unit("S01", [("S02", 2.0, True), ("S02", 50.0, False), ("S03", 3.0, False)])},
        pairs={"b": unit("S02", [("S01", 4.0, True), ("S03", 5.0, True)])},
    )
    rows = {(r["train_subject"], r["test_subject"]): r for r in pair_rows(run) if r["posture"] == "P2"}
    assert rows["S01", "S02"]["rmse_q_mean_deg"] == 2.0
    assert (rows["S01", "S02"]["n"], rows["S01", "S02"]["doc_failures"]) == (1, 1)
    assert (rows["S01", "S03"]["n"], rows["S01", "S03"]["doc_failures"]) == (0, 1)
    line = next(ln for ln in to_csv(list(rows.values())).splitlines() if ln.startswith("moirl,P2,1,S01,S03,"))
    assert line == "moirl,P2,1,S01,S03,,,0,1"
    md = "\n".join(write_pairs(run, fig_dir=tmp_path / "figures")["markdown"])
    assert "**2 prediction(s) failed**" in md and "nan" not in md
    assert "nan" not in (tmp_path / "iscv_pairs.csv").read_text()


def test_the_pair_heatmaps_are_drawn_from_the_jobs_write_pairs_returns(pairs_run, tmp_path, monkeypatch):
    """write_pairs writes iscv_pairs.csv and returns its figures as jobs (drawn beside the run's other figures,
    in the figure workers): it draws nothing itself, and a heatmap job gives each panel its subject × subject
    matrix on one colour scale, with one colour bar."""
    from types import SimpleNamespace

    import matplotlib.pyplot as plt

    from reachirl.experiments import pairs
    from reachirl.experiments.rendering import draw

    numbers = {"sections": int, "rmse_q_mean_deg": float, "rmse_q_sd_deg": float, "n": int, "doc_failures": int}
    rows = [{k: numbers.get(k, str)(v) for k, v in r.items()} for r in _rows(pairs_run)]
    monkeypatch.setattr(pairs, "pair_rows", lambda run: rows)
    config = SimpleNamespace(methods=("moirl",), sections=(1,), iscv="all-pairs")
    run = SimpleNamespace(out_dir=tmp_path, config=config, postures=["P2"], dataset=SimpleNamespace(subjects="ab"))
    out = pairs.write_pairs(run)
    assert (tmp_path / "iscv_pairs.csv").read_text() == (pairs_run / "iscv_pairs.csv").read_text()
    assert not (tmp_path / "figures").exists()  # nothing drawn: the caller draws the jobs
    names = [j.paths[-1].name for j in out["jobs"]]
    assert names == ["iscv_pairs_moirl_s1.png", "iscv_vs_cv_moirl.png"] and list(out["figures"]) == names
    heat = out["jobs"][0]
    subjects, matrix = heat.kwargs["matrices"]["P2"]
    assert subjects == ["S01", "S02", "S03"] and heat.kwargs["vmax"] == np.nanmax(matrix)
    assert matrix[1, 2] == next(
        r["rmse_q_mean_deg"]
        for r in rows
        if (r["train_subject"], r["test_subject"], r["posture"]) == ("S02", "S03", "P2")
    )
    fig = pairs.plot_pair_matrices(**heat.kwargs)
    image = fig.axes[0].images[0]
    np.testing.assert_array_equal(image.get_array(), matrix)
    assert image.get_clim() == (0, heat.kwargs["vmax"])
    bar = fig.axes[-1]  # one colour bar for the panels, which share the scale
    assert len(fig.axes) == len(heat.kwargs["matrices"]) + 1 and bar.get_ylabel() == "RMSE of q (deg)"
    assert bar.get_ylim() == (0, heat.kwargs["vmax"])
    plt.close(fig)
    for job in out["jobs"]:
        assert draw(job) == job.paths and job.paths[-1].is_file()
