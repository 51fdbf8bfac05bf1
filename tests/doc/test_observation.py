"""Predicting a reach as it was recorded (``reachirl.doc.observation``): the cut, the gain it brings, its plumbing
(Trial field, trials file, preprocessing, MO-IRL, ``fit``/``evaluate``, ``reproduce``), and its errors."""

import json
from dataclasses import replace

import numpy as np
import pytest

from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.cli import main
from reachirl.data.trial import load_trials, save_trials, trial_from_solution
from reachirl.doc.evaluation import evaluate_trials
from reachirl.doc.observation import (
    MOVING_FRACTION,
    common_threshold,
    observe,
    observed_knots,
    rest_to_rest,
)
from reachirl.errors import InputError
from reachirl.irl.moirl import MOIRL, mean_task
from reachirl.virtual import nominal_weights, posture_q

N = 40
ARM = ArmModel.from_anthropometrics(1.76, 70.0, "M")


def _recorded(q0_deg_offset=(0.0, 0.0), duration=0.8, posture="P2", threshold=0.05, weights=None):
    """A reach solved rest to rest under ``weights`` and cut at its own ``threshold`` crossings, as a recording
    would be: ``(trial, the whole solution, its task)``."""
    w = nominal_weights() if weights is None else weights
    task = ReachingTask(ARM, posture_q(posture) + np.deg2rad(q0_deg_offset), 0.95 * ARM.length, duration, n_nodes=N)
    sol = solve_doc(task, w)
    assert sol.converged
    seen = observe(sol, task, threshold)
    return replace(seen, subject="S01", posture=posture, trial_id="T1", onset_threshold=threshold), sol, task


def test_the_cut_is_where_the_speed_crosses_the_threshold():
    trial, sol, task = _recorded()
    fine = np.linspace(0.0, task.duration, 20001)
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(sol.t, sol.q, axis=0)
    peak = np.max(np.linalg.norm(ARM.fingertip_velocity(spline(fine), spline(fine, 1)), axis=1))
    ends = np.linalg.norm(ARM.fingertip_velocity(trial.q[[0, -1]], trial.qd[[0, -1]]), axis=1)
    np.testing.assert_allclose(ends, 0.05 * peak, rtol=2e-3)
    assert 0.8 < trial.duration / task.duration < 0.97  # a bell-shaped reach: most of it above 5 %
    assert trial.x0[2:] @ trial.x0[2:] > 0  # it starts moving, as a recorded trial does


def test_observed_knots_are_the_knots_of_the_observed_trial():
    """MO-IRL reads each rollout's knots off the solution's spline; they must be those of the trial that
    :func:`observe` makes, read as a demonstration is (:meth:`Trial.knots`), and the whole solution's own
    knots without a threshold."""
    _, sol, task = _recorded()
    for threshold in (0.05, 0.2):
        seen = observe(sol, task, threshold)
        q, qd, tau, dt = observed_knots(sol, task, threshold)
        q_ref, qd_ref, tau_ref = seen.knots(N)
        np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(qd, qd_ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(tau, tau_ref, rtol=0, atol=1e-6 * np.max(np.abs(tau_ref)))
        assert dt == pytest.approx(seen.duration / N, rel=1e-12)
    whole = trial_from_solution(sol, ARM, task.target_x)
    *knots, dt = observed_knots(sol, task, None)
    for mine, ref in zip(knots, whole.knots(N), strict=True):
        np.testing.assert_allclose(mine, ref, rtol=0, atol=1e-9 * max(1.0, np.max(np.abs(ref))))
    assert dt == pytest.approx(whole.duration / N, rel=1e-12)


def test_the_shared_spline_matrices_give_scipys_interpolant_and_its_fine_samples():
    """A DOC solution's knots are equally spaced: a prediction's spline comes from matrices shared by every solution
    of N intervals (coefficients, fine values and slopes), and must be scipy's not-a-knot interpolant of the same
    knots to rounding, at any time and in its first two derivatives; knots spaced otherwise take scipy's own."""
    from scipy.interpolate import make_interp_spline

    from reachirl.doc import observation as obs

    _, sol, task = _recorded()
    for duration in (task.duration, 0.37, 2.9):
        t = np.linspace(0.0, duration, N + 1)
        ref = make_interp_spline(t, sol.q, k=3)
        mine = obs._knot_spline(t, sol.q, shared=True)
        x = np.random.default_rng(1).uniform(0.0, duration, 300)
        for nu in (0, 1, 2):  # each derivative divides the knots' rounding by the interval once more
            expected = ref(x, nu)
            np.testing.assert_allclose(mine(x, nu), expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))
        fine = np.linspace(0.0, duration, obs._FINE * N + 1)
        q, qd = obs._fine_samples(replace(sol, t=t), mine, fine, shared=True)
        np.testing.assert_allclose(q, ref(fine), rtol=0, atol=1e-12 * np.max(np.abs(sol.q)))
        np.testing.assert_allclose(qd, ref(fine, 1), rtol=0, atol=1e-12 * np.max(np.abs(ref(fine, 1))))
    uneven = np.sort(np.r_[0.0, np.random.default_rng(2).uniform(0.0, 1.0, N - 1), 1.0])
    scipys = make_interp_spline(uneven, sol.q, k=3).c
    np.testing.assert_array_equal(obs._knot_spline(uneven, sol.q, shared=True).c, scipys)
    # MO-IRL's rollouts (the default) keep scipy's own spline, bit for bit
    np.testing.assert_array_equal(obs._knot_spline(sol.t, sol.q).c, make_interp_spline(sol.t, sol.q, k=3).c)


def test_seen_as_recorded_the_true_weights_reproduce_their_reach():
    """The seed's task (the DOC over the trial's own duration, from rest) cannot reproduce a reach cut at 5 %;
    the observed prediction does, to within what the fixed moving fraction leaves."""
    trial, _, _ = _recorded()
    plain = evaluate_trials(nominal_weights(), [trial], N)[0]
    seen = evaluate_trials(nominal_weights(), [trial], N, observe=True)[0]
    assert seen.converged and plain.converged
    assert seen.rmse_q < 0.25 < plain.rmse_q
    assert seen.rmse_q < 0.4 * plain.rmse_q


def test_uncut_trials_are_predicted_whole_and_fits_ignore_observe():
    trial = _recorded()[0]
    uncut = replace(trial, onset_threshold=None)
    a = evaluate_trials(nominal_weights(), [uncut], N, observe=True)[0]
    b = evaluate_trials(nominal_weights(), [uncut], N)[0]
    np.testing.assert_array_equal(a.prediction.q, b.prediction.q)
    demos = [
        replace(_recorded((d, -d), 0.75 + 0.02 * d)[0], onset_threshold=None, trial_id=f"T{d}")
        for d in (-2.0, 0.0, 2.0)
    ]
    fit = dict(n_nodes=N, max_iter=3, tol=1e-5)
    w_obs = MOIRL(2, **fit, experimental={"observe": True}).fit(demos)
    w_plain = MOIRL(2, **fit).fit(demos)
    np.testing.assert_array_equal(w_obs.weights_, w_plain.weights_)
    assert w_obs.plain_fit_ is None


def test_observed_fit_counts_both_stages_and_predicts_as_it_fitted():
    demos = [replace(_recorded((d, -d), 0.75 + 0.02 * d)[0], trial_id=f"T{d}") for d in (-2.0, 0.0, 2.0)]
    est = MOIRL(2, n_nodes=N, max_iter=3, tol=1e-5, experimental={"observe": True}).fit(demos)
    assert est.plain_fit_ is not None
    plain = MOIRL(2, n_nodes=N, max_iter=3, tol=1e-5, experimental={"observe": False}).fit(demos)
    np.testing.assert_allclose(est.plain_fit_["weights"], plain.weights_)  # the first stage is the plain fit
    # its history runs from ω₀ to where the observed stage's history starts
    first = est.plain_fit_["history"]
    assert first[0]["iteration"] == 0 and first[0]["merit"] == est.plain_fit_["initial_merit"]
    np.testing.assert_allclose(est.history_[0]["weights"], plain.weights_)
    assert est.plain_fit_["n_iter"] == len(first) - 1 == plain.n_iter_
    pred = est.predict(demos[0])
    again = evaluate_trials(est.weights_, [demos[0]], N, observe=True, path=est.rollout_path())[0].prediction
    np.testing.assert_allclose(pred.q, again.q, atol=1e-9)  # predict starts from the fit's own rollout
    cold = evaluate_trials(est.weights_, [demos[0]], N, observe=True)[0].prediction
    assert np.degrees(np.max(np.abs(pred.q - cold.q))) < 1e-3  # and finds the minimum-jerk start's optimum
    horizon = demos[0].duration / MOVING_FRACTION
    assert pred.t[-1] == pytest.approx(demos[0].duration, rel=0.08)  # the observed part,
    assert pred.t[-1] < 0.97 * horizon  # not the whole horizon


def test_trials_cut_at_different_thresholds_cannot_share_a_rollout():
    a = _recorded()[0]
    b = replace(a, trial_id="T2", onset_threshold=0.03)
    assert common_threshold([a, a]) == 0.05
    assert common_threshold([a, replace(a, onset_threshold=None)]) is None
    with pytest.raises(ValueError, match="different onset thresholds"):
        MOIRL(1, n_nodes=N, max_iter=1, experimental={"observe": True}).fit([a, b])


def test_bad_options_are_refused():
    a = _recorded()[0]
    with pytest.raises(ValueError, match="observe must be True or False"):
        MOIRL(1, n_nodes=N, experimental={"observe": "yes"}).fit([a])
    with pytest.raises(ValueError, match="multimodal"):
        MOIRL(1, n_nodes=N, experimental={"observe": True, "acceptance": "multimodal"}).fit([a])
    with pytest.raises(InputError, match="onset_threshold must be a fraction"):
        replace(a, onset_threshold=1.5)


def test_trials_file_round_trip_keeps_the_threshold_and_refuses_a_bad_one(tmp_path):
    from reachirl.io import npz_bytes

    a = _recorded()[0]
    b = replace(a, trial_id="T2", onset_threshold=None)
    path = save_trials(tmp_path / "t.npz", [a, b])
    assert [t.onset_threshold for t in load_trials(path)] == [0.05, None]
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(arrays["meta.json"].tobytes())
    meta["trials"][0]["onset_threshold"] = 2.0
    arrays["meta.json"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(npz_bytes(arrays))
    with pytest.raises(InputError, match="'onset_threshold' must be null or a fraction") as e:
        load_trials(bad)
    assert "bad.npz" in str(e.value)


def test_preprocessing_records_the_threshold_only_where_it_cut():
    from reachirl.data.preprocess import PreprocessOptions, angles_to_trial
    from reachirl.data.readers import AngleData

    _, sol, task = _recorded()
    rate = 100.0
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(sol.t, sol.q, axis=0)
    t_move = np.arange(0.0, task.duration, 1 / rate)
    rest = np.arange(1, 41) / rate
    q = np.vstack([np.repeat(sol.q[:1], 40, axis=0), spline(t_move), np.repeat(sol.q[-1:], 40, axis=0)])
    t = np.r_[-rest[::-1], t_move, t_move[-1] + rest] + 0.4
    kw = dict(subject="S01", posture="P2", trial_id="T1", side="right", subject_info=None, options=PreprocessOptions())
    with_rest = angles_to_trial(AngleData(t=t, q=q, source="rec.mot"), **kw)
    assert with_rest.onset_threshold == 0.05
    n_cut = 40 + int(0.3 * t_move.shape[0])  # the record starts mid-reach: no rest before
    no_rest = angles_to_trial(AngleData(t=t[n_cut:], q=q[n_cut:], source="rec.mot"), **kw)
    assert no_rest.onset_threshold is None


def test_fit_records_observe_and_evaluate_follows_it(tmp_path, capsys):
    demos = [replace(_recorded((d, -d), 0.75 + 0.02 * d)[0], trial_id=f"T{d}") for d in (-2.0, 0.0, 2.0)]
    trials = save_trials(tmp_path / "t.npz", demos)
    for expect in (True, False):
        model = tmp_path / f"m{expect}.json"
        run = tmp_path / f"r{expect}.toml"
        run.write_text(f"[experimental]\nobserve = {str(expect).lower()}\n")
        assert (
            main(
                [
                    "fit",
                    str(trials),
                    "--sections",
                    "1",
                    "--nodes",
                    str(N),
                    "--max-iter",
                    "2",
                    "--config",
                    str(run),
                    "--rollout",
                    "mean",
                    "--out",
                    str(model),
                ]
            )
            == 0
        )
        assert json.loads(model.read_text())["info"]["observe"] is expect
        out = tmp_path / f"e{expect}.json"
        assert main(["evaluate", "--model", str(model), str(trials), "--out", str(out)]) == 0
        d = json.loads(model.read_text())
        weights, rollout = np.array(d["weights"]), np.array(d["info"]["rollout_q"])
        # the model keeps the fit's own reach: the DOC of the demonstrations' mean task (rest to rest when
        # observed) under the learned weights, solved here from scratch
        task = mean_task(demos, N)
        own = solve_doc(rest_to_rest(task) if expect else task, weights)
        assert np.degrees(np.max(np.abs(own.q - rollout))) < 0.01
        want = evaluate_trials(weights, demos, N, observe=expect, path=rollout)  # evaluate starts from it
        got = json.loads(out.read_text())["trials"]
        np.testing.assert_allclose([g["rmse_deg"]["q"] for g in got], [w.rmse_q for w in want], rtol=1e-9)
        cold = evaluate_trials(weights, demos, N, observe=expect)  # the same optimum from the minimum-jerk start
        np.testing.assert_allclose([g["rmse_deg"]["q"] for g in got], [w.rmse_q for w in cold], atol=1e-3)
    d = json.loads((tmp_path / "mTrue.json").read_text())
    d["info"]["observe"] = "yes"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    capsys.readouterr()
    assert main(["evaluate", "--model", str(bad), str(trials), "--out", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "info.observe" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.json").exists()
    for rollout, message in (
        ([[0.1, 0.2]] * N, f"field 'info.rollout_q': expected {N + 1} rows of 2 joint angles"),
        ([[0.1, 0.2]] * N + [[0.1, None]], "field 'info.rollout_q', row 40: expected 2 finite"),
    ):
        d = json.loads((tmp_path / "mTrue.json").read_text())
        d["info"]["rollout_q"] = rollout
        bad.write_text(json.dumps(d))
        assert main(["evaluate", "--model", str(bad), str(trials), "--out", str(tmp_path / "x.json")]) == 2
        err = capsys.readouterr().err
        assert message in err and str(bad) in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "x.json").exists()
    n_windows = len(json.loads((tmp_path / "mTrue.json").read_text())["weights"])
    for phi in ([[1.0] * 7] * (n_windows + 1), [[1.0] * 6 + [-1.0]] * n_windows, "Φ"):
        d = json.loads((tmp_path / "mTrue.json").read_text())
        d["info"]["reach_features"] = phi
        bad.write_text(json.dumps(d))
        assert main(["evaluate", "--model", str(bad), str(trials), "--out", str(tmp_path / "x.json")]) == 2
        err = capsys.readouterr().err
        assert f"field 'info.reach_features': expected {n_windows} rows of 7 finite numbers >= 0" in err
        assert str(bad) in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "x.json").exists()
    # without n_nodes, 100 knots are assumed: the message says so, not only that the rows are wrong
    d = json.loads((tmp_path / "mTrue.json").read_text())
    del d["n_nodes"]
    bad.write_text(json.dumps(d))
    assert main(["evaluate", "--model", str(bad), str(trials), "--out", str(tmp_path / "x.json")]) == 2
    assert (
        "expected 101 rows of 2 joint angles (the field 'n_nodes' is missing: 100 knots assumed), found "
        f"'{N + 1} rows'" in capsys.readouterr().err
    )
