"""What the data determines about the weights, the weight samples, and the paper's claim tested on them; on
recorded trials (markers with noise, cut at a speed threshold)."""

import json

import numpy as np
import pytest
from scipy import stats

from reachirl import MOIRL
from reachirl.cli import main
from reachirl.data.trial import load_trials, select_trials
from reachirl.errors import InputError
from reachirl.features import FEATURES, cost_shares
from reachirl.irl.model import LearnedModel, check_model_dict, save_model
from reachirl.irl.uncertainty import (
    PRIOR_LOG_SD,
    _errors,
    claim_verdict,
    describe_direction,
    determination,
    indistinguishable,
    laplace_posterior,
    mean_width,
    merit_noise,
    residuals_and_jacobian,
    rise_over_noise,
    share_intervals,
    versus_fit,
    weight_uncertainty,
)

ACC = FEATURES.index("joint_acceleration")


@pytest.fixture(scope="module")
def fitted(recorded):
    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])
    return MOIRL(2, n_nodes=40, max_iter=3).fit(trials), trials


def test_the_shares_are_the_terms_of_the_cost_each_rollout_minimised(fitted):
    """Recorded trials are cut at a speed threshold, so a fit's rollouts are rest-to-rest DOCs seen between their
    crossings of it. The shares were taken on the windows of the part seen, which begin after the weights' first
    window starts and end before their last one ends (up to 0.23 total variation at onset and end on make run's
    fits): now on the whole DOC's windows, where ``ω·Φ`` sums to the cost the DOC minimised."""
    from reachirl.doc.observation import observed_knots
    from reachirl.features import windowed_features

    est, _ = fitted
    (task,), (sol,) = est.tasks_, est.train_solutions_
    assert est._thresholds[0] is not None  # cut trials: the part seen is not the whole DOC
    phi = est.reach_features()
    assert np.isclose(float(np.sum(est.weights_ * phi)), sol.cost, rtol=1e-9)
    seen = windowed_features(task.arm, *observed_knots(sol, task, est._thresholds[0]), 2)
    assert not np.isclose(float(np.sum(est.weights_ * seen)), sol.cost, rtol=1e-3)


def test_the_windows_edges_on_the_recorded_reach_say_where_the_weights_act(fitted, tmp_path):
    """Nothing said where a window lies on the recorded reach. MODEL.json's ``window_edges`` are the windows' edges
    with 0 at the recorded onset and 1 at the offset: there the rollout's fingertip speed crosses the threshold,
    the first window begins before the onset and the last ends after the offset. A damaged field is refused."""
    from reachirl.irl.model import LearnedModel, load_model, save_model

    est, _ = fitted
    (task,), (sol,), (threshold,) = est.tasks_, est.train_solutions_, est._thresholds
    edges = est.window_edges()
    assert edges.shape == (3,) and edges[0] < 0 < 1 < edges[-1] and np.allclose(np.diff(edges), np.diff(edges)[0])
    T = task.duration
    onset, offset = (np.array([0.0, 1.0]) - edges[0]) / (edges[-1] - edges[0]) * T  # s from the DOC's start
    from scipy.interpolate import make_interp_spline

    spline = make_interp_spline(sol.t, sol.q, k=3)
    fine = np.linspace(0.0, T, 4001)
    speed = task.arm.fingertip_speed(spline(fine), spline(fine, 1))
    at = np.interp([onset, offset], fine, speed)
    np.testing.assert_allclose(at, threshold * speed.max(), rtol=0.03)
    save_model(tmp_path / "m.json", LearnedModel.from_estimator(est))
    d = json.loads((tmp_path / "m.json").read_text())
    assert d["info"]["window_edges"] == pytest.approx(edges.tolist())
    d["info"]["window_edges"] = [0.5, 0.2, 1.0]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(InputError, match=r"field 'info.window_edges': expected 3 increasing finite numbers"):
        load_model(tmp_path / "bad.json")


def test_the_residuals_are_the_merit_and_their_jacobian_matches_re_solved_finite_differences(fitted):
    est, _ = fitted
    free = est._movable(est._w_fit.shape)
    r, J = residuals_and_jacobian(est, free)
    assert np.mean(np.sum(r**2, axis=1)) == pytest.approx(est.merit_, rel=1e-9)
    det = determination(r, J, free)
    v = det.directions[0][free]  # the most determined direction, unit length in the free log-weights
    h = 0.02
    moved = []
    for sign in (1.0, -1.0):
        w = est._w_fit.copy()
        w[free] *= np.exp(sign * h * v)
        sols, _, _ = est._rollouts(est.tasks_, w, est.train_solutions_, est._guesses)
        assert all(s.converged for s in sols)
        moved.append(np.stack([est._state(i, t, s) for i, (t, s) in enumerate(zip(est.tasks_, sols, strict=True))]))
    n1 = est.n_nodes + 1
    scale = np.sqrt(est._channels) / np.sqrt(n1)
    fd = ((moved[0] - moved[1]) / (2 * h) * scale).reshape(len(est.tasks_), -1)[est.task_of_demo_]
    predicted = J @ v
    assert np.linalg.norm(fd - predicted) <= 0.1 * np.linalg.norm(predicted)  # the cut at the threshold: not smooth
    # the merit's curvature along it is the squared singular value (Gauss-Newton)
    assert np.linalg.norm(predicted) ** 2 / len(r) == pytest.approx(det.singular_values[0] ** 2, rel=1e-9)


def test_an_overall_rescale_of_the_weights_is_never_determined(fitted):
    est, _ = fitted
    free = est._movable(est._w_fit.shape)
    _, J = residuals_and_jacobian(est, free)
    ones = np.ones(J.shape[-1]) / np.sqrt(J.shape[-1])
    assert np.linalg.norm(J @ ones) <= 1e-4 * np.linalg.norm(J, axis=(1, 2)).max()


def test_fewer_residuals_than_log_weights_count_every_direction():
    """One demonstration of 11 knots × 4 channels against 70 free log-weights: the 26 directions beyond the
    residuals' rank move nothing and count as undetermined, orthonormal to the others."""
    rng = np.random.default_rng(0)
    free = np.ones((10, 7), dtype=bool)
    r, J = rng.normal(size=(1, 44)), rng.normal(size=(1, 44, 70))
    det = determination(r, J, free)
    assert det.singular_values.shape == (70,) and det.directions.shape == (70, 10, 7)
    assert np.all(det.singular_values[44:] == 0.0) and det.n_determined <= 44
    v = det.directions.reshape(70, -1)
    np.testing.assert_allclose(v @ v.T, np.eye(70), atol=1e-10)
    np.testing.assert_allclose(J[0] @ v[44:].T, 0.0, atol=1e-10)  # they do not move the states
    assert det.to_dict()["n_directions"] == 70


def test_indistinguishable_is_a_one_sided_paired_test():
    fit = np.array([1.0, 2.0, 1.5, 0.8, 1.2])
    assert indistinguishable(fit + np.array([0.01, -0.02, 0.0, 0.01, -0.01]), fit)
    assert not indistinguishable(fit * 1.5, fit)
    assert indistinguishable(fit * 0.5, fit)  # better is never worse
    # a rise every demonstration shares but far below the noise (a warm re-solve of the same weights) is no rise
    assert indistinguishable(fit + 1e-6, fit)
    # beyond the noise (δm = 0.44 here) but not consistent: not told apart either
    assert indistinguishable(fit + np.array([2.5, -1.0, 0.2, -0.6, 1.4]), fit)
    assert not indistinguishable(np.array([np.nan, 1, 1, 1, 1.0]), fit)
    assert merit_noise(np.array([1.0, 1.0])) == 1e-12  # no spread: the floor


def test_directions_are_said_in_words():
    v = np.zeros((3, 7))
    v[0, ACC], v[2, ACC], v[1, FEATURES.index("joint_torque")] = 0.6, 0.6, -0.5
    assert describe_direction(v) == "joint_acceleration (windows 1, 3) against joint_torque (window 2)"
    one = np.zeros((3, 7))
    one[0, FEATURES.index("energy")] = 1.0
    assert describe_direction(one) == "energy (window 1) alone"
    one[1, FEATURES.index("energy")] = 0.8
    assert describe_direction(one) == "energy (windows 1-2) together"


def test_the_claim_is_supported_contradicted_or_undetermined_over_the_samples():
    k, s = 40, 8
    shares = np.full((k, s, 7), 1 / 7)
    shares[:, [0, -1], ACC] = 0.6
    assert claim_verdict(shares)["verdict"] == "supported"
    shares[:, [0, -1], ACC] = 0.01
    assert claim_verdict(shares)["verdict"] == "contradicted"
    shares[: k // 2, [0, -1], ACC] = 0.6
    verdict = claim_verdict(shares)
    assert verdict["verdict"] == "undetermined" and verdict["fraction"] == 0.5
    assert claim_verdict(shares[:, :2])["verdict"] == "not applicable"
    # one shape whatever the verdict: what a reader of MODEL.json or results.json can rely on
    assert (
        set(claim_verdict(shares[:, :2]))
        == set(claim_verdict(shares))
        == {"verdict", "fraction", "n_samples", "reason"}
    )


def _fit_with_samples(trials, out) -> None:
    """``reachirl fit`` of S01's P2 reaches, 2 windows, with 25 weight samples."""
    argv = ["fit", str(trials), "--sections", "2", "--nodes", "40", "--max-iter", "3", "--subject", "S01"]
    assert main([*argv, "--posture", "P2", "--uncertainty", "25", "--out", str(out)]) == 0


def test_fit_uncertainty_writes_samples_in_the_units_of_the_weights(recorded, tmp_path, capsys):
    out = tmp_path / "m.json"
    _fit_with_samples(recorded / "trials.npz", out)
    model = json.loads(out.read_text())
    u = model["uncertainty"]
    # the summary line says how many shares the data leaves undetermined, counted from the written intervals
    n_undetermined = sum(not d for row in u["share_intervals"]["determined"] for d in row)
    said = capsys.readouterr().out
    assert f"{n_undetermined} of 14 cost shares undetermined" in said
    # a claim that does not apply says so and why (it was left out of the line, which a reader searched for it)
    assert "the paper's claim: not applicable (needs at least 3 windows)" in said
    samples = np.array(u["weight_samples"])
    assert samples.shape == (25, 2, 7) and np.all(samples > 0) and np.all(np.isfinite(samples))
    lo, hi = np.array(u["share_intervals"]["low"]), np.array(u["share_intervals"]["high"])
    assert lo.shape == (2, 7) and np.all(lo <= hi) and np.all((lo >= 0) & (hi <= 1))
    shares = np.array(u["share_samples"])
    np.testing.assert_allclose(shares.sum(axis=2), 1.0)
    assert u["determination"]["n_directions"] == 14
    assert 0 <= u["checked"]["indistinguishable"] <= u["checked"]["solved"] == 10
    # the same seed gives the same samples; another seed others
    again = tmp_path / "again.json"
    _fit_with_samples(recorded / "trials.npz", again)
    assert json.loads(again.read_text())["uncertainty"]["weight_samples"] == u["weight_samples"]


def test_a_removed_feature_has_no_weight_in_any_sample(fitted):
    _, trials = fitted
    mask = np.ones(7, dtype=bool)
    mask[FEATURES.index("torque_change")] = False
    est = MOIRL(2, n_nodes=40, max_iter=2, feature_mask=mask, uncertainty=20).fit(trials)
    samples = np.array(est.uncertainty_["weight_samples"])
    assert np.all(samples[:, :, ~mask] == 0) and np.all(samples[:, :, mask] > 0)
    assert est.uncertainty_["determination"]["n_directions"] == 12
    with pytest.raises(ValueError, match="feature_mask must be booleans of shape"):
        MOIRL(2, feature_mask=np.ones(3, dtype=bool)).fit(trials)
    with pytest.raises(ValueError, match="uncertainty must be a number of samples from 20 to 1000"):
        MOIRL(2, uncertainty=5).fit(trials)


def test_a_share_the_fit_held_fixed_is_never_determined(fitted, tmp_path):
    # a frozen window's shares (and a removed feature's) are the same in every draw: their intervals were zero wide
    # and read as determined ("7 of 16 determined" with the data determining none of them), hatched as findings
    _, trials = fitted
    mask = np.ones(7, dtype=bool)
    mask[FEATURES.index("torque_change")] = False
    est = MOIRL(2, n_nodes=40, max_iter=2, feature_mask=mask, uncertainty=20, experimental={"frozen_windows": [0]}).fit(
        trials
    )
    iv = est.uncertainty_["share_intervals"]
    width = np.subtract(iv["high"], iv["low"])
    det = np.array(iv["determined"])
    assert np.all(width[0] < 1e-9) and np.all(width[1, ~mask] < 1e-9)  # held fixed: the same in every draw
    assert not det[0].any() and not det[1, ~mask].any()
    # nor do their zero widths enter the mean width: window 2's six learned shares alone (under the prior alone
    # about 0.95 wide; averaged with the eight held-fixed zeros it read 0.4)
    assert iv["learned"] == [[False] * 7, mask.tolist()]
    assert mean_width(iv) == pytest.approx(width[1, mask].mean())
    assert est.uncertainty_["prior"]["mean_width"] > 0.8
    # the mask is read back with the model, and a damaged one is refused naming the field
    d = json.loads(save_model(tmp_path / "m.json", LearnedModel.from_estimator(est, trials)).read_text())
    check_model_dict(d, "m.json")
    d["uncertainty"]["share_intervals"]["learned"] = [[True] * 7]
    with pytest.raises(InputError, match=r"m\.json.*'uncertainty\.share_intervals'.*'learned'"):
        check_model_dict(d, "m.json")
    # the data's own narrow intervals are still determined (the rule above, on draws)
    draws = np.zeros((400, 2, 7))
    draws[:, :, 0] = np.linspace(0.10, 0.20, 400)[:, None]
    draws[:, :, 1:] = (1 - draws[:, :, :1]) / 6
    free = np.ones((2, 7), dtype=bool)
    free[0] = False
    assert share_intervals(draws, free=free)["determined"] == [[False] * 7, [True] * 7]
    one = np.zeros((2, 7), dtype=bool)
    one[:, 0] = True  # a window with one learned weight: its share is 1 whatever the weight
    assert not np.any(share_intervals(draws, free=one)["determined"])


def test_the_claim_does_not_apply_where_the_fit_held_joint_accelerations_share(fitted):
    # with the first window frozen at w0, its joint-acceleration share is the same in every draw: the verdict (22 %
    # of the draws, "undetermined" on S01's P2) was read on a share the data had no say in; with the feature
    # removed its share is 0 everywhere, and the claim read "contradicted"
    _, trials = fitted
    est = MOIRL(3, n_nodes=40, max_iter=1, uncertainty=20, experimental={"frozen_windows": [2]}).fit(trials)
    claim = est.uncertainty_["claim"]
    assert claim["verdict"] == "not applicable" and "window(s) 3" in claim["reason"]
    assert est.uncertainty_["prior"]["claim_fraction"] is None
    draws = np.full((400, 3, 7), 1 / 7)
    free = np.ones((3, 7), dtype=bool)
    assert claim_verdict(draws, free)["verdict"] == "contradicted"  # learned everywhere: the rule as before
    frozen = free.copy()
    frozen[0] = False
    removed = free.copy()
    removed[:, ACC] = False
    for held in (frozen, removed):
        claim = claim_verdict(draws, held)
        assert claim["verdict"] == "not applicable" and claim["fraction"] is None
        assert "held fixed" in claim["reason"]


def test_a_merit_rise_is_said_in_units_of_the_merit_noise():
    """δm of errors 1…5: t₀.₉₅(4) · sd / √5 = 2.1318 · 1.5811 / 2.2361 = 1.5074."""
    fit = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    assert rise_over_noise(fit + 3.0148, fit) == pytest.approx(2.0, rel=1e-4)
    assert rise_over_noise(fit - 0.75370, fit) == pytest.approx(-0.5, rel=1e-4)


def test_the_data_tells_weights_far_from_the_fit_from_it_but_not_the_fit_itself(fitted, monkeypatch):
    from reachirl.irl import uncertainty

    est, _ = fitted
    own = versus_fit(est, est._effective(est._w_fit))  # re-solved warm: the same reaches
    assert own["converged"] and own["verdict"] == "as good" and abs(own["rise_over_noise"]) < 0.01
    far = est._effective(est._w_fit).copy()
    far[:, FEATURES.index("energy")] *= 1e3  # a cost made of energy alone: another reach
    told = versus_fit(est, far)
    assert told["converged"] and told["verdict"] == "worse" and told["rise_over_noise"] > 1.0
    # weights whose reaches the demonstrations prefer to the fit's: the fit stopped short of them
    e_fit = uncertainty.fit_errors(est)
    monkeypatch.setattr(uncertainty, "rollout_errors", lambda est, w: (0.2 * e_fit, [], 1))
    preferred = versus_fit(est, far)
    assert preferred["verdict"] == "better" and preferred["rise_over_noise"] < -1.0


def test_weights_whose_doc_fails_are_said_to_have_failed_not_to_be_told_apart(fitted, monkeypatch):
    from reachirl.irl import uncertainty

    est, _ = fitted
    monkeypatch.setattr(uncertainty, "rollout_errors", lambda est, w: (None, [], 1))
    assert versus_fit(est, est._w_fit) == {"converged": False, "verdict": None, "rise_over_noise": None}


def test_the_checked_samples_use_the_merits_own_errors(fitted):
    est, _ = fitted
    states = [est._state(i, t, s) for i, (t, s) in enumerate(zip(est.tasks_, est.train_solutions_, strict=True))]
    assert np.mean(_errors(est, states)) == pytest.approx(est.merit_, rel=1e-12)


@pytest.mark.slow
def test_coverage_of_the_true_shares_on_a_small_virtual_set(recorded):
    """On virtual subjects the 95 % intervals contain the true cost shares (on the truth's own reach, seen as
    recorded) in at least 90 % of the cells of every fit: measured 0.95-1.0 (mean 0.97) over 35 fits of seven
    populations. The truth has shares of exactly 0 and 1, which a prior that ruled them out would miss."""
    from reachirl.experiments.analysis import reference_features, true_weights
    from reachirl.experiments.datasets import load

    ds = load(recorded / "raw")
    cover = []
    for posture in ("P2", "P4"):
        trials = select_trials(list(ds.trials), subjects=["S01"], postures=[posture])
        est = MOIRL(8, n_nodes=100, uncertainty=40).fit(trials)
        w_true = true_weights(ds.truth, [t.trial_id for t in trials])
        phi = reference_features(trials, w_true, 100, "casadi", True)
        true = w_true * phi / (w_true * phi).sum(axis=1, keepdims=True)
        lo = np.array(est.uncertainty_["share_intervals"]["low"])
        hi = np.array(est.uncertainty_["share_intervals"]["high"])
        cover.append(np.mean((true >= lo - 0.005) & (true <= hi + 0.005)))
        # the truth has the paper's claim: the posterior's draws (not 40 samples' chance) must not contradict it
        claim = est.uncertainty_["claim"]
        assert claim["n_samples"] == 4000 and claim["verdict"] != "contradicted", claim
        # the reaches explain the truth's cost no worse than the fit's (measured: as good on all 40 8-window fits
        # of eight built-in populations): were it worse, the fit would hold something the truth's reaches lack
        judged = versus_fit(est, est._effective(w_true))
        assert judged["converged"] and judged["verdict"] in ("as good", "better"), judged
    assert min(cover) >= 0.9, cover


def test_a_pooled_fit_says_how_much_pooling_narrows_the_intervals(recorded):
    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"])
    est = MOIRL(2, n_nodes=40, max_iter=2, uncertainty=20).fit(trials)
    pooling = est.uncertainty_["pooling"]
    assert sorted(pooling["per_task"]) == ["S01/P2", "S01/P4"]
    for rec in (pooling["pooled"], *pooling["per_task"].values()):
        assert 0 <= rec["mean_width"] <= 1 and 0 <= rec["undetermined_fraction"] <= 1
    # more demonstrations determine at least as much: the pooled Gauss-Newton model adds the tasks' curvatures
    assert pooling["pooled"]["n_determined"] >= min(r["n_determined"] for r in pooling["per_task"].values())


@pytest.mark.parametrize("rollout", ["per_demo", "mean"])
def test_pooling_compares_the_data_s_tasks_whatever_the_rollouts(recorded, rollout):
    # docs/outputs.md: pooling is there with trials of several (subject, posture) tasks, per_task by subject/posture;
    # per_demo listed each trial as a task (and pooled one posture), mean left several postures without a record
    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"])
    est = MOIRL(1, n_nodes=20, max_iter=1, rollout=rollout, uncertainty=20).fit(trials)
    assert sorted(est.uncertainty_["pooling"]["per_task"]) == ["S01/P2", "S01/P4"]
    one = select_trials(trials, postures=["P2"])
    assert MOIRL(1, n_nodes=20, max_iter=1, rollout=rollout, uncertainty=20).fit(one).uncertainty_["pooling"] is None


def test_a_checked_sample_whose_doc_failed_is_counted_as_failed_not_as_solved(fitted, monkeypatch):
    """A solver failure is counted and reported apart: before, ``solved`` was always ``n_check`` and a sample
    whose re-solve failed passed for one the demonstrations tell apart from the fit."""
    from reachirl.irl import uncertainty

    est, trials = fitted
    real, calls = uncertainty.rollout_errors, []

    def every_other_fails(est_, w):
        calls.append(1)
        errors, cand, runs = real(est_, w)
        return (None if len(calls) % 2 else errors), cand, runs

    monkeypatch.setattr(uncertainty, "rollout_errors", every_other_fails)
    u = uncertainty.weight_uncertainty(est, trials, n_samples=20, n_check=4)
    assert len(calls) == 4
    assert u["checked"]["failed"] == 2 and u["checked"]["solved"] == 2
    assert 0 <= u["checked"]["indistinguishable"] <= 2


def test_a_fit_whose_rollout_has_no_sensitivity_says_so_instead_of_failing(fitted, monkeypatch):
    from reachirl.irl import uncertainty

    def degenerate(*args, **kwargs):
        raise ValueError("the KKT matrix is singular (a degenerate optimum)")

    monkeypatch.setattr(uncertainty, "weight_jacobian", degenerate)
    _, trials = fitted
    est = MOIRL(2, n_nodes=40, max_iter=1, uncertainty=20).fit(trials)
    assert est.uncertainty_ is None
    assert any(w.startswith("no weight samples: the KKT matrix is singular") for w in est.warnings_)


def test_without_data_the_intervals_rule_out_no_printable_share():
    """Where the data says nothing, the samples are the prior's, and its 95 % interval of every share of a
    7-feature window reaches from 0 to 0.995 (the report's precision): a feature that alone makes a window's cost
    is not excluded before the data speaks."""
    d, m, p = 10, 20, 7
    J, r = np.zeros((d, m, p)), 0.1 * np.random.default_rng(1).normal(size=(d, m))
    mean, cov, _ = laplace_posterior(r, J, np.full(p, 3.0), np.zeros(p))
    np.testing.assert_allclose(mean, 0.0, atol=1e-12)
    np.testing.assert_allclose(cov, PRIOR_LOG_SD**2 * np.eye(p), rtol=1e-12)
    eta = np.random.default_rng(2).multivariate_normal(mean, cov, size=200_000)
    intervals = share_intervals(cost_shares(np.exp(eta)[:, None, :], np.ones((1, p))))
    assert np.all(np.array(intervals["low"]) <= 0.005) and np.all(np.array(intervals["high"]) >= 0.995)
    assert not np.any(intervals["determined"])


def test_the_posterior_follows_the_data_where_it_is_determined_and_the_prior_elsewhere():
    """Two log-weights: the residuals see only the first. Its posterior sits at the Gauss-Newton model's minimum
    (the fit moved by the model's step ``−g / a``) with the variance the model gives (τ / a); the second keeps the
    prior's mean and spread."""
    rng = np.random.default_rng(0)
    d, m = 12, 30
    J = np.zeros((d, m, 2))
    J[:, :, 0] = rng.normal(size=(d, m))
    r = 0.1 * rng.normal(size=(d, m))
    eta_hat, eta_prior = np.array([1.0, 2.0]), np.array([0.0, -1.0])
    mean, cov, tau = laplace_posterior(r, J, eta_hat, eta_prior, prior_sd=3.0)
    a = np.sum(J[:, :, 0] ** 2) / d
    assert tau == pytest.approx(merit_noise(np.sum(r**2, axis=1)) / 4)
    assert cov[0, 0] == pytest.approx(1 / (a / tau + 1 / 9))
    g = np.sum(J[:, :, 0] * r) / d
    assert mean[0] == pytest.approx(cov[0, 0] * ((a * 1.0 - g) / tau + 0.0 / 9))
    assert mean[1] == pytest.approx(-1.0) and cov[1, 1] == pytest.approx(9.0) and cov[0, 1] == pytest.approx(0.0)


def test_a_fit_that_stopped_short_of_the_minimum_is_not_the_posterior_s_centre():
    """Residuals linear in the log-weights, ``r_d = J_d (η − η*) + ε_d``, seen from a fit ``η̂`` that stopped
    short of ``η*``: the posterior (prior too wide to matter) centres on the least-squares minimum, where the
    data puts the weights, and holds ``η*`` within its 95 % ellipsoid; centred on the fit, it would exclude it."""
    rng = np.random.default_rng(3)
    d, m, p = 20, 40, 3
    J = rng.normal(size=(d, m, p))
    eta_star, eta_hat = np.array([0.5, -1.0, 2.0]), np.array([0.8, -0.6, 1.5])
    r = np.einsum("dmp,p->dm", J, eta_hat - eta_star) + 0.05 * rng.normal(size=(d, m))
    mean, cov, _ = laplace_posterior(r, J, eta_hat, np.zeros(p), prior_sd=1e6)
    A, b = J.reshape(-1, p), (r - np.einsum("dmp,p->dm", J, eta_hat)).reshape(-1)
    np.testing.assert_allclose(mean, np.linalg.lstsq(A, -b, rcond=None)[0], atol=1e-8)
    assert np.linalg.norm(mean - eta_star) < 0.01 < np.linalg.norm(eta_hat - eta_star) / 10
    z = (mean - eta_star) @ np.linalg.solve(cov, mean - eta_star)
    assert z < stats.chi2.ppf(0.95, p)
    assert (eta_hat - eta_star) @ np.linalg.solve(cov, eta_hat - eta_star) > 10 * stats.chi2.ppf(0.95, p)


def test_the_shares_a_fit_shows_lie_in_their_own_intervals(recorded):
    """The shares quoted and drawn (on the fit's own reach) are those the intervals bracket: every determined one
    lies in its interval. The recorded demonstrations' shares would not: their noise inflates joint acceleration
    and torque change, and a determined share moves outside its interval."""
    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])
    # one rollout per demonstration: each compared with the DOC from its own start, the data determines shares
    est = MOIRL(2, n_nodes=40, max_iter=5, uncertainty=20, rollout="per_demo").fit(trials)
    iv = est.uncertainty_["share_intervals"]
    lo, hi, det = (np.array(iv[k]) for k in ("low", "high", "determined"))
    assert det.sum() >= 1  # the check below is about determined shares, not only about the prior's wide ones
    shown = cost_shares(est.weights_, est.reach_features())
    assert np.all((shown[det] >= lo[det] - 0.005) & (shown[det] <= hi[det] + 0.005)), (shown, lo, hi)
    on_demos = cost_shares(est.weights_, np.mean([t.features(40, 2) for t in trials], axis=0))
    assert not np.all((on_demos[det] >= lo[det]) & (on_demos[det] <= hi[det]))
    # what the prior alone gives, beside it: wider intervals (the data narrows them where it determines them)
    prior = est.uncertainty_["prior"]
    assert float(np.mean(hi - lo)) < prior["mean_width"] <= 1.0
    assert prior["claim_fraction"] is None  # two windows: the claim needs onset, mid-reach and end


def test_a_narrow_interval_that_misses_the_fits_share_is_not_determined():
    """A share is quoted only where the data pins it down around the fit's own value: narrow and containing it."""
    draws = np.zeros((400, 1, 7))
    draws[:, 0, 0] = np.linspace(0.10, 0.20, 400)  # narrow: 0.1 wide
    draws[:, 0, 1] = np.linspace(0.0, 0.9, 400)  # wide
    inside, outside = np.full((1, 7), 0.15), np.full((1, 7), 0.15)
    outside[0, 0] = 0.22  # 0.02 above the interval's top, beyond the printed precision
    assert share_intervals(draws, inside)["determined"][0][0]
    assert not share_intervals(draws, outside)["determined"][0][0]  # the fit lies outside its own narrow interval
    assert not share_intervals(draws, inside)["determined"][0][1]  # wide: undetermined wherever the fit lies
    assert share_intervals(draws)["determined"][0][0]  # without the fit's shares: the width alone


def test_uncertainty_true_is_the_bare_flag_s_default_and_false_is_none(recorded):
    # design.md: `fit ... --uncertainty` (and `MOIRL(..., uncertainty=...)`); the bare flag draws 40 samples, and
    # MOIRL(uncertainty=True) refused True ("must be a number of samples") instead of doing the same
    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])
    est = MOIRL(1, n_nodes=20, max_iter=1, uncertainty=True).fit(trials)
    assert est.uncertainty_["n_samples"] == 40
    assert np.shape(est.uncertainty_["weight_samples"]) == (40, 1, 7)
    from reachirl.cli import build_parser

    bare = build_parser().parse_args(["fit", "t.npz", "--sections", "1", "--out", "m.json", "--uncertainty"])
    assert bare.uncertainty == est.uncertainty_["n_samples"]  # the same number as the bare flag
    assert MOIRL(1, n_nodes=20, max_iter=1, uncertainty=False).fit(trials).uncertainty_ is None
    with pytest.raises(ValueError, match=r"uncertainty must be a number of samples from 20 to 1000, True \(40\)"):
        MOIRL(1, uncertainty=1000.5).fit(trials)


def test_uncertainty_zero_is_none_as_in_a_run_file(recorded):
    # a run file's `uncertainty = 0` (reproduce) means no samples; MOIRL(uncertainty=0) refused it
    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])
    for none in (0, np.int64(0)):
        assert MOIRL(1, n_nodes=20, max_iter=1, uncertainty=none).fit(trials).uncertainty_ is None
    for bad in (19, -1, 0.0):
        with pytest.raises(ValueError, match=r"uncertainty must be .*, or 0, False or None for none, got "):
            MOIRL(1, n_nodes=20, max_iter=1, uncertainty=bad).fit(trials)


def test_numpy_scalars_stand_for_the_python_values_they_hold(recorded, tmp_path):
    # MOIRL(uncertainty=np.True_) was refused ("must be a number of samples") where True draws 40 samples, and a
    # numpy boolean in `experimental` was refused where True or False was taken
    from reachirl.irl.model import LearnedModel, load_model, save_model

    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])
    est = MOIRL(
        np.int64(1),
        n_nodes=np.int64(20),
        max_iter=np.int64(1),
        seed_form=np.False_,
        uncertainty=np.True_,
        random_state=np.int64(0),
        experimental={"line_search_stop": np.False_, "max_tries": np.int64(3), "beta": np.float64(1e-9)},
    ).fit(trials)
    assert est.uncertainty_["n_samples"] == 40
    assert est.options_.line_search_stop is False and est.options_.max_tries == 3
    assert type(est.options_.max_tries) is int and type(est.options_.beta) is float
    save_model(tmp_path / "m.json", LearnedModel.from_estimator(est, trials))  # the record is plain JSON
    assert load_model(tmp_path / "m.json").info["options"]["line_search_stop"] is False
    assert MOIRL(1, n_nodes=20, max_iter=1, uncertainty=np.False_).fit(trials).uncertainty_ is None
    # a boolean is no count, numpy's or Python's
    for bad in (True, np.True_):
        with pytest.raises(ValueError, match=r"max_iter must be an integer >= 1, got (np\.)?True"):
            MOIRL(1, n_nodes=20, max_iter=bad).fit(trials)
    with pytest.raises(ValueError, match=r"max_tries must be an integer, not a boolean \(got True\)"):
        MOIRL(1, n_nodes=20, experimental={"max_tries": np.True_}).fit(trials)


def test_a_claim_verdict_the_prior_alone_gives_is_said_to_be_no_finding():
    """`fit --sections 40 --uncertainty` on UE-ADL's ADL001: 0 of 280 directions determined, yet "the paper's claim
    ...: contradicted (2 % of the posterior; 2 % under the prior alone)", and the report's "contradicted (2 % of
    draws; 2 %)": with many windows the prior alone contradicts the claim, and the verdict read as the data's. Now
    the summary and the report say it is the prior's verdict, not a finding; an undetermined one, or one the prior
    alone does not give, reads as before."""
    from types import SimpleNamespace

    from reachirl.cli.fit import _claim_words
    from reachirl.experiments.cost import cost_section
    from reachirl.irl.uncertainty import prior_gives_verdict

    contradicted = {"verdict": "contradicted", "fraction": 0.02225, "n_samples": 4000, "reason": None}
    prior = {"mean_width": 0.985, "claim_fraction": 0.02475}
    assert prior_gives_verdict(contradicted, prior)
    assert not prior_gives_verdict(contradicted, {"claim_fraction": 0.07})  # the data's own verdict
    assert not prior_gives_verdict({"verdict": "undetermined", "fraction": 0.02}, {"claim_fraction": 0.01})
    assert prior_gives_verdict({"verdict": "supported", "fraction": 0.99}, {"claim_fraction": 0.98})
    words = _claim_words(contradicted, prior)
    assert words.endswith(
        "contradicted (2 % of the posterior; 2 % under the prior alone, which gives the same verdict without the "
        "data: not a finding)"
    ), words
    assert _claim_words({**contradicted, "verdict": "undetermined", "fraction": 0.07}, prior).endswith(
        "undetermined (7 % of the posterior; 2 % under the prior alone)"
    )
    unc = {
        "determination": {"n_determined": 0, "n_directions": 280, "determined": []},
        "share_intervals": {"low": np.zeros((40, 7)).tolist(), "high": np.ones((40, 7)).tolist()},
        "prior": prior,
        "claim": contradicted,
        "checked": {"solved": 10, "indistinguishable": 0},
    }
    unc["share_intervals"]["determined"] = np.zeros((40, 7), bool).tolist()
    run = SimpleNamespace(
        results={"moirl-forward-s40": {"key": "moirl-forward-s40", "unit": {"posture": "forward"}, "uncertainty": unc}}
    )
    (row,) = [line for line in cost_section(run) if line.startswith("| moirl-forward-s40 |")]
    assert "| contradicted (2 % of draws; 2 %; the prior's verdict too, not a finding) |" in row, row


def test_weight_samples_from_one_demonstration_warn_that_their_noise_is_a_stand_in(recorded):
    """`fit` on a single reach with --uncertainty said "4 of 56 weight directions determined by the trials" (more
    than five reaches of the same arm determine) and nothing else: with one demonstration there is no spread to
    measure δm from, and it is the merit itself. Now the fit warns; two demonstrations do not."""
    from reachirl.irl.moirl import ONE_DEMO_SAMPLES

    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])
    one = MOIRL(3, n_nodes=40, max_iter=2, uncertainty=20).fit(trials[:1])
    assert one.uncertainty_ is not None and ONE_DEMO_SAMPLES in one.warnings_
    two = MOIRL(3, n_nodes=40, max_iter=2, uncertainty=20).fit(trials[:2])
    assert ONE_DEMO_SAMPLES not in two.warnings_
    assert ONE_DEMO_SAMPLES not in MOIRL(3, n_nodes=40, max_iter=2).fit(trials[:1]).warnings_


def test_pooling_per_task_from_one_demonstration_warns_that_its_noise_is_a_stand_in(recorded, tmp_path, capsys):
    """pooling.per_task of a task with one trial used merit_noise's stand-in (the merit itself) without the warning
    a single-demonstration fit gives; now it warns, naming the tasks, and `reachirl fit` says it as it says the
    single-demonstration one."""
    from reachirl.cli import main
    from reachirl.data.trial import save_trials
    from reachirl.irl.moirl import ONE_DEMO_SAMPLES

    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"])
    p2, p4 = (select_trials(trials, postures=[p]) for p in ("P2", "P4"))
    est = MOIRL(1, n_nodes=20, max_iter=1, uncertainty=20).fit([*p2[:2], p4[0]])
    assert sorted(est.uncertainty_["pooling"]["per_task"]) == ["S01/P2", "S01/P4"]
    said = (
        "uncertainty.pooling.per_task from one demonstration for 1 task(s) (S01/P4): with no second one to measure "
        "the task's trial-to-trial spread, the merit rise it can tell from noise is taken as its merit itself, so "
        "those tasks' widths rest on that stand-in, not on measured noise"
    )
    assert said in est.warnings_ and ONE_DEMO_SAMPLES not in est.warnings_
    both = MOIRL(1, n_nodes=20, max_iter=1, uncertainty=20).fit([*p2[:2], *p4[:2]])
    assert not any("pooling.per_task" in w for w in both.warnings_)
    path = save_trials(tmp_path / "pooled_one_p4.npz", [*p2[:2], p4[0]])
    out = tmp_path / "pooled_one_p4.json"
    argv = ["fit", str(path), "--sections", "1", "--nodes", "20", "--max-iter", "1", "--uncertainty", "20"]
    assert main([*argv, "--out", str(out)]) == 0
    assert f"warning: {said}" in capsys.readouterr().err


@pytest.mark.parametrize(("fraction", "expected"), [(0.01, True), (0.5, False)])
def test_the_claim_record_says_when_its_verdict_is_the_prior_s(fitted, monkeypatch, fraction, expected):
    """MODEL.json's `claim` carries `prior_verdict`: true when the draws under the prior alone give the posterior's
    verdict too (a researcher reading the JSON sees it is no finding), false when the prior alone leaves it open."""
    from reachirl.irl import uncertainty

    est, trials = fitted
    real = uncertainty.claim_verdict
    calls = []

    def verdict(shares, free=None):
        calls.append(1)
        out = real(shares, free)
        if len(calls) == 1:  # the prior's draws
            return {**out, "fraction": fraction}
        return {**out, "verdict": "contradicted", "fraction": 0.01}  # the posterior's: contradicted

    monkeypatch.setattr(uncertainty, "claim_verdict", verdict)
    unc = weight_uncertainty(est, trials, 20, 0, n_check=0)
    assert unc["claim"]["verdict"] == "contradicted" and unc["prior"]["claim_fraction"] == fraction
    assert unc["claim"]["prior_verdict"] is expected
