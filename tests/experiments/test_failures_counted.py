"""Issue 11, item 2: a prediction whose DOC did not converge is counted and left out of the RMSE, never averaged
in silently (evaluate's summary and terminal line, reproduce's tables)."""

import json

import numpy as np
import pytest

from reachirl.doc import DocSolution
from reachirl.doc.evaluation import TrialError, summarise
from reachirl.experiments import tables as tb


def _error(tid, rmse, converged):
    t = np.linspace(0, 1, 5)
    sol = DocSolution(t, np.zeros((5, 2)), np.zeros((5, 2)), np.zeros((4, 2)), 1.0, converged, 1, 0.0)
    return TrialError(tid, rmse, rmse, rmse, converged=converged, prediction=sol)


def test_summary_leaves_failed_predictions_out_and_counts_them():
    errs = [_error("a", 2.0, True), _error("b", 4.0, True), _error("c", 40.0, False)]
    s = summarise(errs)
    assert s["n_trials"] == 3 and s["n_included"] == 2 and s["doc_failures"] == 1
    assert s["rmse_deg"]["q"]["mean"] == pytest.approx(3.0)
    assert s["rmse_deg"]["q"]["std"] == pytest.approx(1.0)
    s_all = summarise(errs, include_failed=True)
    assert s_all["n_included"] == 3 and s_all["doc_failures"] == 1
    assert s_all["rmse_deg"]["q"]["mean"] == pytest.approx(46.0 / 3)


def test_summary_with_no_converged_prediction_has_no_rmse():
    s = summarise([_error("a", 5.0, False)])
    assert s["n_included"] == 0 and s["doc_failures"] == 1
    assert s["rmse_deg"]["q"] == {"mean": None, "std": None}
    json.dumps(s)  # still JSON


def _unit(posture, rmses, converged):
    trials = [
        {"id": str(i), "rmse_deg": {"q1": r, "q2": r, "q": r}, "converged": c}
        for i, (r, c) in enumerate(zip(rmses, converged, strict=True))
    ]
    return {
        "unit": {"method": "moirl", "posture": posture, "sections": 1},
        "sets": {s: {"trials": trials} for s in tb.SETS},
    }


def test_reproduce_table_excludes_and_counts_failures():
    results = {"a": _unit("P1", [1.0, 3.0, 90.0], [True, True, False]), "b": _unit("P2", [5.0], [True])}
    table = tb.build_table(results, "moirl", ["P1", "P2"], [1])
    cell = table["P1"]["train"][1]
    assert cell["q"]["mean"] == pytest.approx(2.0) and cell["q"]["n"] == 2 and cell["doc_failures"] == 1
    assert table[tb.ALL_TRIALS]["train"][1]["q"]["mean"] == pytest.approx(3.0)
    assert table[tb.ALL_TRIALS]["train"][1]["doc_failures"] == 1
    rows = tb.table_rows(table, ["P1", "P2"], [1])
    p1_q = next(r for r in rows if r[0] == "P1" and r[1] == "q")
    assert p1_q[2] == "2.00 ± 1.00 (1 DOC failed)"
    p2_q = next(r for r in rows if r[0] == "P2" and r[1] == "q")
    assert "failed" not in p2_q[2]


def test_evaluate_cli_marks_counts_and_leaves_out_failures(tmp_path, monkeypatch, capsys):
    from reachirl.cli import evaluate as cli_evaluate
    from reachirl.cli import main
    from reachirl.irl.model import LearnedModel, save_model

    model = save_model(tmp_path / "m.json", LearnedModel(np.full((1, 7), 0.1)))
    errs = [_error("a", 2.0, True), _error("b", 40.0, False)]
    monkeypatch.setattr(cli_evaluate, "load_trials", lambda path: ["a", "b"])
    monkeypatch.setattr(cli_evaluate, "fingerprint", lambda trials: "0123456789abcdef")
    monkeypatch.setattr(LearnedModel, "evaluate", lambda self, *a, **k: errs)
    out = tmp_path / "metrics.json"
    assert main(["evaluate", "--model", str(model), "trials.npz", "--out", str(out), "--backend", "crocoddyl"]) == 0
    d = json.loads(out.read_text())
    assert [t["converged"] for t in d["trials"]] == [True, False]
    assert d["summary"]["doc_failures"] == 1 and d["summary"]["n_included"] == 1
    assert d["summary"]["rmse_deg"]["q"]["mean"] == pytest.approx(2.0)
    line = capsys.readouterr().out
    assert "q 2.00 ± 0.00 deg over 1 prediction(s); 1 DOC failure(s) (crocoddyl), left out of the RMSE" in line
