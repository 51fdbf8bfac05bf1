"""The interior point on the knots (``reachirl.doc.interior``): the slacks' elimination against a numerical
minimum, its answers from far starts against fatrop's on reaches recorded as real ones are (cut at a speed
threshold), exact Newton vouching for them, a bound the optimum presses against, and the cases where it must give
way to fatrop."""

import dataclasses

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from reachirl import solve_doc
from reachirl.data.trial import load_trials
from reachirl.doc import interior, newton
from reachirl.doc.observation import observed_task
from reachirl.virtual import nominal_weights


@pytest.fixture(scope="module")
def recorded_p4(recorded):
    return [t for t in load_trials(recorded / "trials.npz") if t.posture == "P4"]


@pytest.mark.parametrize("e", [-3.0, -1e-4, 0.0, 2e-6, 0.7])
def test_the_energy_barrier_is_the_slacks_minimum(e):
    """``c|e|`` as the NLP writes it, ``c(s⁺ + s⁻)`` with ``s⁺ − s⁻ = e``, under the barrier ``−μ ln s±``: the
    closed-form slacks are the numerical minimiser's, the closed-form value is that minimum (up to the constant
    ``μ ln(2c²/μ) + μ``), and its derivative is the finite difference's."""
    c, mu = 0.8, 1e-3

    def barrier(sm):
        sp = e + sm
        return c * (sp + sm) - mu * np.log(sp) - mu * np.log(sm)

    lowest = max(0.0, -e)
    best = minimize_scalar(barrier, bounds=(lowest + 1e-15, lowest + 10.0), method="bounded", options={"xatol": 1e-14})
    sp, sm = interior._split(np.array([e]), np.array([c]), mu)
    assert sm[0] == pytest.approx(best.x, rel=1e-6, abs=1e-12)
    assert sp[0] - sm[0] == pytest.approx(e, abs=1e-15)
    phi, dphi = interior._energy_barrier(np.array([e]), np.array([c]), mu)
    assert phi[0] + mu * np.log(2 * c**2 / mu) + mu == pytest.approx(best.fun, rel=1e-9, abs=1e-12)
    h = 1e-7
    fd = (
        interior._energy_barrier(np.array([e + h]), np.array([c]), mu)[0]
        - interior._energy_barrier(np.array([e - h]), np.array([c]), mu)[0]
    ) / (2 * h)
    assert dphi[0] == pytest.approx(fd[0], rel=1e-6, abs=1e-9)
    # as μ → 0 the barrier is the energy itself
    assert interior._energy_barrier(np.array([e]), np.array([c]), 1e-14)[0][0] == pytest.approx(c * abs(e), abs=1e-12)


def _central_system(task, w, q, mu, fscale=None):
    """The reach, the iterate at ``q`` with its slacks at their optimum and its duals central, and its system."""
    reach = interior._Reach(task, w, q, fscale)
    out, phi, tip = reach.evaluate(q, np.zeros(reach.act.size), mu)
    sp, sm = interior._split(out[72, reach.act], reach.c, mu)
    x = interior._Iterate(q, out, phi, tip, sp, sm, reach.slacks(q))
    x.center(reach, mu)
    ab, rhs, error, *_ = reach.kkt(x, mu)
    return reach, x, ab.copy(), rhs, error


@pytest.mark.parametrize("tight", [False, True])
def test_the_step_system_is_the_barrier_functions_newton_system(recorded_p4, tight):
    """With the split's slacks at their optimum and the duals central (``z = μ/s``, ``y = c − z⁺``, ``λ = 0``), the
    condensed primal-dual system is Newton's on the primal barrier function: its right-hand side is minus the
    barrier function's gradient in the knots and its knots' block that function's Hessian, both against central
    finite differences of the barrier function the line search evaluates; the bar's column and row are its
    constraint's gradient, the bar's right-hand side its distance, the residual the gradient's largest entry, and
    the barrier function is infinite outside the bounds. At a small ``μ`` (the energy's curvature weighs) and with
    bounds close to the path and a large ``μ`` (theirs does)."""
    trial = recorded_p4[1]
    task = observed_task(trial, 30, trial.onset_threshold)
    w = nominal_weights()
    q = solve_doc(task, w * np.array([2.0, 0.5, 1.0, 1.0, 3.0, 1.0, 0.7])).q[1:-1] + 0.002  # off the optimum
    mu = 1e-3
    if tight:
        speeds = np.abs(np.diff(np.vstack([task.q0, q]), axis=0)) / task.dt
        task = dataclasses.replace(
            task, q_lower=q.min(axis=0) - 0.01, q_upper=q.max(axis=0) + 0.01, qd_max=1.1 * speeds.max(axis=0)
        )
        mu = 1.0
    reach, x, ab, rhs, error = _central_system(task, w, q, mu)
    m = reach.lay.m

    def phi(qq):
        return reach.evaluate(qq, x.y, mu)[1]

    def gradient(qq):  # at the same objective scale
        return -_central_system(task, w, qq, mu, reach.fscale)[3][:m]

    h = 1e-6
    steps = np.eye(m).reshape(m, -1, 2)
    fd = np.array([(phi(q + h * e) - phi(q - h * e)) / (2 * h) for e in steps])
    g = -rhs[:m]
    assert np.max(np.abs(g - fd)) < 2e-5 * max(1.0, np.max(np.abs(g)))
    assert error == pytest.approx(np.max(np.abs(g)), rel=1e-12)
    assert rhs[m] == pytest.approx(-(task.arm.fk(q[-1])[0] - task.target_x), abs=1e-12)
    bar = np.array([(task.arm.fk(q[-1] + h * e)[0] - task.arm.fk(q[-1] - h * e)[0]) / (2 * h) for e in np.eye(2)])
    bw = interior._BW
    column, row = ab[2 * bw + np.arange(m - 2, m) - m, m], ab[2 * bw + m - np.arange(m - 2, m), np.arange(m - 2, m)]
    assert np.allclose(column, bar, rtol=1e-7, atol=1e-9) and np.allclose(row, bar, rtol=1e-7, atol=1e-9)
    fd_h = np.array([(gradient(q + h * e) - gradient(q - h * e)) / (2 * h) for e in steps]).T
    dense = np.zeros((m, m))
    for j in range(m):
        for i in range(max(0, j - bw), min(m, j + bw + 1)):
            dense[i, j] = ab[2 * bw + i - j, j]
    assert np.max(np.abs(dense - fd_h)) < 1e-4 * np.max(np.abs(dense))
    assert np.max(np.abs(fd_h[np.abs(np.subtract.outer(range(m), range(m))) > bw])) < 1e-6 * np.max(np.abs(dense))
    outside = q.copy()
    outside[5, 0] = task.q_lower[0] - 1e-3
    assert reach.evaluate(outside, x.y, mu)[1] == np.inf


def test_far_weights_are_solved_as_fatrop_solves_them(recorded_p4):
    """The uncertainty's checked samples re-solve the fit's reach under weights far from the fit's (factors of
    ten and more): the interior point from the fit's solution answers, its optimum is exact Newton's (started there,
    Newton vouches for a point less than 0.005° away, at the same cost to 1e-6), and it costs no more
    than fatrop's from the same start (fatrop stops at its tolerance; both find the same reach, within 0.05°)."""
    w = nominal_weights()
    rng = np.random.default_rng(11)
    answered = vouched = 0
    for trial in recorded_p4[:4]:
        task = observed_task(trial, 60, trial.onset_threshold)
        before = solve_doc(task, w)
        far = w * np.exp(1.5 * rng.standard_normal(w.shape))
        far = far / far.max()
        found = interior.interior_solve(task, far, before.q)
        if found is None:
            continue
        answered += 1
        exact = newton.newton_solve(task, far, found.q, found.fscale)
        if exact is not None:  # no bound active: Newton vouches for the point (its corners exact, e = 0)
            vouched += 1
            assert np.degrees(np.max(np.abs(exact.q - found.q))) < 0.005
            assert found.cost == pytest.approx(exact.cost, rel=1e-6)
        slow = solve_doc(task, far, warm_start=before)
        assert slow.converged and slow.status.startswith(("fatrop", "ipopt"))
        assert found.cost <= slow.cost * (1 + 1e-7)
        assert np.degrees(np.max(np.abs(found.q - slow.q))) < 0.05
    assert answered >= 3 and vouched >= 2, (answered, vouched)


def test_solve_doc_takes_the_interior_point_where_newton_cannot_settle(recorded_p4):
    """A warm solve under far weights (``newton=True, interior=True``, the uncertainty's path): Newton gives way, the
    interior point answers (status ``interior``), and the reach is fatrop's to 0.05° at a cost no higher; without
    ``interior`` (MO-IRL's line search), fatrop answers."""
    trial = recorded_p4[0]
    task = observed_task(trial, 60, trial.onset_threshold)
    w = nominal_weights()
    before = solve_doc(task, w)
    far = w * np.exp(2.0 * np.random.default_rng(0).standard_normal(w.shape))  # factors of ten and more
    fast = solve_doc(task, far, warm_start=before, newton=True, interior=True)
    slow = solve_doc(task, far, warm_start=before)
    assert solve_doc(task, far, warm_start=before, newton=True).status.startswith("fatrop")  # without it: fatrop
    assert fast.status == "interior: Success" and fast.converged and fast.iterations > 0
    assert slow.status.startswith("fatrop") and slow.converged
    assert fast.cost <= slow.cost * (1 + 1e-7)
    assert np.degrees(np.max(np.abs(fast.q - slow.q))) < 0.05


def test_a_speed_bound_the_optimum_presses_against(recorded_p4):
    """Newton refuses a reach whose optimum sits on the speed bound; the interior point answers it, with the
    bound met and fatrop's reach to 0.01°."""
    trial = recorded_p4[1]
    task = observed_task(trial, 60, trial.onset_threshold)
    w = nominal_weights()
    free = solve_doc(task, w)
    qd_max = np.array(task.qd_max, dtype=float)
    qd_max[0] = 0.9 * np.max(np.abs(free.qd[:, 0]))
    bounded = dataclasses.replace(task, qd_max=qd_max)
    start = free.q.copy()
    start[:, 0] = task.q0[0] + 0.85 * (free.q[:, 0] - task.q0[0])  # slower: strictly inside the new bound
    assert newton.newton_solve(bounded, w / w.max(), start) is None
    found = interior.interior_solve(bounded, w / w.max(), start)
    assert found is not None
    speed = np.abs(np.diff(found.q[:, 0])) / task.dt
    assert np.all(speed < qd_max[0]) and speed.max() > 0.999 * qd_max[0]
    slow = solve_doc(bounded, w, guess=start)
    assert slow.converged
    assert np.degrees(np.max(np.abs(found.q - slow.q))) < 0.01


def test_it_gives_way_when_it_cannot_vouch_for_its_answer(recorded_p4, monkeypatch):
    """A start outside the bounds or on one, or too few steps allowed: None; where it gives way, ``solve_doc``
    answers by fatrop from the same start."""
    trial = recorded_p4[2]
    task = observed_task(trial, 60, trial.onset_threshold)
    w = nominal_weights()
    before = solve_doc(task, w)
    far = w * np.exp(2.0 * np.random.default_rng(0).standard_normal(w.shape))
    outside = before.q.copy()
    outside[10, 1] = task.q_upper[1] + 0.01
    assert interior.interior_solve(task, far, outside) is None
    assert interior.interior_solve(task, far, before.q, max_iter=1) is None
    at_limit = before.q.copy()
    at_limit[10, 0] = task.q_lower[0]  # on the bound: not strictly inside
    assert interior.interior_solve(task, far, at_limit) is None
    import reachirl.doc.casadi as backend

    monkeypatch.setattr(backend, "interior_solve", lambda *a, **k: None)
    sol = solve_doc(task, far, warm_start=before, newton=True, interior=True)
    assert sol.converged and sol.status.startswith("fatrop")


def test_the_line_search_keeps_fatrop_and_the_checked_samples_take_the_interior_point(recorded_p4, monkeypatch):
    """MO-IRL's fits solve without the interior point; the uncertainty's re-solves under far weights
    (``rollout_errors``) take it."""
    from reachirl.irl import moirl, uncertainty

    asked = []
    real = moirl.solve_doc

    def recording(*args, **kwargs):
        asked.append(kwargs.get("interior", False))
        return real(*args, **kwargs)

    monkeypatch.setattr(moirl, "solve_doc", recording)
    est = moirl.MOIRL(n_windows=2, random_state=0).fit(recorded_p4[:2])
    assert asked and not any(asked)
    asked.clear()
    far = est.weights_ * np.exp(2.0 * np.random.default_rng(1).standard_normal(est.weights_.shape))
    errors, _, _ = uncertainty.rollout_errors(est, far)
    assert errors is not None and asked and all(asked)
