"""The Crocoddyl/CSQP backend: pinned versions, derivatives against finite differences, agreement with CasADi."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from reachirl import ReachingTask, solve_doc
from reachirl.features import FEATURES, trajectory_cost

cb = pytest.importorskip("reachirl.doc.crocoddyl")

POSTURES_DEG = {
    "P1": (-60.0, 90.0),
    "P2": (0.0, 90.0),
    "P3": (30.0, 120.0),
    "P4": (-60.0, 60.0),
    "P5": (50.0, 80.0),
}
# Typical size of each Φ (N = 100, 0.7 s reaches from the postures above); weights are ~1/Φ times random
# factors.
PHI_SCALE = np.array([0.5, 3.0, 0.3, 60.0, 100.0, 3.0, 40.0])


def random_weights(rng, n_windows):
    return np.exp(rng.uniform(np.log(0.3), np.log(3.0), (n_windows, len(FEATURES)))) / PHI_SCALE


def make_task(arm, posture, duration=0.7, n=100):
    return ReachingTask(arm, np.deg2rad(POSTURES_DEG[posture]), 0.95 * arm.length, duration, n)


def rmse_deg(a, b):
    return float(np.rad2deg(np.sqrt(np.mean((a - b) ** 2))))


def test_pinocchio_is_pinned_to_a_version_that_works_with_crocoddyl():
    import crocoddyl
    import pinocchio

    # pin 4.1.0 + crocoddyl 3.2.1 segfaults in ResidualModelFrameTranslation.calc (measured on this project's machines)
    assert pinocchio.__version__ == "4.0.0"
    assert crocoddyl.__version__ == "3.2.1"


def test_frame_translation_residual_does_not_crash():
    """Run the call that segfaults with pin 4.1.0 in a child process, so a crash fails this test only."""
    code = textwrap.dedent(
        """
        import numpy as np, pinocchio, crocoddyl
        from reachirl import ArmModel
        model = ArmModel.from_anthropometrics(1.76, 70.0, "M").pinocchio_model()
        state = crocoddyl.StateMultibody(model)
        tip = model.getFrameId("fingertip")
        residual = crocoddyl.ResidualModelFrameTranslation(state, tip, np.zeros(3), 2)
        costs = crocoddyl.CostModelSum(state, 2)
        costs.addCost("tip", crocoddyl.CostModelResidual(state, residual), 1.0)
        actuation = crocoddyl.ActuationModelFull(state)
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, costs)
        d = dam.createData()
        x, u = np.array([0.3, 1.0, 0.5, -0.2]), np.array([1.0, 0.5])
        dam.calc(d, x, u)
        dam.calcDiff(d, x, u)
        assert np.isfinite(d.cost)
        import mim_solvers  # after pinocchio and crocoddyl (libboost_atomic)
        """
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-2000:]}"


def _finite_difference(model, x, u, h=1e-6):
    def f(x, u):
        d = model.createData()
        model.calc(d, x, u) if u is not None else model.calc(d, x)
        return d.cost, d.xnext.copy(), d.g.copy()

    g0 = f(x, u)[2]
    Lx, Fx, Gx = np.zeros(6), np.zeros((6, 6)), np.zeros((g0.size, 6))
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        (cp, xp, gp), (cm, xm, gm) = f(x + e, u), f(x - e, u)
        Lx[i], Fx[:, i], Gx[:, i] = (cp - cm) / (2 * h), (xp - xm) / (2 * h), (gp - gm) / (2 * h)
    if u is None:
        return Lx, Fx, Gx, None, None, None
    Lu, Fu, Gu = np.zeros(2), np.zeros((6, 2)), np.zeros((g0.size, 2))
    for i in range(2):
        e = np.zeros(2)
        e[i] = h
        (cp, xp, gp), (cm, xm, gm) = f(x, u + e), f(x, u - e)
        Lu[i], Fu[:, i], Gu[:, i] = (cp - cm) / (2 * h), (xp - xm) / (2 * h), (gp - gm) / (2 * h)
    return Lx, Fx, Gx, Lu, Fu, Gu


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
@pytest.mark.parametrize("feature", [*FEATURES, "all"])
def test_knot_derivatives_match_finite_differences(arm, rng, feature, compiled):
    task = make_task(arm, "P2")
    w = random_weights(rng, 1) if feature == "all" else np.eye(len(FEATURES))[[FEATURES.index(feature)]]
    prob = cb.build_problem(arm, task.n_nodes, 1, cb.CsqpOptions(compiled_knots=compiled))
    prob.update(task, w)
    for _ in range(3):
        x = np.r_[rng.uniform(-1, 1.5, 2), rng.uniform(-3, 3, 2), rng.uniform(-5, 5, 2)]
        u = rng.uniform(-8, 8, 2)
        for model, uu in ((prob.running[7], u), (prob.terminal, None)):
            d = model.createData()
            if uu is None:
                model.calc(d, x)
                model.calcDiff(d, x)
            else:
                model.calc(d, x, uu)
                model.calcDiff(d, x, uu)
            Lx, Fx, Gx, Lu, Fu, Gu = _finite_difference(model, x, uu)
            scale = 1.0 + np.abs(Lx).max()
            np.testing.assert_allclose(d.Lx, Lx, atol=2e-6 * scale, err_msg=f"{feature}: Lx")
            np.testing.assert_allclose(d.Gx, Gx, atol=1e-6, err_msg=f"{feature}: Gx")
            if uu is not None:
                np.testing.assert_allclose(d.Lu, Lu, atol=2e-6 * (1.0 + np.abs(Lu).max()), err_msg=f"{feature}: Lu")
                np.testing.assert_allclose(d.Fx, Fx, atol=1e-6, err_msg=f"{feature}: Fx")
                np.testing.assert_allclose(d.Fu, Fu, atol=1e-6, err_msg=f"{feature}: Fu")
                np.testing.assert_allclose(d.Gu, Gu, atol=1e-6, err_msg=f"{feature}: Gu")


def test_problem_cost_is_the_features_cost(arm, rng):
    """On a dynamically consistent trajectory the shooting problem's cost is Σ ω Φ of features.py (energy up
    to its smoothing ε·duration), and its constraints read the terminal fingertip x and velocity.
    """
    task = make_task(arm, "P4", duration=0.75)
    w = random_weights(rng, 6)
    q, qd, tau = cb.initial_guess(task)
    prob = cb.build_problem(arm, task.n_nodes, 6)
    prob.update(task, w)
    xs, us = cb.solver._to_shooting(task, q, qd, tau)
    cost = prob.problem.calc(xs, us)
    exact = trajectory_cost(arm, q, qd, tau, task.dt, w)
    assert abs(cost - exact) <= w[:, 1].max() * cb.DEFAULT_OPTIONS.energy_smoothing * task.duration + 1e-9
    g = prob.problem.terminalData.g
    assert g[0] == pytest.approx(arm.fk(q[-1])[0])
    np.testing.assert_allclose(g[3:], np.r_[q[-1], qd[-1]])


@pytest.mark.parametrize(("posture", "n_windows", "seed"), [("P2", 1, 0), ("P4", 8, 1)])
def test_backends_agree(arm, posture, n_windows, seed):
    rng = np.random.default_rng(seed)
    task = make_task(arm, posture, duration=rng.uniform(0.6, 0.8))
    w = random_weights(rng, n_windows)
    a = solve_doc(task, w, backend="casadi")
    b = solve_doc(task, w, backend="crocoddyl")
    assert a.converged and b.converged, (a.status, b.status)
    assert b.backend == "crocoddyl" and b.q.shape == (101, 2) and b.tau.shape == (100, 2)
    assert rmse_deg(a.q, b.q) < 0.5
    assert abs(b.cost - a.cost) / a.cost < 0.01
    # the constraints hold
    assert arm.fk(b.q[-1])[0] == pytest.approx(task.target_x, abs=1e-5)
    np.testing.assert_allclose(b.qd[-1], 0.0, atol=1e-4)
    np.testing.assert_allclose(b.q[0], task.q0)


def test_weights_change_in_place_and_warm_start_converges(arm):
    rng = np.random.default_rng(3)
    task = make_task(arm, "P2")
    w = random_weights(rng, 6)
    first = solve_doc(task, w, backend="crocoddyl")
    prob = cb.build_problem(arm, task.n_nodes, 6)
    item = prob.running[50].costs.costs["joint_torque"]
    other = prob.running[50].costs.costs["joint_velocity"]
    jt, jv = FEATURES.index("joint_torque"), FEATURES.index("joint_velocity")
    # CSQP gets the weights up to one common factor (solve_doc and crocoddyl.solve normalise their scale)
    assert item.weight / other.weight == pytest.approx(w[3, jt] / w[3, jv])
    w2 = w * 1.1
    w2[:, FEATURES.index("joint_acceleration")] *= 1.2
    cold = solve_doc(task, w2, backend="crocoddyl")
    warm = solve_doc(task, w2, backend="crocoddyl", warm_start=first)
    assert cb.build_problem(arm, task.n_nodes, 6) is prob  # the same problem, updated in place
    assert item.weight / other.weight == pytest.approx(w2[3, jt] / w2[3, jv])
    assert cold.converged and warm.converged
    # A primal warm start usually saves CSQP iterations (here 14 against 23 cold; on the benchmark's weight
    # changes 8 of 10 are faster) but not always (no multipliers to restart from): only check it lands on the
    # same reach.
    assert rmse_deg(cold.q, warm.q) < 0.5


def test_converged_means_feasible(arm):
    """A converged solution satisfies the dynamics and the terminal constraints to the feasibility tolerance
    (CSQP's own test held them only to the cost-relative KKT tolerance).
    """
    rng = np.random.default_rng(7)
    task = make_task(arm, "P4", duration=0.798)
    w = random_weights(rng, 8)
    b = solve_doc(task, w, backend="crocoddyl")
    assert b.converged, b.status
    tol = cb.DEFAULT_OPTIONS.feasibility_tolerance
    dt = task.dt
    # semi-implicit Euler: q_{k+1} = q_k + dt q̇_{k+1}, q̇_{k+1} = q̇_k + dt q̈_k with τ_k = ID(q_k, q̇_k, q̈_k)
    np.testing.assert_allclose(b.q[1:], b.q[:-1] + dt * b.qd[1:], atol=2 * tol)
    tau = arm.inverse_dynamics(b.q[:-1], b.qd[:-1], np.diff(b.qd, axis=0) / dt)
    np.testing.assert_allclose(b.tau, tau, atol=1e-4 * (1.0 + np.abs(b.tau).max()))
    assert abs(arm.fk(b.q[-1])[0] - task.target_x) <= tol
    np.testing.assert_allclose(b.qd[-1], 0.0, atol=tol)


@pytest.mark.slow
@pytest.mark.parametrize("posture", list(POSTURES_DEG))
@pytest.mark.parametrize("n_windows", [1, 6, 8])
def test_backends_agree_sweep(arm, posture, n_windows):
    rng = np.random.default_rng(100 * n_windows + int(posture[1]))
    task = make_task(arm, posture, duration=rng.uniform(0.6, 0.8))
    w = random_weights(rng, n_windows)
    a = solve_doc(task, w, backend="casadi")
    b = solve_doc(task, w, backend="crocoddyl")
    assert a.converged, a.status
    assert b.converged, b.status
    assert rmse_deg(a.q, b.q) < 0.5
    assert abs(b.cost - a.cost) / a.cost < 0.01


def test_bounds_left_out_of_the_first_solve_come_back_when_violated(arm):
    """The first CSQP solve leaves the running knots' joint-limit and speed bounds out (``screen_bounds``).
    On a reach whose free optimum exceeds the speed bound, the returned trajectory must still respect it, and
    land on CasADi's solution (which always carries the bound); on a reach where the bounds are inactive the
    screened solve is the full problem's solution.
    """
    rng = np.random.default_rng(11)
    task = make_task(arm, "P2")
    w = random_weights(rng, 1)
    free = solve_doc(task, w, backend="crocoddyl")
    full = cb.solve(task, w, options=cb.CsqpOptions(screen_bounds=False))
    assert free.converged and full.converged and free.attempts == 1
    assert rmse_deg(free.q, full.q) < 0.01
    peak = np.abs(free.qd).max(axis=0)
    slow = ReachingTask(task.arm, task.q0, task.target_x, task.duration, task.n_nodes, qd_max=0.8 * peak)
    a = solve_doc(slow, w, backend="casadi")
    b = solve_doc(slow, w, backend="crocoddyl")
    assert a.converged and b.converged, (a.status, b.status)
    assert b.attempts >= 2  # the screened solution broke the bound and was solved again with it
    tol = cb.DEFAULT_OPTIONS.feasibility_tolerance
    assert np.all(np.abs(b.qd) <= slow.qd_max + tol)
    assert np.any(np.abs(b.qd) >= slow.qd_max - 1e-3)  # the bound is active
    assert rmse_deg(a.q, b.q) < 0.05
    assert abs(b.cost - a.cost) / a.cost < 1e-3


def test_a_failed_screened_solve_is_solved_again_with_every_bound_from_the_same_start(arm, monkeypatch):
    rng = np.random.default_rng(12)
    task = make_task(arm, "P4")
    w = random_weights(rng, 1)
    real, calls = cb.solver._attempt, []

    def screened_fails(prob, task_, weights, xs, us, tol, options, running_bounds=True):
        calls.append((running_bounds, np.array(xs)))
        out = real(prob, task_, weights, xs, us, tol, options, running_bounds)
        return (False, *out[1:]) if not running_bounds else out

    monkeypatch.setattr(cb.solver, "_attempt", screened_fails)
    sol = solve_doc(task, w, backend="crocoddyl")
    assert [c[0] for c in calls] == [False, True]
    np.testing.assert_array_equal(calls[1][1], calls[0][1])  # not from the failed solve's end point
    assert sol.converged and sol.attempts == 2
    tol = cb.DEFAULT_OPTIONS.feasibility_tolerance
    assert abs(arm.fk(sol.q[-1])[0] - task.target_x) <= tol


def test_a_held_back_line_search_reaches_the_same_optimum_in_fewer_iterations(arm):
    """``line_search_growth``: after α = 1 the line search halves from twice the last accepted step instead of
    from ½. On this reach (``bench backends``' fifth problem) CSQP's greedy search takes long steps that it
    then undoes (58 SQP iterations); held back (the default), it reaches the same optimum as CasADi in far
    fewer. Warm starts keep CSQP's own search."""
    task = ReachingTask(arm, np.deg2rad([30.0, 120.0]), 0.95 * arm.length, 0.6644573449479664, 100)
    w = np.array([[3.7566, 0.16801, 2.3031, 0.013074, 0.010436, 0.12960, 0.019143]])
    ref = solve_doc(task, w, backend="casadi")
    greedy_options = cb.CsqpOptions(line_search_growth=0.0)  # CSQP's own line search
    greedy = cb.solve(task, w, options=greedy_options)
    held = cb.solve(task, w)  # the default: growth 2
    assert cb.DEFAULT_OPTIONS.line_search_growth == 2.0
    assert ref.converged and greedy.converged and held.converged
    assert rmse_deg(held.q, ref.q) < 0.03 and abs(held.cost - ref.cost) / ref.cost < 1e-3
    assert rmse_deg(greedy.q, ref.q) < 0.03
    assert held.iterations < greedy.iterations / 2, (held.iterations, greedy.iterations)
    # a warm start ignores the option: the same iterates as CSQP's own search
    w2 = 1.1 * w
    a = cb.solve(task, w2, warm_start=held, options=greedy_options)
    b = cb.solve(task, w2, warm_start=held)
    assert a.converged and a.iterations == b.iterations and np.array_equal(a.q, b.q)
