"""Exact Newton on the knots (``reachirl.doc.newton``), the predictions' solver: its derivatives against finite
differences of the cost computed independently (``reachirl.features``), its answers against fatrop's on reaches
recorded as real ones are, and the cases where it must give way."""

import dataclasses

import numpy as np
import pytest

from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.data.trial import load_trials
from reachirl.doc import compiled, newton
from reachirl.doc.observation import observed_solution, observed_task
from reachirl.doc.task import moved_path, rest_to_rest_knots
from reachirl.features import euler_knots, trajectory_cost
from reachirl.virtual import nominal_weights, posture_q

N = 40
ARM = ArmModel.from_anthropometrics(1.76, 70.0, "M")


def _task(dq_deg=(0.0, 0.0), reach=0.95, duration=0.8, **kw) -> ReachingTask:
    return ReachingTask(ARM, posture_q("P2") + np.deg2rad(dq_deg), reach * ARM.length, duration, n_nodes=N, **kw)


def _powers(task, q):
    """Each stage's joint power ``q̇_kᵀτ_k`` on the knots ``q (N+1, 2)`` (stage 0's is zero: at rest)."""
    _, qd, tau = euler_knots(task.arm, q, task.dt)
    return np.r_[0.0, np.sum(qd[1:-1] * tau[1:], axis=1)]


def _knot_gradient(task, weights, q, fscale):
    """The stages' gradient in the inner knots, with each knot's power on its own side (no kink)."""
    n = task.n_nodes
    lay = newton._scatter(n)
    arm, dt = newton._params(task)
    w_knot = weights[newton.window_index(n, weights.shape[0])]
    x = newton._stage_knots(task.q0, q[1:n])
    sigma = np.sign(_powers(task, q))
    ws = np.vstack([w_knot.T, sigma])
    out = np.asarray(newton._stage_map(n)(x, ws, np.zeros((1, n)), arm, dt, fscale))
    return lay.grad_op @ out[:8].ravel(order="F"), lay


def _cost(task, weights, inner, fscale):
    q = np.vstack([task.q0, inner, inner[-1:]])
    q, qd, tau = rest_to_rest_knots(task, q)
    return fscale * trajectory_cost(task.arm, q, qd, tau, task.dt, weights)


def test_the_knot_gradient_is_the_derivative_of_the_trajectory_cost():
    """Central differences of ``features.trajectory_cost`` (its own implementation of the seven features and of
    the Euler knots) against the compiled stage derivatives, on a reach with energy of both signs."""
    task = _task((3.0, -2.0))
    w = nominal_weights()
    q = solve_doc(task, w).q + 0.01 * np.sin(np.linspace(0, 3 * np.pi, N + 1))[:, None]
    q[-1] = q[-2]
    fscale = 1.0 / trajectory_cost(task.arm, *euler_knots(task.arm, q, task.dt), task.dt, w)
    grad, lay = _knot_gradient(task, w, q, fscale)
    inner = q[1:N].copy()
    h = 1e-6
    fd = np.zeros_like(inner)
    for k in range(inner.shape[0]):
        for j in range(2):
            up, down = inner.copy(), inner.copy()
            up[k, j] += h
            down[k, j] -= h
            fd[k, j] = (_cost(task, w, up, fscale) - _cost(task, w, down, fscale)) / (2 * h)
    ours = grad[lay.q_rows].reshape(N - 1, 2)
    assert np.max(np.abs(ours - fd)) < 1e-5 * np.max(np.abs(fd))
    # the stages' costs (the objective's scale of a solve from q) add up to the trajectory's
    found = newton.newton_solve(task, w, q, max_iter=0)
    assert found is None  # no step allowed: it cannot vouch for q
    arm, dt = newton._params(task)
    sigma = np.zeros((1, N))
    ws = np.vstack([w[newton.window_index(N, 8)].T, sigma])
    out = np.asarray(newton._stage_map(N)(newton._stage_knots(task.q0, q[1:N]), ws, sigma, arm, dt, 1.0))
    assert np.isclose(out[-1].sum(), 1.0 / fscale, rtol=1e-12)


def test_the_compiled_stage_function_equals_the_virtual_machine():
    f = newton._stage()
    with compiled.setting("on"):
        fc = compiled.compiled_function(f)
    assert fc is not None
    rng = np.random.default_rng(0)
    args = [rng.normal(size=8), rng.uniform(size=8), 0.3, rng.uniform(0.1, 1, size=9), 0.01, 2.0]
    assert np.allclose(np.asarray(fc(*args)), np.asarray(f(*args)), rtol=1e-12, atol=1e-12)
    with compiled.setting("off"):
        assert compiled.compiled_function(f) is None


@pytest.fixture(scope="module")
def recorded_p4(recorded):
    return [t for t in load_trials(recorded / "trials.npz") if t.posture == "P4"]


def test_predictions_by_newton_are_fatrops_on_recorded_trials(recorded_p4):
    """Each recorded reach (cut at a speed threshold) predicted from another's solution moved to it, as
    ``reproduce`` predicts from the fit's rollout: the same answer as fatrop from the same start, within 0.01°."""
    w = nominal_weights()
    trials = recorded_p4
    first = trials[0]
    n = 60
    path = solve_doc(observed_task(first, n, first.onset_threshold), w).q
    answered = 0
    for trial in trials[1:]:
        task = observed_task(trial, n, trial.onset_threshold)
        guess = moved_path(task, path)
        fast = solve_doc(task, w, guess=guess, newton=True)
        slow = solve_doc(task, w, guess=guess)
        assert fast.converged and slow.converged
        answered += fast.status.startswith("newton")
        seen_fast = observed_solution(fast, task, trial.onset_threshold)
        seen_slow = observed_solution(slow, task, trial.onset_threshold)
        assert np.degrees(np.max(np.abs(seen_fast.q - seen_slow.q))) < 0.01
        assert abs(fast.cost - slow.cost) <= 1e-5 * slow.cost
    assert answered >= len(trials) - 2


def test_a_warm_newton_solve_is_fatrops_warm_solve_under_new_weights(recorded_p4):
    """MO-IRL's line search re-solves the same reach under moved weights from the last solution: Newton from that
    solution (``warm_newton``) finds fatrop's optimum (within 0.01°, cost within 1e-5) on recorded reaches."""
    w = nominal_weights()
    rng = np.random.default_rng(3)
    answered = 0
    for trial in recorded_p4[:4]:
        task = observed_task(trial, 60, trial.onset_threshold)
        before = solve_doc(task, w)
        moved = w * np.exp(0.1 * rng.standard_normal(w.shape))  # a line-search try: log-weights moved by ~0.1
        fast = solve_doc(task, moved, warm_start=before, newton=True)
        slow = solve_doc(task, moved, warm_start=before)
        assert fast.converged and slow.converged and slow.status.startswith("fatrop")
        answered += fast.status.startswith("newton")
        assert np.degrees(np.max(np.abs(fast.q - slow.q))) < 0.01
        assert abs(fast.cost - slow.cost) <= 1e-5 * slow.cost
    assert answered >= 3


def test_a_newton_answers_cost_is_the_trajectory_cost_of_its_reach(recorded_p4):
    """Newton's answer reports the objective its last step evaluated (not recomputed): the DOC's cost of the
    returned knots, computed independently by ``reachirl.features``, to rounding; the windows' weights included."""
    rng = np.random.default_rng(5)
    w = nominal_weights()
    w = w * np.exp(0.2 * rng.standard_normal(w.shape))  # every window its own weights
    trials = recorded_p4
    path = solve_doc(observed_task(trials[0], 60, trials[0].onset_threshold), w).q
    answered = 0
    for trial in trials[1:6]:
        task = observed_task(trial, 60, trial.onset_threshold)
        sol = solve_doc(task, w * 1e3, guess=moved_path(task, path), newton=True)  # any scale: ω and cω alike
        if not sol.status.startswith("newton"):
            continue
        answered += 1
        expected = trajectory_cost(task.arm, sol.q, sol.qd, sol.tau, task.dt, w * 1e3)
        assert sol.cost == pytest.approx(expected, rel=1e-9)
    assert answered >= 3


def test_newton_gives_way_when_it_cannot_vouch_for_its_answer():
    w = nominal_weights()
    task = _task((3.0, -2.0))
    start = moved_path(task, solve_doc(_task(), w).q)
    fscale = 1.0 / trajectory_cost(task.arm, *euler_knots(task.arm, start, task.dt), task.dt, w)
    # a start it cannot finish from in the steps allowed
    assert newton.newton_solve(task, w, start, fscale, max_iter=1) is None
    found = newton.newton_solve(task, w, start, fscale)
    assert found is not None
    # a speed bound the optimum presses against: Newton ignores bounds, so it must refuse and fatrop answers
    qd_max = np.array(task.qd_max, dtype=float)
    qd_max[0] = 0.9 * np.max(np.abs(np.diff(found.q[:, 0]))) / task.dt
    bounded = dataclasses.replace(task, qd_max=qd_max)
    assert newton.newton_solve(bounded, w, start, fscale) is None
    sol = solve_doc(bounded, w, guess=start, newton=True)
    assert sol.converged and sol.status.startswith("fatrop")
    assert np.max(np.abs(sol.qd[:, 0])) <= qd_max[0] * (1 + 1e-6)


def test_a_saddle_is_refused():
    """The reduced-Hessian test at a converged answer: it holds there (the bar's curvature included), and fails
    for the same point with the stages' Hessians negated."""
    w = nominal_weights()
    task = _task((3.0, -2.0))
    start = moved_path(task, solve_doc(_task(), w).q)
    found = newton.newton_solve(task, w, start)
    assert found is not None
    arm, dt = newton._params(task)
    x = newton._stage_knots(task.q0, found.q[1:N])
    e = _powers(task, found.q)
    ws = np.vstack([w[newton.window_index(N, 8)].T, np.sign(e)])
    out = np.asarray(newton._stage_map(N)(x, ws, np.zeros((1, N)), arm, dt, found.fscale)).ravel(order="F")
    jtip = np.asarray(ARM.jacobian(found.q[-1])[0])
    curv = found.bar_multiplier * newton._fingertip_hessian(task, found.q[-1])
    kink = np.zeros(N, dtype=bool)
    assert found.n_kinks == 0
    assert newton._is_minimum(out, N, kink, jtip, curv)
    flipped = out.copy().reshape(newton._ROWS, N, order="F")
    flipped[8:72] *= -1
    assert not newton._is_minimum(flipped.ravel(order="F"), N, kink, jtip, curv)


def _stage_outputs(task, w, found, kink, e):
    """The stage function's output at Newton's answer (each knot's power ``e`` on its side, zero at the kinks)."""
    arm, dt = newton._params(task)
    ws = np.vstack([w[newton.window_index(N, w.shape[0])].T, np.where(kink, 0.0, np.sign(e))])
    x = newton._stage_knots(task.q0, found.q[1:N])
    return np.asarray(newton._stage_map(N)(x, ws, np.zeros((1, N)), arm, dt, found.fscale))


def _dense(out, kinks):
    """The knots' Hessian ``(m, m)`` and the kinks' constraint gradients ``(len(kinks), m)``, assembled densely
    from each stage's local derivatives (stage k's knots q_{k−2} … q_{k+1}; the start fixed, q_N = q_{N−1})."""
    m = 2 * (N - 1)
    hess, grads = np.zeros((m, m)), np.zeros((len(kinks), m))
    for k in range(N):
        idx = [2 * (min(knot, N - 1) - 1) + c for knot in (k - 2, k - 1, k, k + 1) for c in (0, 1)]
        keep = [i for i, j in enumerate(idx) if j >= 0]
        sub = np.array(idx)[keep]
        h = out[8:72, k].reshape(8, 8, order="F")
        np.add.at(hess, (sub[:, None], sub[None, :]), h[np.ix_(keep, keep)])
        for row, kk in enumerate(kinks):
            if kk == k:
                np.add.at(grads[row], sub, out[73:81, k][keep])
    return hess, grads


def test_the_kinks_restrict_the_second_order_test_to_their_null_space():
    """At an answer with kinks (a large energy weight), a stage Hessian made indefinite along one kink's gradient
    is still a minimum, since the kink's constraint forbids that direction: ``_is_minimum`` agrees with the
    dense null-space eigenvalues, with and without the kinks, so each kink's gradient lands on its own knots."""
    from scipy.linalg import null_space

    w = nominal_weights().copy()
    w[:, 1] *= 100
    task = _task((3.0, -2.0))
    found = newton.newton_solve(task, w, moved_path(task, solve_doc(_task(), w).q))
    assert found is not None and found.n_kinks > 0
    e = _powers(task, found.q)
    kink = np.abs(e) < 1e-7
    kink[0] = False
    assert kink.sum() == found.n_kinks
    out = _stage_outputs(task, w, found, kink, e)
    k = int(np.flatnonzero(kink)[len(np.flatnonzero(kink)) // 2])
    v = out[73:81, k]
    hess, _ = _dense(out, [])
    out[8:72, k] -= (20 * np.max(np.abs(hess)) / (v @ v) * np.outer(v, v)).ravel(order="F")
    hess, grads = _dense(out, list(np.flatnonzero(kink)))
    jtip = np.asarray(ARM.jacobian(found.q[-1])[0])
    curv = found.bar_multiplier * newton._fingertip_hessian(task, found.q[-1])
    hess[-2:, -2:] += curv
    bar = np.zeros((1, hess.shape[0]))
    bar[0, -2:] = jtip
    z = null_space(np.vstack([grads, bar]))
    assert np.min(np.linalg.eigvalsh(hess)) < 0  # indefinite ...
    assert np.min(np.linalg.eigvalsh(z.T @ hess @ z)) > 0  # ... but not where the constraints allow a move
    flat = out.ravel(order="F")
    assert newton._is_minimum(flat, N, kink, jtip, curv)
    z_bar = null_space(bar)
    assert np.min(np.linalg.eigvalsh(z_bar.T @ hess @ z_bar)) < 0
    assert not newton._is_minimum(flat, N, np.zeros(N, dtype=bool), jtip, curv)


def _step_state(task, w, q, kinks, seed=0):
    """The step function's inputs at the knots ``q``: each knot's power on its own side, kinks at ``kinks``
    with multipliers a tenth of their energy weight (so that no kink is released), the bar's multiplier 0.3."""
    n = task.n_nodes
    fscale = 1.0 / trajectory_cost(task.arm, *euler_knots(task.arm, q, task.dt), task.dt, w)
    w_knot = w[newton.window_index(n, w.shape[0])]
    kink = np.zeros(n)
    kink[kinks] = 1.0
    rng = np.random.default_rng(seed)
    lam = kink * 0.1 * fscale * task.dt * w_knot[:, 1] * rng.choice([-1.0, 1.0], size=n)
    sigma = np.sign(_powers(task, q))
    arm, dt = newton._params(task)
    return [newton._path(task.q0, q[1:n]), w_knot.reshape(-1), sigma, kink, lam, 0.3, 0.0, 0.0, arm, dt, fscale,
            task.target_x]  # fmt: skip


def test_the_step_is_newtons_on_the_residual_it_returns():
    """The banded KKT matrix the step function assembles (in LAPACK's storage) against central differences of
    the residual it returns, in every knot, every kink's multiplier and the bar's: the step solves the
    linearised KKT conditions. Off the kinks, a multiplier's row is its own unit row (``λ_k = 0``). Compiled and
    virtual machine agree to the last bit."""
    task = _task((3.0, -2.0))
    w = nominal_weights()
    q = solve_doc(task, w).q + 0.01 * np.sin(np.linspace(0, 3 * np.pi, N + 1))[:, None]
    q[-1] = q[-2]
    e = _powers(task, q)
    kinks = [k for k in np.argsort(-np.abs(e))[:12] if k > 0][:3]  # kinks where the power is far from zero
    args = _step_state(task, w, q, kinks)
    f = newton._step_function(N)
    with compiled.setting("on"):
        fc = compiled.compiled_function(f)
    assert fc is not None
    lay = newton._scatter(N)
    size = lay.size

    def residual(a):
        out = fc(*a)
        assert float(out[5]) == 0.0  # the active set does not change: no side flips, no kink released
        return np.asarray(out[1]).ravel()

    lu = np.asarray(fc(*args)[0]).reshape(3 * newton._BW + 1, size, order="F")
    kkt = np.zeros((size, size))
    for j in range(size):
        for i in range(max(0, j - newton._BW), min(size, j + newton._BW + 1)):
            kkt[i, j] = lu[2 * newton._BW + i - j, j]
    vm = [np.asarray(x) for x in f(*args)]
    for x, y in zip(vm, [np.asarray(x) for x in fc(*args)], strict=True):
        assert np.array_equal(x, y)  # to the last bit: the compiler's flags contract no multiply-adds

    def moved(j, h):  # the inputs with unknown j moved by h
        a = [np.array(x, dtype=float, copy=True) if np.ndim(x) else float(x) for x in args]
        if j == size - 1:
            a[5] += h
        elif j % 3 == 2:
            a[4][j // 3 + 1] += h  # λ_k, k = j // 3 + 1
        else:
            knot = j // 3 + 1
            a[0][2 * (knot + 2) + j % 3] += h
            if knot == N - 1:
                a[0][2 * (N + 2) + j % 3] += h  # q_N = q_{N−1}
        return a

    kink_cols = [3 * (k - 1) + 2 for k in kinks]
    cols = list(lay.q_rows) + kink_cols + [size - 1]
    h = 1e-6
    fd = np.column_stack([(residual(moved(j, h)) - residual(moved(j, -h))) / (2 * h) for j in cols])
    noise = 100 * np.finfo(float).eps * np.max(np.abs(residual(args))) / h  # round-off of the differences
    np.testing.assert_allclose(fd, kkt[:, cols], rtol=1e-6, atol=noise)
    free = [r for r in lay.lam_rows if r not in kink_cols]
    assert np.array_equal(kkt[free], np.eye(size)[free])
