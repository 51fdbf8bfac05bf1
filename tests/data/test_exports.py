"""Trajectory exports: ``evaluate --predictions``, ``preprocess --export`` and reproduce's predictions, read back
with pandas and with reachirl's own MOT reader."""

import numpy as np
import pandas as pd
import pytest

from reachirl.data.exports import CSV_COLUMNS, TrajectoryExport, export_trajectories, safe_name
from reachirl.data.readers import read_file, read_mot
from reachirl.data.trial import load_trials
from reachirl.data.writers import write_mot


def test_safe_name():
    assert safe_name("S01/P2/right/T03") == "S01_P2_right_T03"
    assert safe_name("../a b/c:d") == "_a-b_c-d"  # no path parts, no leading dot
    assert "/" not in safe_name("a/b/c") and safe_name("") == "trial"


def test_clashing_names_get_a_suffix(tmp_path):
    t = np.linspace(0, 1, 5)
    demo = {"q": np.zeros((5, 2)), "qd": np.zeros((5, 2))}
    export_trajectories(tmp_path, [TrajectoryExport("a/b", t, demo), TrajectoryExport("a_b", t, demo)])
    idx = pd.read_csv(tmp_path / "index.csv", keep_default_na=False)
    assert list(idx["id"]) == ["a/b", "a_b"] and list(idx["file"]) == ["a_b", "a_b-2"]
    assert (tmp_path / "a_b-2.csv").exists() and (tmp_path / "a_b-2.mot").exists()


def test_a_new_export_removes_the_files_an_earlier_one_listed_and_it_does_not_write(tmp_path):
    t = np.linspace(0, 1, 5)
    demo = {"q": np.zeros((5, 2)), "qd": np.zeros((5, 2))}
    export_trajectories(tmp_path, [TrajectoryExport(i, t, demo) for i in ("S1/T1", "S1/T2", "S1/T3")])
    (tmp_path / "notes.csv").write_text("mine")  # not an export's: kept
    (tmp_path / ".S1_T1.csv.k3j_x9Qa.tmp").write_text("half")  # what a killed export's atomic write left: removed
    export_trajectories(tmp_path, [TrajectoryExport("S1/T2", t, demo)])
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == ["S1_T2.csv", "S1_T2.mot", "index.csv", "notes.csv"]
    assert list(pd.read_csv(tmp_path / "index.csv")["file"]) == ["S1_T2"]


@pytest.mark.parametrize("then", [["S1/T2", "S2/T1"], ["S1/T2"]])
def test_an_export_interrupted_after_the_index_went_leaves_nothing_the_next_one_keeps(tmp_path, monkeypatch, then):
    """An export interrupted after removing the earlier index (evaluate --predictions, SIGTERM) left the earlier
    export's files and its own, unlisted, and the next export kept them all (120 files of a subject no longer
    exported). Its pending list names them: the next export removes those it does not write again."""
    from reachirl.data import exports

    t = np.linspace(0, 1, 5)
    demo = {"q": np.zeros((5, 2)), "qd": np.zeros((5, 2))}
    export_trajectories(tmp_path, [TrajectoryExport(i, t, demo) for i in ("S1/T1", "S1/T2", "S1/T3")])
    (tmp_path / "notes.csv").write_text("mine")
    real, written = exports.write_mot, []

    def interrupted(path, *args, **kwargs):
        if written:
            raise KeyboardInterrupt
        written.append(path)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(exports, "write_mot", interrupted)
    with pytest.raises(KeyboardInterrupt):
        export_trajectories(tmp_path, [TrajectoryExport(i, t, demo) for i in ("S3/T1", "S3/T2")])
    assert not (tmp_path / "index.csv").exists() and (tmp_path / "S3_T1.mot").exists()
    monkeypatch.setattr(exports, "write_mot", real)
    export_trajectories(tmp_path, [TrajectoryExport(i, t, demo) for i in then])
    names = {safe_name(i) for i in then}
    expect = sorted([*(f"{n}.{e}" for n in names for e in ("csv", "mot")), "index.csv", "notes.csv"])
    assert sorted(p.name for p in tmp_path.iterdir()) == expect


def test_a_failed_prediction_is_listed_and_not_exported(tmp_path):
    # it was exported like the others: only METRICS.json said converged false, the trajectory files could not
    from reachirl.data.exports import is_export

    t = np.linspace(0, 1, 5)
    arrays = {"q": np.zeros((5, 2)), "qd": np.zeros((5, 2))}

    def item(tid, converged):
        return TrajectoryExport(tid, t, arrays, arrays, converged=converged)

    export_trajectories(tmp_path, [item(i, True) for i in ("S1/T1", "S1/T2", "S1/T3")])
    export_trajectories(tmp_path, [item("S1/T1", True), item("S1/T2", False), item("S1/T3", True)])
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "S1_T1.csv",
        "S1_T1.mot",
        "S1_T3.csv",
        "S1_T3.mot",
        "index.csv",
    ]  # the earlier export's files of the failed prediction removed too
    idx = pd.read_csv(tmp_path / "index.csv", keep_default_na=False, dtype=str)
    assert idx.to_dict("records") == [
        {"id": "S1/T1", "file": "S1_T1", "set": "", "converged": "true"},
        {"id": "S1/T2", "file": "", "set": "", "converged": "false"},
        {"id": "S1/T3", "file": "S1_T3", "set": "", "converged": "true"},
    ]
    assert is_export(tmp_path)
    export_trajectories(tmp_path, [TrajectoryExport("S1/T4", t, arrays)])  # no prediction: converged unknown
    assert (tmp_path / "index.csv").read_text() == "id,file,set,converged\nS1/T4,S1_T4,,\n"


def test_an_export_from_before_the_converged_column_is_still_an_export(tmp_path):
    from reachirl.cli._args import refuse_foreign_export_files
    from reachirl.data.exports import is_export

    (tmp_path / "index.csv").write_text("id,file,set\nS1/T1,S1_T1,\n")
    (tmp_path / "S1_T1.csv").write_text("old")
    assert is_export(tmp_path)
    refuse_foreign_export_files(tmp_path, ["index.csv", "S1_T1.csv"], "--predictions")  # its files, replaced
    t = np.linspace(0, 1, 5)
    export_trajectories(tmp_path, [TrajectoryExport("S1/T2", t, {"q": np.zeros((5, 2)), "qd": np.zeros((5, 2))})])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["S1_T2.csv", "S1_T2.mot", "index.csv"]


def test_evaluate_leaves_a_failed_prediction_out_of_its_export(tmp_path, tiny_trials, monkeypatch, capsys):
    import json
    from dataclasses import replace

    from reachirl.cli import main
    from reachirl.irl.model import LearnedModel, save_model

    real = LearnedModel.evaluate

    def second_fails(self, trials, *args, **kwargs):
        errors = real(self, trials, *args, **kwargs)
        return [replace(e, converged=False) if i == 1 else e for i, e in enumerate(errors)]

    monkeypatch.setattr(LearnedModel, "evaluate", second_fails)
    model = save_model(tmp_path / "m.json", LearnedModel(np.full((1, 7), 0.1), n_nodes=20))
    pred, out = tmp_path / "pred", tmp_path / "metrics.json"
    argv = ["evaluate", "--model", str(model), str(tiny_trials), "--out", str(out), "--predictions", str(pred)]
    assert main(argv) == 0
    trials = load_trials(tiny_trials)
    stdout = capsys.readouterr().out
    assert (
        f"wrote 5 trajectories (.csv, .mot) and index.csv to {pred}; 1 whose DOC did not converge left out "
        "(index.csv: converged false)"
    ) in stdout
    idx = pd.read_csv(pred / "index.csv", keep_default_na=False, dtype=str)
    assert list(idx["id"]) == [t.id for t in trials]
    assert list(idx["converged"]) == ["true", "false", "true", "true", "true", "true"]
    assert idx["file"][1] == "" and not list(pred.glob(f"{safe_name(trials[1].id)}.*"))
    assert all((pred / f"{name}.csv").is_file() and (pred / f"{name}.mot").is_file() for name in idx["file"][2:])
    assert [t["converged"] for t in json.loads(out.read_text())["trials"]][1] is False


def test_reproduce_leaves_a_failed_prediction_out_of_its_export(tmp_path, monkeypatch):
    from types import SimpleNamespace

    from reachirl.experiments import report

    n = 5
    ids = np.array(["S1/P1/right/T1", "S1/P1/right/T2"])
    arrays = {
        "train/ids": ids,
        "train/sides": np.array(["right", "right"]),
        "train/t": np.tile(np.linspace(0, 1, n), (2, 1)),
    }
    for who in ("demo", "pred"):
        arrays |= {f"train/{who}_q": np.zeros((2, n, 2)), f"train/{who}_qd": np.zeros((2, n, 2))}
        arrays[f"train/{who}_tau"] = np.zeros((2, n - 1, 2))
    monkeypatch.setattr(report, "load_unit_arrays", lambda out_dir, key: arrays)
    trials = [{"id": ids[0], "converged": True}, {"id": ids[1], "converged": False}]
    run = SimpleNamespace(out_dir=tmp_path, results={"u": {"sets": {"train": {"trials": trials}}}})
    (index,) = report.write_predictions(run)
    assert index.read_text().splitlines() == [
        "id,file,set,converged",
        "S1/P1/right/T1,S1_P1_right_T1,train,true",
        "S1/P1/right/T2,,train,false",
    ]
    assert sorted(p.name for p in index.parent.iterdir()) == ["S1_P1_right_T1.csv", "S1_P1_right_T1.mot", "index.csv"]


@pytest.fixture(scope="module")
def exported(tiny_trials, tmp_path_factory, cli):
    d = tmp_path_factory.mktemp("exp")
    model = d / "model.json"
    proc = cli("fit", tiny_trials, "--sections", "2", "--nodes", "20", "--max-iter", "2", "--out", model)
    assert proc.returncode == 0, proc.stderr
    proc = cli("evaluate", "--model", model, tiny_trials, "--out", d / "metrics.json", "--predictions", d / "pred")
    assert proc.returncode == 0, proc.stderr
    return d / "pred", proc


def test_evaluate_predictions_csv_and_mot(exported, tiny_trials):
    pred, proc = exported
    trials = load_trials(tiny_trials)
    assert f"wrote 6 trajectories (.csv, .mot) and index.csv to {pred}" in proc.stdout
    idx = pd.read_csv(pred / "index.csv", keep_default_na=False)
    assert list(idx["id"]) == [t.id for t in trials] and list(idx.columns) == ["id", "file", "set", "converged"]
    assert list(idx["converged"]) == [True] * len(trials)  # pandas reads true/false as booleans
    for tr, name in zip(trials, idx["file"], strict=True):
        df = pd.read_csv(pred / f"{name}.csv")
        assert tuple(df.columns) == CSV_COLUMNS
        assert len(df) == 21 and df["time_s"].iloc[-1] == pytest.approx(tr.duration)
        # the demonstration is the trial itself on the knots; degrees are the radians converted
        np.testing.assert_allclose(df[["demo_q1_rad", "demo_q2_rad"]].to_numpy(), tr.resample(21).q, atol=1e-8)
        np.testing.assert_allclose(df["pred_q2_deg"], np.rad2deg(df["pred_q2_rad"]), rtol=1e-7)
        # torques act on intervals: the last row has none
        assert df["pred_tau1_Nm"].iloc[:-1].notna().all() and np.isnan(df["pred_tau1_Nm"].iloc[-1])
        # prediction starts where the trial starts
        np.testing.assert_allclose(df[["pred_q1_rad", "pred_q2_rad"]].iloc[0], tr.x0[:2], atol=1e-6)
        # the MOT: OpenSim header and arm26 names, read back by reachirl's reader into q
        text = (pred / f"{name}.mot").read_text().splitlines()
        assert "inDegrees=yes" in text and "endheader" in text
        assert text[text.index("endheader") + 1].split("\t") == ["time", "r_shoulder_elev", "r_elbow_flex"]
        mot = read_mot(pred / f"{name}.mot")
        np.testing.assert_allclose(mot.t, df["time_s"], atol=1e-8)
        np.testing.assert_allclose(mot.q, df[["pred_q1_rad", "pred_q2_rad"]].to_numpy(), atol=1e-7)
        # and OpenSim's shoulder elevation is q1 + 90°
        body = pd.read_csv(pred / f"{name}.mot", sep="\t", skiprows=text.index("endheader") + 1)
        np.testing.assert_allclose(body["r_shoulder_elev"], df["pred_q1_deg"] + 90.0, atol=1e-5)


def test_preprocess_export_round_trip(tmp_path, tiny_trials, cli):
    tr = load_trials(tiny_trials)[0]
    src = tmp_path / "in" / "reach.mot"
    src.parent.mkdir()
    write_mot(src, tr.t, np.rad2deg(tr.q))
    proc = cli(
        "preprocess",
        src,
        "--subject",
        "S9",
        "--posture",
        "P2",
        "--cutoff",
        "0",
        "--out",
        tmp_path / "t.npz",
        "--export",
        tmp_path / "exp",
    )
    assert proc.returncode == 0, proc.stderr
    done = load_trials(tmp_path / "t.npz")[0]
    df = pd.read_csv(tmp_path / "exp" / f"{safe_name(done.id)}.csv")
    assert tuple(df.columns) == tuple(c for c in CSV_COLUMNS if not c.startswith("pred_"))
    np.testing.assert_allclose(df["demo_tau2_Nm"], done.tau[:, 1], rtol=1e-6, atol=1e-9)
    back = read_file(tmp_path / "exp" / f"{safe_name(done.id)}.mot")
    np.testing.assert_allclose(back.q, done.q, atol=1e-7)
    # the CSV reads back too (its time_s and demo_q1_rad columns were once "no 'time' column")
    back = read_file(tmp_path / "exp" / f"{safe_name(done.id)}.csv")
    np.testing.assert_allclose(back.t, done.t, atol=1e-9)
    np.testing.assert_allclose(back.q, done.q, atol=1e-7)


def test_export_needs_a_folder(tmp_path, tiny_trials, cli):
    (tmp_path / "file").write_text("x")
    proc = cli(
        "evaluate",
        "--model",
        tmp_path / "m.json",
        tiny_trials,
        "--out",
        tmp_path / "x.json",
        "--predictions",
        tmp_path / "file",
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().endswith("file: exists and is not a folder; --predictions needs a folder")


def _csv_cell_by_cell(t, demo, pred) -> str:
    """The CSV as ``trajectory_csv`` wrote it before it formatted whole tables: one ``csv.writer`` row per
    sample, ``f"{v:.9g}"`` per cell."""
    import csv
    import io

    from reachirl.data.exports import _columns

    t = np.asarray(t, dtype=float).reshape(-1)
    cols = {"time_s": t}
    for prefix, arrays in (("demo", demo), ("pred", pred)):
        if arrays is not None:
            cols |= _columns(t.size, arrays, prefix)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for row in np.column_stack(list(cols.values())):
        w.writerow(["" if not np.isfinite(v) else f"{v:.9g}" for v in row])
    return buf.getvalue()


def test_csv_text_is_the_cell_by_cell_formatting(rng):
    """Negative zeros, numbers that round to zero, subnormals, huge ones, NaN and ±inf (empty cells)."""
    from reachirl.data.exports import trajectory_csv

    special = [0.0, -0.0, -1e-9, 5e-324, -5e-324, 1e300, -1e300, 0.1, -2 / 3, 123456789.5, np.nan, np.inf, -np.inf]
    n = 60
    t = np.sort(rng.uniform(0, 1, n))
    vals = np.concatenate([special, rng.normal(0, 100, 400), rng.normal(0, 1e-8, 400), 10 ** rng.uniform(-30, 30, 400)])
    pick = rng.choice(vals, size=(4, n, 2)) * rng.choice([-1.0, 1.0], size=(4, n, 2))
    pick[0, 0], pick[1, 0], pick[3, 1] = [np.nan, -0.0], [np.inf, -np.inf], [-np.inf, -5e-324]
    demo = {"q": pick[0], "qd": pick[1], "tau": pick[2][:-1]}
    pred = {"q": pick[3], "qd": pick[0][::-1]}
    finite = {"q": np.nan_to_num(pick[1], posinf=1.0, neginf=-1.0), "qd": pick[2] * 0.0}
    for d, p in ((demo, pred), (demo, None), (None, pred), (finite, None), (finite, finite)):
        assert trajectory_csv(t, d, p) == _csv_cell_by_cell(t, d, p)
    text = trajectory_csv(t, demo, pred)
    assert "nan" not in text and "inf" not in text
    first = text.splitlines()[1].split(",")
    assert first[1] == "" and first[2] == "-0"  # NaN: an empty cell; -0.0 as %.9g writes it
