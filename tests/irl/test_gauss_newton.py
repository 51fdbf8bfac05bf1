"""The Gauss-Newton merit step: the DOC solution's derivative in its log-weights (implicit function theorem)
against re-solved finite differences, the observed state's derivative against finite differences of
:func:`observe`, the bounded least-squares step against its closed form, and the step inside MO-IRL."""

from dataclasses import replace

import numpy as np
import pytest

from moirl_settings import whole_rollout_moirl
from reachirl import FEATURES, ArmModel, ReachingTask, solve_doc
from reachirl.doc.observation import observe, observed_state_jacobian, rest_to_rest
from reachirl.doc.sensitivity import weight_jacobian
from reachirl.doc.task import rest_to_rest_knots
from reachirl.irl.moirl import MOIRL as _MOIRL
from reachirl.irl.objective import gauss_newton_step
from reachirl.virtual import knot_trials

MOIRL = whole_rollout_moirl(_MOIRL)  # the iteration on whole rollouts, full-state merit

N_NODES = 40


@pytest.fixture(scope="module")
def problem(arm):
    rng = np.random.default_rng(7)
    w = np.exp(rng.normal(0.0, 0.7, (3, 7))) * np.array([1.0, 1.0, 1.0, 1.0, 1e-2, 1.0, 1e-2])
    task = ReachingTask(arm, np.deg2rad([-80.0, 95.0]), 0.9 * arm.length, 0.8, n_nodes=N_NODES)
    sol = solve_doc(task, w)
    assert sol.converged
    return task, w, sol


def _resolved(task, w, s, j, h=1e-3, backend="casadi"):
    """Central difference of the solver's own solutions along log ω_{s,j}."""
    wp, wm = w.copy(), w.copy()
    wp[s, j] *= np.exp(h)
    wm[s, j] *= np.exp(-h)
    return (solve_doc(task, wp, backend=backend).q - solve_doc(task, wm, backend=backend).q) / (2 * h)


def test_the_weight_jacobian_matches_resolved_finite_differences(problem):
    task, w, sol = problem
    jac = weight_jacobian(task, w, sol)
    assert jac.shape == (N_NODES + 1, 2, 3, 7)
    np.testing.assert_array_equal(jac[0], 0.0)  # q0 is the task's
    for s, j in [(0, 3), (1, 2), (2, 6), (1, 1), (0, 0), (2, 4)]:
        fd = _resolved(task, w, s, j)
        assert np.linalg.norm(jac[:, :, s, j] - fd) <= 1e-2 * np.linalg.norm(fd) + 1e-7, (s, j)


def test_a_reach_whose_power_sits_at_zero_moves_as_its_re_solved_finite_differences():
    """A cost dominated by the energy: the optimum holds the joint power at zero (q̇ ⟂ τ) on every knot, each within
    the interior point's tolerance of the energy's corner. Those knots keep their power at zero when the weights
    change; taking the sign of a 1e-9 W power for their side made the derivatives wrong by factors (by 10⁶ along
    the energy's weight, which moves nothing here)."""
    arm = ArmModel.from_anthropometrics(1.76, 69.9, "M")
    task = ReachingTask(arm, np.deg2rad([-60.0, 90.0]), 0.6, 0.8, n_nodes=40)
    w = np.array([[6.7, 1100.0, 19.0, 0.034, 0.00093, 1.1, 0.00091]])
    sol = solve_doc(task, w)
    assert sol.converged
    _, qd, tau = rest_to_rest_knots(task, sol.q)
    assert np.all(np.abs(np.sum(qd[1:-1] * tau[1:], axis=1)) < 1e-6)  # the power sits at zero on every knot
    jac = weight_jacobian(task, w, sol)
    fds = [_resolved(task, w, 0, j) for j in range(7)]
    largest = max(np.linalg.norm(fd) for fd in fds)
    for j, fd in enumerate(fds):
        assert np.linalg.norm(jac[:, :, 0, j] - fd) <= 1e-2 * np.linalg.norm(fd) + 1e-3 * largest, FEATURES[j]


def test_a_learned_cost_s_knots_near_the_energy_s_corner_move_as_re_solved():
    """The 8-window cost learned on the built-in data's P4 (seed 0, rounded): fatrop leaves some knots' power
    within 1e-5 to 1e-4 of |q̇||τ| of zero, on the corner, where a smooth knot's derivative was 20-90 % off."""
    arm = ArmModel(0.2668, 0.4387, 1.993, 1.910, 0.1206, 0.1585, 0.01453, 0.02397)
    w = np.array(
        [
            [0.1104, 0.001875, 1.0, 0.0001079, 1.184e-06, 0.08235, 0.001063],
            [0.01768, 0.001353, 0.2034, 5.147e-05, 1.233e-06, 0.03472, 0.0001261],
            [0.02849, 0.001646, 0.1687, 3.151e-05, 9.121e-07, 0.007823, 9.828e-05],
            [0.01208, 0.001416, 0.08231, 5.261e-05, 8.915e-07, 0.004907, 0.0001162],
            [0.004089, 0.0009836, 0.0879, 7.407e-05, 6.917e-07, 0.005685, 0.0003765],
            [0.01152, 0.001209, 0.2386, 2.982e-05, 7.806e-07, 0.01052, 0.0004488],
            [0.02649, 0.0009825, 0.297, 4.259e-05, 4.263e-07, 0.03385, 0.0003399],
            [0.1368, 0.001261, 0.8505, 4.254e-05, 3.758e-07, 0.04386, 0.0002882],
        ]
    )
    task = ReachingTask(arm, np.deg2rad([-31.0, 89.6]), 0.67, 0.87, n_nodes=50)
    sol = solve_doc(task, w)
    assert sol.converged
    jac = weight_jacobian(task, w, sol)
    h = 0.01
    for v in np.random.default_rng(0).normal(size=(4, *w.shape)):
        v /= np.linalg.norm(v)
        fd = (solve_doc(task, w * np.exp(h * v)).q - solve_doc(task, w * np.exp(-h * v)).q) / (2 * h)
        assert np.linalg.norm(np.einsum("kisj,sj->ki", jac, v) - fd) <= 0.1 * np.linalg.norm(fd)


def test_scaling_every_weight_moves_no_reach(problem):
    """The DOC is scale-free (ω and cω have one optimum), so the derivatives along every log-weight sum to zero:
    a property of the problem the implicit-function computation does not build in."""
    task, w, sol = problem
    jac = weight_jacobian(task, w, sol)
    total = jac.reshape(N_NODES + 1, 2, -1).sum(axis=-1)
    assert np.abs(total).max() < 1e-3 * np.abs(jac).max()  # the solution is optimal to ~1e-6, not exactly


def test_a_crocoddyl_solution_has_the_derivative_of_the_same_problem(problem):
    task, w, sol = problem
    croc = solve_doc(task, w, backend="crocoddyl")
    assert croc.converged
    a, b = weight_jacobian(task, w, sol), weight_jacobian(task, w, croc)
    assert np.linalg.norm(a - b) < 0.05 * np.linalg.norm(a)


def test_the_weight_jacobian_refuses_an_unconverged_or_foreign_solution(problem):
    task, w, sol = problem
    with pytest.raises(ValueError, match="needs a converged solution"):
        weight_jacobian(task, w, replace(sol, converged=False))
    with pytest.raises(ValueError, match="the solution has 41 knots, the task 31"):
        weight_jacobian(replace(task, n_nodes=30), w, sol)


@pytest.mark.parametrize("threshold", [0.05, None])
def test_the_observed_state_jacobian_matches_finite_differences_of_observe(problem, threshold):
    task, w, _ = problem
    task = rest_to_rest(task)
    sol = solve_doc(task, w)
    dq = weight_jacobian(task, w, sol).reshape(N_NODES + 1, 2, -1)[:, :, [3, 9, 16]]
    jac = observed_state_jacobian(sol, task, threshold, dq)
    assert jac.shape == (N_NODES + 1, 4, 3)

    def seen(q):  # what MO-IRL's merit compares: the observed reach, or the DOC's own knots without a threshold
        if threshold is None:
            return np.hstack([q, np.vstack([np.zeros(2), np.diff(q, axis=0) / task.dt])])
        return observe(replace(sol, q=q), task, threshold).knot_state(N_NODES)

    for c in range(3):
        e = 1e-5
        fd = (seen(sol.q + e * dq[:, :, c]) - seen(sol.q - e * dq[:, :, c])) / (2 * e)
        assert np.linalg.norm(jac[:, :, c] - fd) <= 1e-4 * np.linalg.norm(fd), c


def test_the_observed_state_jacobian_refuses_a_wrong_shape(problem):
    task, _, sol = problem
    with pytest.raises(ValueError, match=r"dq must have shape \(41, 2, P\)"):
        observed_state_jacobian(sol, task, 0.05, np.zeros((40, 2, 3)))


def test_the_gauss_newton_step_is_the_damped_least_squares_minimiser():
    rng = np.random.default_rng(0)
    r = rng.normal(size=(3, 30))
    jac = rng.normal(size=(3, 30, 5))
    eta = gauss_newton_step(r, jac, bound=1e3, ridge=1e-3)
    # the closed form, written out: (1/D) Σ JᵀJ + ρI against −(1/D) Σ Jᵀr
    a = sum(jac[d].T @ jac[d] for d in range(3)) / 3
    rho = 1e-3 * np.trace(a) / 5
    expected = np.linalg.solve(a + rho * np.eye(5), -sum(jac[d].T @ r[d] for d in range(3)) / 3)
    np.testing.assert_allclose(eta, expected, rtol=1e-8, atol=1e-10)


def test_the_gauss_newton_step_stays_in_its_box_and_beats_clipping():
    rng = np.random.default_rng(1)
    r = 10 * rng.normal(size=(2, 40))
    jac = rng.normal(size=(2, 40, 6))
    bound = 0.1
    eta = gauss_newton_step(r, jac, bound=bound, ridge=0.0)
    assert np.all(np.abs(eta) <= bound)

    def model(e):
        return np.mean([np.sum((r[d] + jac[d] @ e) ** 2) for d in range(2)])

    free = np.linalg.lstsq(jac.reshape(-1, 6), -r.reshape(-1), rcond=None)[0]
    assert model(eta) <= model(np.clip(free, -bound, bound)) + 1e-12
    assert model(eta) < model(np.zeros(6))


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((np.zeros((2, 5)), np.zeros((2, 4, 3)), 1.0), r"do not match"),
        ((np.zeros((2, 5)), np.zeros((2, 5, 3)), 0.0), "bound must be a number > 0"),
        ((np.full((2, 5), np.nan), np.zeros((2, 5, 3)), 1.0), "finite residuals"),
    ],
)
def test_the_gauss_newton_step_refuses_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        gauss_newton_step(*args)


@pytest.fixture(scope="module")
def dominated_demos():
    return knot_trials(4, "P2", seed=1, n_nodes=N_NODES)


@pytest.mark.parametrize("rollout", ["mean", "per_demo"])
def test_gauss_newton_merit_steps_lower_the_merit_without_probing(dominated_demos, rollout):
    """One window on time-varying reaches: the likelihood has nothing to say, so the progress comes from the
    Gauss-Newton merit steps, each a line-search try or a few, never the 14 probes per rollout of the
    per-feature model."""
    est = MOIRL(1, n_nodes=N_NODES, rollout=rollout, max_iter=4, experimental={"merit_model": "gauss-newton"})
    est.fit(dominated_demos)
    steps = [h for h in est.history_[1:] if h["step"] == "merit" and h["accepted"]]
    assert steps and est.merit_ < 0.9 * est.initial_merit_
    per_try = 1 if rollout == "mean" else len(dominated_demos)
    for h in steps:
        prev = est.history_[h["iteration"] - 1]
        assert h["merit"] < prev["merit"] * (1 - est.fallback_tol)
        assert h["doc_solves"] - prev["doc_solves"] < 14 * per_try


def test_merit_model_is_validated(dominated_demos):
    with pytest.raises(ValueError, match="merit_model must be 'gauss-newton' or 'probes'"):
        MOIRL(1, n_nodes=N_NODES, experimental={"merit_model": "newton"}).fit(dominated_demos)
