"""The scale-free MO-IRL step: its value against an independent formula, its gradient, the trust region
(``Δω > −ω``, at most ``max_ratio``), invariance to the features' units, the demonstrations' features as the DOC
computes them, and the fixed point at the true weights."""

import numpy as np
import pytest

from moirl_settings import moirl_params, whole_rollout_moirl
from reachirl import ReachingTask, solve_doc
from reachirl.data.trial import trial_from_solution
from reachirl.features import windowed_features
from reachirl.irl.moirl import MOIRL as _MOIRL
from reachirl.irl.moirl import mean_task
from reachirl.irl.objective import channel_scale, feature_scale, merit, solve_step, step_objective

MOIRL = whole_rollout_moirl(_MOIRL)  # the iteration on whole rollouts, full-state merit

N_NODES = 40


def _problem(rng, n_demo=4, n_windows=3, n_traj=2):
    theta = rng.uniform(0.02, 0.5, (n_windows, 7))
    phi_i = rng.uniform(0.2, 2.0, (n_traj, n_windows, 7))
    phi_star = rng.uniform(0.2, 2.0, (n_demo, n_windows, 7))
    return theta, [(phi_i, phi_star, np.ones(n_demo))]


def _objective_by_hand(eta, theta, phi_i, phi_star, beta, lam, log_sigma):
    """The subproblem written out term by term with plain loops (no shared code)."""
    w_new = theta * np.exp(eta)
    total = 0.0
    for d in range(phi_star.shape[0]):
        z = 1.0
        for i in range(phi_i.shape[0]):
            c = 0.0
            for s in range(theta.shape[0]):
                for j in range(7):
                    c += w_new[s, j] * (phi_i[i, s, j] - phi_star[d, s, j])
            z += np.exp(-c)
        total += -np.log(1.0 / z)
    total += 0.5 * beta * np.sum(eta**2)
    log_w = np.log(w_new) - log_sigma
    for s in range(theta.shape[0] - 1):
        for j in range(7):
            total += 0.5 * lam * (log_w[s + 1, j] - log_w[s, j]) ** 2
    return total


@pytest.mark.parametrize("lam", [0.0, 0.7])
def test_step_objective_matches_the_written_out_formula(lam):
    rng = np.random.default_rng(1)
    theta, groups = _problem(rng)
    eta = rng.normal(0.0, 0.5, theta.shape)
    log_sigma = rng.normal(0.0, 1.0, theta.shape)
    value, _ = step_objective(eta, theta, groups, beta=0.3, smoothness=lam, log_sigma=log_sigma)
    expected = _objective_by_hand(eta, theta, groups[0][0], groups[0][1], 0.3, lam, log_sigma)
    assert value == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("lam", [0.0, 0.7])
def test_step_objective_gradient_matches_finite_differences(lam):
    rng = np.random.default_rng(2)
    theta, groups = _problem(rng)
    eta = rng.normal(0.0, 0.5, theta.shape)
    log_sigma = rng.normal(0.0, 1.0, theta.shape)
    _, grad = step_objective(eta, theta, groups, beta=0.3, smoothness=lam, log_sigma=log_sigma)
    h = 1e-6
    fd = np.zeros_like(eta)
    for idx in np.ndindex(eta.shape):
        e = np.zeros_like(eta)
        e[idx] = h
        fd[idx] = (
            step_objective(eta + e, theta, groups, 0.3, lam, log_sigma)[0]
            - step_objective(eta - e, theta, groups, 0.3, lam, log_sigma)[0]
        ) / (2 * h)
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-8)


def test_the_step_does_not_depend_on_the_features_units():
    rng = np.random.default_rng(4)
    phi_i = rng.uniform(0.2, 2.0, (1, 2, 7))
    phi_star = rng.uniform(0.2, 2.0, (4, 2, 7))
    w = rng.uniform(0.01, 1.0, (2, 7))
    units = 10.0 ** rng.uniform(-6, 6, 7)  # each feature in another unit: Φ_j·c_j, ω_j/c_j
    steps = []
    for c in (np.ones(7), units):
        ps, pi, wc = phi_star * c, phi_i * c, w / c
        sigma = feature_scale(ps)
        dw, _ = solve_step(wc, sigma, [(pi / sigma, ps / sigma, np.ones(4))], beta=0.1, max_ratio=10.0)
        steps.append(dw * c)  # back in the first units
    np.testing.assert_allclose(steps[1], steps[0], rtol=1e-6, atol=1e-12 * np.abs(steps[0]).max())


def test_feature_scale_is_the_demonstrations_mean_with_a_floor():
    phi = np.array([[[1.0, 0.0, 4.0]], [[3.0, 0.0, 2.0]]])  # 2 demos, 1 window, 3 features
    phi = np.concatenate([phi, np.array([[[2.0, 0.0, 1.0]], [[2.0, 0.0, 1.0]]])], axis=1)  # a second window
    sigma = feature_scale(phi, floor=1e-3)
    np.testing.assert_allclose(sigma[:, 0], [2.0, 2.0])
    np.testing.assert_allclose(sigma[:, 2], [3.0, 1.0])
    assert np.all(sigma[:, 1] > 0)  # an absent feature gets a positive floor, never a division by zero


def test_normalised_merit_weighs_each_channel_by_its_spread():
    t = np.linspace(0.0, 1.0, 11)
    demo = np.stack([t, 2 * t, 10 * np.sin(np.pi * t), 0 * t], axis=1)[None]
    w = channel_scale(demo)
    np.testing.assert_allclose(w[:3], 1.0 / np.var(demo.reshape(-1, 4), axis=0)[:3])
    off = demo[0] + np.array([0.1, 0.0, 0.0, 0.0])
    assert merit(demo, off, w) == pytest.approx(0.01 / np.var(t), rel=1e-12)


# ---------------------------------------------------------------------- the demonstrations and the DOC


@pytest.fixture(scope="module")
def doc_demos(arm):
    """Three DOC solutions of one reach under known 2-window weights, stored as trials."""
    w = np.array([[0.1, 0.2, 0.2, 0.01, 1e-5, 0.02, 0.05], [0.05, 1.0, 0.2, 0.002, 1e-5, 0.02, 0.05]])
    task = ReachingTask(arm, np.deg2rad([-90.0, 90.0]), 0.9 * arm.length, 0.7, n_nodes=N_NODES)
    sol = solve_doc(task, w)
    assert sol.converged
    return w, task, sol, [trial_from_solution(sol, arm, task.target_x, trial_id=str(i)) for i in range(3)]


def test_a_doc_solution_fed_back_as_a_demonstration_has_the_docs_own_features(doc_demos):
    _, task, sol, demos = doc_demos
    own = windowed_features(task.arm, sol.q, sol.qd, sol.tau, task.dt, 2)
    np.testing.assert_allclose(demos[0].features(N_NODES, 2), own, rtol=1e-9, atol=1e-12)
    _, qd, tau = demos[0].knots(N_NODES)
    np.testing.assert_allclose(tau, sol.tau, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(qd, sol.qd, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("cutoff", [None])
def test_the_true_weights_are_a_fixed_point_of_the_first_step(doc_demos, cutoff):
    """From the true weights, the rollout is the demonstration itself: the step must not move the weights
    by more than a few percent (with the default feature filter, which smooths the DOC's own path a little)."""
    w, task, _, demos = doc_demos
    est = MOIRL(2, n_nodes=N_NODES, experimental={"feature_cutoff": cutoff})
    starts = np.array([0])
    phi_star = est._demo_features(demos, starts)
    sigma = feature_scale(phi_star)
    rollout = solve_doc(mean_task(demos, N_NODES), w)
    phi_i = windowed_features(task.arm, rollout.q, rollout.qd, rollout.tau, task.dt, 2)[None]
    dw, _ = solve_step(w, sigma, [(phi_i / sigma, phi_star / sigma, np.ones(3))], beta=1.0)
    assert np.max(np.abs(dw / w)) < (1e-6 if cutoff is None else 0.05)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"scaling": "units"}, "scaling must be 'demo' or None"),
        ({"merit": "q"}, "merit must be 'state' or 'normalised'"),
        ({"max_ratio": 1.0}, "max_ratio must be > 1"),
        ({"smoothness": -1.0}, "smoothness must be a number >= 0 or 'cv'"),
        ({"smoothness": "loo"}, "smoothness must be a number >= 0 or 'cv'"),
        ({"smoothness": "cv", "cv_folds": 1}, "cv_folds must be >= 2"),
        ({"use_gamma": False}, "apply to the seed's raw form only"),
        ({"tol": -1e-3}, "tol must be a number >= 0"),
        ({"max_iter": 0}, "max_iter must be an integer >= 1"),
    ],
)
def test_bad_options_are_refused(doc_demos, kwargs, match):
    with pytest.raises(ValueError, match=match):
        MOIRL(2, n_nodes=N_NODES, **moirl_params(kwargs)).fit(doc_demos[3])


def test_smoothness_cv_chooses_from_the_grid_on_the_training_demonstrations(doc_demos):
    _, _, _, demos = doc_demos
    est = MOIRL(2, n_nodes=N_NODES, max_iter=2, experimental={"smoothness": "cv", "cv_folds": 3}).fit(demos)
    from reachirl.irl.moirl import SMOOTHNESS_GRID

    assert set(est.cv_scores_) == set(SMOOTHNESS_GRID)
    assert est.smoothness_ in SMOOTHNESS_GRID
    best = min(est.cv_scores_.values())
    assert est.cv_scores_[est.smoothness_] <= best * 1.01


def test_smoothness_cv_says_its_fold_fits_warnings_once_in_its_own(doc_demos, monkeypatch, caplog):
    # the fold fits logged their own warnings, which `reachirl fit` (caller_shows_fit_warnings) silenced for good:
    # neither on stderr nor in the model's info.warnings. Every step here only rescales: every fit stays at w0
    from reachirl.irl import moirl as moirl_module
    from reachirl.irl.base import caller_shows_fit_warnings

    _, _, _, demos = doc_demos
    monkeypatch.setattr(moirl_module, "solve_step", lambda w, *a, **k: (-0.9 * w, {"nit": 1}))
    params = {"smoothness": "cv", "cv_folds": 2, "fallback": None}
    est = MOIRL(2, n_nodes=N_NODES, max_iter=2, **moirl_params(params))
    with caplog.at_level("WARNING", logger="reachirl"), caller_shows_fit_warnings():
        est.fit(demos)
    assert not caplog.records  # the caller says them, from warnings_
    cv = [m for m in est.warnings_ if m.startswith("smoothness cross-validation")]
    n_fits = 2 * len(moirl_module.SMOOTHNESS_GRID)
    assert cv == [
        f"smoothness cross-validation: {n_fits} of {n_fits} fold fits were not fully learned ({n_fits} never left "
        f"the initial weights), so smoothness {est.smoothness_:g} was chosen partly on weights that were not learned"
    ]
    assert sum(m.startswith("never left the initial weights") for m in est.warnings_) == 1  # the fit's own
    caplog.clear()
    with caplog.at_level("WARNING", logger="reachirl"):  # a library fit logs each of its warnings_ once
        est.fit(demos)
    assert sorted(r.getMessage() for r in caplog.records) == sorted(est.warnings_)


def test_a_step_that_only_rescales_stops_the_fit_without_doc_solves(doc_demos, monkeypatch):
    from reachirl.irl import moirl as moirl_module

    _, _, _, demos = doc_demos
    monkeypatch.setattr(moirl_module, "solve_step", lambda w, *a, **k: (-0.9 * w, {"nit": 1}))
    est = MOIRL(2, n_nodes=N_NODES, max_iter=5, experimental={"fallback": None}).fit(demos)
    assert est.stop_reason_ == "step_only_rescales"
    assert est.n_doc_solves_ == est.history_[0]["doc_solves"]  # nothing spent on the null direction
    assert est.flag_ == "w0"


def test_the_line_search_spends_no_solve_on_steps_below_min_step(doc_demos, monkeypatch):
    from reachirl.irl import moirl as moirl_module

    _, _, _, demos = doc_demos
    monkeypatch.setattr(moirl_module, "solve_step", lambda w, *a, **k: (5e-4 * w, {"nit": 1}))
    monkeypatch.setattr(moirl_module, "_is_rescale", lambda w, dw: False)
    est = MOIRL(2, n_nodes=N_NODES, max_iter=3, experimental={"min_step": 1e-3, "fallback": None}).fit(demos)
    assert est.history_[1]["tries"] == 0 and est.stop_reason_ == "no_improving_step"
    assert est.n_doc_solves_ == est.history_[0]["doc_solves"]
    with pytest.raises(ValueError, match=r"min_step must be in \[0, 1\)"):
        MOIRL(2, n_nodes=N_NODES, experimental={"min_step": 1.5}).fit(demos)
