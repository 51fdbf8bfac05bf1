"""Issue 11: CSQP converges whatever the overall scale of the weights (the learned weights of the scale-free
fits span five orders of magnitude), and a warm start is used only for the same task."""

import dataclasses

import numpy as np
import pytest

from reachirl import ReachingTask, solve_doc

cb = pytest.importorskip("reachirl.doc.crocoddyl")

# An MO-IRL fit (1 window, built-in virtual subject S01, posture P1): the weights CSQP stalled on
W_LEARNED = np.array([[3.29e-2, 7.82e-3, 4.49e-2, 4.20e-4, 9.34e-6, 2.06e-2, 1.88e-3]])


def _rmse_deg(a, b):
    return float(np.rad2deg(np.sqrt(np.mean((a - b) ** 2))))


@pytest.fixture(scope="module")
def task(arm):
    return ReachingTask(arm, np.deg2rad([-80.0, 95.0]), 0.95 * arm.length, 0.7, n_nodes=60)


def test_same_solution_at_every_scale_of_the_weights(task):
    sols = [cb.solve(task, W_LEARNED * s) for s in (1.0, 100.0, 1e4)]
    assert all(s.converged for s in sols), [s.status for s in sols]
    for s, k in zip(sols[1:], (100.0, 1e4), strict=True):
        assert _rmse_deg(s.q, sols[0].q) < 0.02
        assert s.cost / k == pytest.approx(sols[0].cost, rel=1e-4)


def test_the_merit_penalty_follows_the_multipliers(task):
    """With CSQP's fixed merit penalty (and no scaling) the same weights at 100x stall: the penalty is below the
    constraint multipliers, so the ℓ1 merit is not exact."""
    fixed = dataclasses.replace(cb.DEFAULT_OPTIONS, objective_scale=0.0, merit_penalty_factor=0.0)
    assert not cb.solve(task, W_LEARNED * 1e4, options=fixed).converged
    assert cb.solve(task, W_LEARNED * 1e4).converged


def test_warm_start_only_from_the_same_task(task, arm):
    w = W_LEARNED * 100.0
    first = solve_doc(task, w, backend="crocoddyl")
    again = solve_doc(task, w, backend="crocoddyl", warm_start=first)
    assert again.converged and again.iterations <= 2  # started at the optimum
    other = ReachingTask(arm, np.deg2rad([-60.0, 90.0]), 0.95 * arm.length, 0.72, n_nodes=60)
    cold = solve_doc(other, w, backend="crocoddyl")
    ignored = solve_doc(other, w, backend="crocoddyl", warm_start=first)
    assert ignored.iterations == cold.iterations
    np.testing.assert_array_equal(ignored.q, cold.q)


def test_fit_and_evaluate_on_the_crocoddyl_backend(arm, tmp_path, capsys, monkeypatch):
    """`reachirl fit --backend crocoddyl` runs MO-IRL on Pinocchio + Crocoddyl + CSQP (every DOC of the fit),
    and evaluate predicts with it."""
    import json

    from reachirl.cli import main
    from reachirl.data.trial import save_trials, trial_from_solution

    w_true = np.array([[0.4, 0.3, 1.0, 0.005, 0.002, 0.2, 0.03]])
    trials = []
    for i, q0 in enumerate(([0.0, 90.0], [4.0, 86.0])):
        task = ReachingTask(arm, np.deg2rad(q0), 0.9 * arm.length, 0.7, n_nodes=30)
        sol = solve_doc(task, w_true, backend="crocoddyl")
        assert sol.converged, sol.status
        trials.append(trial_from_solution(sol, arm, task.target_x, subject="S1", posture="P2", trial_id=str(i)))
    path = tmp_path / "trials.npz"
    save_trials(path, trials)
    model = tmp_path / "model.json"
    calls = []
    original = cb.solve

    def counting(*a, **k):
        calls.append(1)
        return original(*a, **k)

    monkeypatch.setattr(cb, "solve", counting)
    assert (
        main(
            [
                "fit",
                str(path),
                "--sections",
                "1",
                "--nodes",
                "30",
                "--max-iter",
                "2",
                "--backend",
                "crocoddyl",
                "--out",
                str(model),
            ]
        )
        == 0
    )
    m = json.loads(model.read_text())
    assert m["info"]["backend"] == "crocoddyl" and len(calls) == m["info"]["n_doc_solves"] >= 1
    assert "(crocoddyl)" in capsys.readouterr().out
    metrics = tmp_path / "metrics.json"
    assert main(["evaluate", "--model", str(model), str(path), "--out", str(metrics), "--backend", "crocoddyl"]) == 0
    s = json.loads(metrics.read_text())["summary"]
    assert s["n_trials"] == 2 and s["doc_failures"] == 0 and s["rmse_deg"]["q"]["mean"] < 10


@pytest.mark.slow
def test_a_stall_at_the_energys_kink_is_rescued_by_the_smoothing_continuation():
    """A MaxEnt fit with the merit fallback (8 windows, built-in P4; ``benchmarks/learned_weights.json``) on which
    CSQP stalled with KKT ~0.2 at ε = 1e-3 W, even with the exact energy Hessian: the continuation through
    10 ε converges to CasADi's optimum, and turning it off brings the stall back."""
    import json
    from pathlib import Path

    from reachirl import ArmModel

    fits = json.loads((Path(__file__).resolve().parents[2] / "benchmarks" / "learned_weights.json").read_text())
    fit = next(
        f
        for f in fits["fits"]
        if (f["source"], f["method"], f["posture"], f["sections"]) == ("builtin", "maxent", "P4", 8)
    )
    d = next(t for t in fit["trials"]["train"] if t["id"] == "S01/P4/right/S01_P4_T06")
    task = ReachingTask(ArmModel(**d["arm"]), np.array(d["q0"]), d["target_x"], d["duration"], n_nodes=100)
    w = np.array(fit["weights"])
    ref = solve_doc(task, w)
    sol = cb.solve(task, w)
    assert ref.converged and sol.converged, sol.status
    assert _rmse_deg(sol.q, ref.q) < 0.01
    assert abs(sol.cost - ref.cost) / ref.cost < 1e-3
    off = cb.solve(task, w, options=dataclasses.replace(cb.DEFAULT_OPTIONS, fallback_smoothing_factor=0.0))
    assert not off.converged, "this case no longer needs the continuation: pick another one"
