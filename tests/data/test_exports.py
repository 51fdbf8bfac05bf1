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
    assert list(idx["id"]) == [t.id for t in trials] and list(idx.columns) == ["id", "file", "set"]
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
