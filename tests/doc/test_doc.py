"""The DOC: constraints, cost and local optimality on both backends; warm starts, a convergence sweep and
errors on the default one."""

import numpy as np
import pinocchio as pin
import pytest

from reachirl import FEATURES, DocSolution, ReachingTask, solve_doc
from reachirl.features import trajectory_cost

# Start postures (q1, q2) in degrees: a spread of the workspace, fingertip short of a bar at 90 % of arm
# length.
TEST_POSTURES_DEG = [(-60.0, 90.0), (0.0, 90.0), (30.0, 120.0), (-60.0, 60.0), (50.0, 80.0)]
# Typical size of each Φ over a whole reach (from a uniform-weight solve); weights are drawn relative to it.
FEATURE_SCALE = np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])


def random_weights(rng, n_windows, normalised=True):
    w = np.exp(rng.uniform(np.log(1e-2), np.log(1.0), size=(n_windows, len(FEATURES))))
    return w / FEATURE_SCALE if normalised else w * 0.1


def make_task(arm, posture_deg, duration=0.7, frac=0.9, n_nodes=100):
    return ReachingTask(arm, np.deg2rad(posture_deg), frac * arm.length, duration, n_nodes=n_nodes)


# What each backend guarantees. CasADi meets the constraints and the Euler dynamics to round-off; Crocoddyl/CSQP
# declares convergence once its gaps and constraint violation are within its absolute feasibility tolerance,
# 1e-5 (rad, rad/s, m). Crocoddyl's energy term is |·| smoothed by ε = 1 mW, so its optimum is that of a slightly
# different problem: perturbations may lower the exact cost by a little.
TOL = {
    "casadi": {"feasibility": 1e-8, "dynamics": 1e-8, "optimality": 1e-7},
    "crocoddyl": {"feasibility": 1e-5, "dynamics": 1e-5, "optimality": 5e-4},
}


def _solve_example(arm, backend):
    rng = np.random.default_rng(7)
    task = make_task(arm, TEST_POSTURES_DEG[1])
    w = random_weights(rng, 8)
    return task, w, solve_doc(task, w, backend=backend)


@pytest.fixture(scope="module")
def solved(arm):
    return _solve_example(arm, "casadi")


@pytest.fixture(scope="module", params=list(TOL))
def any_backend(arm, request):
    return (*_solve_example(arm, request.param), TOL[request.param])


def test_solution_shapes_and_fields(any_backend):
    task, _, sol, _ = any_backend
    n = task.n_nodes
    assert sol.converged and sol.iterations > 0 and sol.solve_time > 0
    assert sol.t.shape == (n + 1,) and sol.q.shape == (n + 1, 2) and sol.qd.shape == (n + 1, 2)
    assert sol.tau.shape == (n, 2)
    assert sol.t[-1] == pytest.approx(task.duration)


def test_constraints_hold_at_solution(any_backend):
    task, _, sol, tol = any_backend
    arm, dt, eps = task.arm, task.dt, tol["feasibility"]
    np.testing.assert_allclose(sol.q[0], task.q0, atol=1e-12)
    np.testing.assert_allclose(sol.qd[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(sol.qd[-1], 0.0, atol=eps)
    assert arm.fk(sol.q[-1])[0] == pytest.approx(task.target_x, abs=eps)
    assert np.all(sol.q >= task.q_lower - eps) and np.all(sol.q <= task.q_upper + eps)
    assert np.all(np.abs(sol.qd) <= task.qd_max + eps)
    # semi-implicit Euler with Pinocchio's ABA (an independent implementation of the dynamics)
    model = arm.pinocchio_model()
    data = model.createData()
    for k in range(task.n_nodes):
        qdd = pin.aba(model, data, sol.q[k], sol.qd[k], sol.tau[k])
        np.testing.assert_allclose(sol.qd[k + 1], sol.qd[k] + dt * qdd, atol=tol["dynamics"])
        np.testing.assert_allclose(sol.q[k + 1], sol.q[k] + dt * sol.qd[k + 1], atol=tol["dynamics"])


def _cost_with_pinocchio(task, w, q, qd, tau):
    """The seed's objective recomputed from scratch with Pinocchio (CRBA, RNEA, frame Jacobian), sharing no
    code with reachirl.features: interval k of N is in window ⌊k·S/N⌋; q̈_k = (q̇_{k+1} − q̇_k)/dt;
    τ̇_k = (τ_k − τ_{k−1})/dt with τ_{−1} the gravity torque at q_0."""
    model = task.arm.pinocchio_model()
    data = model.createData()
    tip = model.getFrameId("fingertip")
    n, dt, n_win = task.n_nodes, task.dt, w.shape[0]
    tau_prev = pin.rnea(model, data, q[0], np.zeros(2), np.zeros(2))
    total = 0.0
    for k in range(n):
        pin.computeJointJacobians(model, data, q[k])
        pin.updateFramePlacements(model, data)
        jac = pin.getFrameJacobian(model, data, tip, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:2]
        mass = pin.crba(model, data, q[k])
        mass = np.triu(mass) + np.triu(mass, 1).T
        qdd = (qd[k + 1] - qd[k]) / dt
        rates = [
            float(np.sum((jac @ qd[k]) ** 2)),
            abs(float(qd[k] @ tau[k])),
            float(qd[k] @ mass @ qd[k]),
            float(qdd @ qdd),
            float(np.sum(((tau[k] - tau_prev) / dt) ** 2)),
            float(qd[k] @ qd[k]),
            float(tau[k] @ tau[k]),
        ]
        total += dt * float(np.dot(w[(k * n_win) // n], rates))
        tau_prev = tau[k]
    return total


def test_reported_cost_is_the_seeds_objective(any_backend):
    task, w, sol, _ = any_backend
    # torques from the solution's own trajectory by RNEA (independent of the backend's inverse dynamics)
    model = task.arm.pinocchio_model()
    data = model.createData()
    tau = np.array(
        [pin.rnea(model, data, sol.q[k], sol.qd[k], (sol.qd[k + 1] - sol.qd[k]) / task.dt) for k in range(task.n_nodes)]
    )
    np.testing.assert_allclose(tau, sol.tau, rtol=1e-7, atol=1e-7)
    assert sol.cost == pytest.approx(_cost_with_pinocchio(task, w, sol.q, sol.qd, tau), rel=1e-7)


def test_the_casadi_objective_is_the_seeds_objective_away_from_the_optimum(arm, solved, rng):
    """CasADi's symbolic NLP objective (what fatrop minimises), at a feasible path that is not its optimum and
    with exact slacks, equals the seed's objective recomputed with Pinocchio."""
    from reachirl.doc import casadi as backend

    task, w, sol = solved
    q, qd, tau = backend.rest_to_rest_knots(task, _perturbed(task, sol.q, rng, 0.02)[0])
    nlp = backend.build_nlp(task.n_nodes)
    fscale = 0.37
    p = nlp.params(task, w, fscale)
    value = float(nlp.objective(backend._pack(task, q), p)) / fscale
    assert value == pytest.approx(_cost_with_pinocchio(task, w, q, qd, tau), rel=1e-10)
    assert value > sol.cost


def test_casadi_bounds_follow_each_tasks_own_limits(arm):
    """The bounds an NLP keeps per set of joint limits: a task with limits of its own gets its own, a task of
    the first limits gets the first ones back, and nobody can write into the shared arrays."""
    import dataclasses

    from reachirl.doc import casadi as backend

    task = make_task(arm, TEST_POSTURES_DEG[1], n_nodes=40)
    narrower = dataclasses.replace(task, q_upper=task.q_upper - 0.1)
    slower = dataclasses.replace(task, qd_max=task.qd_max * 0.5)
    nlp = backend.build_nlp(task.n_nodes)
    for t in (task, narrower, slower, task):
        ub = nlp.bounds(t)["ubx"][2:-6].reshape(task.n_nodes - 1, -1)  # the inner knots' (x, u) rows
        np.testing.assert_array_equal(ub[:, 0:2], np.tile(t.q_upper, (task.n_nodes - 1, 1)))
        np.testing.assert_array_equal(ub[:, 2:4], np.tile(t.qd_max, (task.n_nodes - 1, 1)))
    with pytest.raises(ValueError, match="read-only"):
        nlp.bounds(task)["lbx"][0] = 0.0


def test_the_returned_torques_drive_the_arm_onto_the_bar_at_rest(any_backend):
    """The terminal constraints met by the motion the torques produce, not only by the returned knots:
    integrate ``sol.tau`` from (q0, 0) with Pinocchio's ABA (semi-implicit Euler, the DOC's dynamics)."""
    task, _, sol, tol = any_backend
    model = task.arm.pinocchio_model()
    data = model.createData()
    q, qd = task.q0.copy(), np.zeros(2)
    for k in range(task.n_nodes):
        qd = qd + task.dt * pin.aba(model, data, q, qd, sol.tau[k])
        q = q + task.dt * qd
    pin.framesForwardKinematics(model, data, q)
    tip_x = data.oMf[model.getFrameId("fingertip")].translation[0]
    eps = 50 * tol["feasibility"]  # the open-loop integration accumulates the per-step feasibility error
    np.testing.assert_allclose(qd, 0.0, atol=eps)
    assert tip_x == pytest.approx(task.target_x, abs=eps)


def _perturbed(task, q, rng, amplitude):
    """A feasible variation: a smooth bump in the interior, zero at the start and on the last knots."""
    n = task.n_nodes
    s = np.linspace(0, 1, n + 1)
    lo, hi = sorted(rng.uniform(0.05, 0.85, 2))
    hi = max(hi, lo + 0.1)
    bump = np.where((s > lo) & (s < hi), np.sin(np.pi * (s - lo) / (hi - lo)) ** 2, 0.0)
    q_new = q + amplitude * bump[:, None] * rng.normal(size=2)
    dt = task.dt
    qd = np.vstack([np.zeros(2), np.diff(q_new, axis=0) / dt])
    tau = task.arm.inverse_dynamics(q_new[:-1], qd[:-1], np.diff(qd, axis=0) / dt)
    return q_new, qd, tau


def test_feasible_perturbations_never_lower_the_cost(any_backend, rng):
    task, w, sol, tol = any_backend
    q_sol = sol.q.copy()
    q_sol[-1] = q_sol[-2]  # the exact q̇_N = 0 (Crocoddyl meets it to its tolerance)
    for amplitude in (1e-2, 3e-2):
        for _ in range(20):
            q, qd, tau = _perturbed(task, q_sol, rng, amplitude)
            assert task.arm.fk(q[-1])[0] == pytest.approx(task.arm.fk(q_sol[-1])[0], abs=1e-12)
            assert trajectory_cost(task.arm, q, qd, tau, task.dt, w) >= sol.cost * (1 - tol["optimality"])


def test_warm_start_reaches_the_same_optimum_in_fewer_iterations(solved, rng):
    task, w, sol = solved
    w2 = w * np.exp(0.1 * rng.normal(size=w.shape))
    cold = solve_doc(task, w2)
    warm = solve_doc(task, w2, warm_start=sol)
    assert cold.converged and warm.converged
    assert warm.iterations < cold.iterations
    assert np.rad2deg(np.abs(warm.q - cold.q).max()) < 0.05
    assert warm.cost == pytest.approx(cold.cost, rel=1e-4)


def test_warm_start_from_another_task_on_the_same_knots_is_solved_cold(arm, solved):
    task, w, sol = solved
    other = make_task(arm, TEST_POSTURES_DEG[2], n_nodes=task.n_nodes)
    out = solve_doc(other, w, warm_start=sol)
    cold = solve_doc(other, w)
    assert out.converged and out.iterations == cold.iterations
    np.testing.assert_array_equal(out.q, cold.q)


def test_warm_start_on_another_number_of_knots_is_refused(arm, solved):
    # it was silently ignored, the task solved cold, hiding the caller's mix-up of tasks
    task, w, sol = solved
    other = make_task(arm, TEST_POSTURES_DEG[1], n_nodes=60)
    want = rf"^warm_start is a solution on {task.n_nodes + 1} knots, but the task has 61 \(n_nodes=60\)"
    with pytest.raises(ValueError, match=want):
        solve_doc(other, w, warm_start=sol)


@pytest.mark.parametrize("backend", ["casadi", "crocoddyl"])
def test_each_backend_refuses_a_warm_start_on_another_number_of_knots(arm, backend):
    impl = pytest.importorskip(f"reachirl.doc.{backend}")
    task = make_task(arm, TEST_POSTURES_DEG[0], n_nodes=30)
    n = 20
    foreign = DocSolution(
        t=np.linspace(0.0, 1.0, n + 1), q=np.zeros((n + 1, 2)), qd=np.zeros((n + 1, 2)), tau=np.zeros((n, 2)),
        cost=1.0, converged=True, iterations=1, solve_time=0.0, backend=backend,
        warm={"backend": backend, "task": ("another",), "fscale": 1.0, "knots": (np.zeros((n + 1, 2)),) * 3},
    )  # fmt: skip
    with pytest.raises(ValueError, match=r"^warm_start is a solution on 21 knots, but the task has 31 \(n_nodes=30\)"):
        impl.solve(task, np.full((2, 7), 0.05), warm_start=foreign)


def test_weights_change_the_optimum(arm):
    task = make_task(arm, TEST_POSTURES_DEG[3])
    acc = np.zeros((1, 7))
    acc[0, 3] = 1.0
    trq = np.zeros((1, 7))
    trq[0, 6] = 1.0
    a, t = solve_doc(task, acc), solve_doc(task, trq)
    assert a.converged and t.converged

    # each optimum is best under its own cost
    def cost(s, w):
        return trajectory_cost(arm, s.q, s.qd, s.tau, task.dt, w)

    assert cost(a, acc) < cost(t, acc)
    assert cost(t, trq) < cost(a, trq)


def test_convergence_sweep(arm):
    """At least 100 problems: 5 postures × 3 durations × 1/6/8 windows × 3 weight draws; ≥ 99 % converge."""
    rng = np.random.default_rng(2024)
    results, by_fatrop = [], []
    for posture in TEST_POSTURES_DEG:
        for duration in (0.6, 0.72, 0.85):
            for n_windows in (1, 6, 8):
                for draw in range(3):
                    w = random_weights(rng, n_windows, normalised=draw != 2)
                    sol = solve_doc(make_task(arm, posture, duration), w)
                    results.append(sol.converged)
                    by_fatrop.append(sol.attempts == 1 and sol.status == "fatrop: Success")
    assert len(results) == 135
    assert np.mean(results) >= 0.99, f"converged {sum(results)}/{len(results)}"
    assert np.mean(by_fatrop) >= 0.97, f"fatrop alone {sum(by_fatrop)}/{len(by_fatrop)}"


def test_a_reach_fatrop_solved_is_not_solved_again_by_ipopt(arm):
    """fatrop 1.1.8 reports its "acceptable level" stop as unsuccessful; with it, 12 of these 15 cold solves at
    XX as fatrop failures and solved a second time by IPOPT."""
    from reachirl.virtual import MOVEMENT_FRACTION, POSTURES, nominal_weights, posture_q

    sols = [
        solve_doc(ReachingTask(arm, posture_q(p), 0.95 * arm.length, d / MOVEMENT_FRACTION), nominal_weights())
        for p in POSTURES
        for d in (0.6, 0.7, 0.8)
    ]
    assert all(s.converged for s in sols)
    assert [s.status for s in sols] == ["fatrop: Success"] * 15
    assert all(s.attempts == 1 for s in sols)


@pytest.mark.parametrize(
    ("weights", "match"),
    [
        (-np.ones((8, 7)), "weights must be >= 0"),
        (np.ones((8, 6)), r"weights must have shape \(n_windows, 7\)"),
        (np.full((2, 7), np.nan), "weights must be finite"),
        (np.ones((200, 7)), "200 windows do not fit in 100 intervals"),
        ([[0.05] * 7, [0.05] * 6], r"weights must be numbers of shape \(n_windows, 7\), got \[\[0\.05"),
        ("low", r"weights must be numbers of shape \(n_windows, 7\), got 'low'"),
        (np.full((2, 7), 0.05) + 1e-3j, r"weights must be real numbers, got complex numbers \(dtype complex128\)"),
        (np.ones((2, 7), bool), r"weights must be real numbers, got booleans \(dtype bool\)"),
    ],
)
def test_bad_weights_raise(solved, weights, match):
    task, _, _ = solved
    with pytest.raises(ValueError, match=match):
        solve_doc(task, weights)


def test_bad_backend_and_task(arm, solved):
    task, w, _ = solved
    with pytest.raises(ValueError, match="unknown DOC backend 'ipopt'"):
        solve_doc(task, w, backend="ipopt")
    with pytest.raises(ValueError, match="out of reach"):
        ReachingTask(arm, [0.0, 1.0], 2 * arm.length, 0.7)
    with pytest.raises(ValueError, match="outside the joint limits"):
        ReachingTask(arm, [0.0, -1.0], 0.5, 0.7)
    with pytest.raises(ValueError, match="duration must be a positive"):
        ReachingTask(arm, [0.0, 1.0], 0.5, -1)
    with pytest.raises(ValueError, match=r"q0 must have shape \(2,\)"):
        ReachingTask(arm, [0.0, 1.0, 2.0], 0.5, 0.7)


def test_joint_limits_in_degrees_are_refused(arm):
    # [-150, 120] "rad" bounded nothing: the DOC was solved without joint limits
    with pytest.raises(ValueError, match=r"^q_upper \[120\. 160\.\] is beyond a full turn of a joint: radians"):
        ReachingTask(arm, [0.0, 1.5], 0.5, 0.7, q_upper=[120.0, 160.0])
    with pytest.raises(ValueError, match=r"^q_lower \[-150\.   -5\.\] is beyond a full turn"):
        ReachingTask(arm, [0.0, 1.5], 0.5, 0.7, q_lower=[-150.0, -5.0], q_upper=[120.0, 160.0])


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (([0.0, 1.0], None, 0.7), r"^target_x must be a number \(m\), got None$"),
        (([0.0, 1.0], np.array([0.5]), 0.7), r"^target_x must be a number \(m\), got array\(\[0\.5\]\)$"),
        (([0.0, 1.0], 0.5, "0.7 s"), r"^duration must be a number \(s\), got '0\.7 s'$"),
        (("q0", 0.5, 0.7), r"^q0 must be 2 numbers, got 'q0'$"),
        ((np.array([-1.5, 1.5]) + 0.1j, 0.5, 0.7), r"^q0 must be 2 real numbers, got complex numbers"),
    ],
)
def test_a_task_of_non_numbers_names_the_field(arm, args, match):
    # numpy's and float()'s own words ("float() argument must be a string or a real number, not 'NoneType'",
    # "only 0-dimensional arrays can be converted to Python scalars") named no field
    with pytest.raises(ValueError, match=match):
        ReachingTask(arm, *args)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"q0": np.array([0.0, np.nan])}, r"^q0 must be finite, got \[ 0\. nan\]$"),
        ({"q_upper": np.array([np.inf, 2.5])}, r"^q_upper must be finite, got \[inf 2\.5\]$"),
        ({"q_lower": np.array([0.5, 0.0]), "q_upper": np.array([0.5, 2.6])}, r"^q_lower \[0\.5 0\. \] must be below"),
        ({"q_lower": [-2.6, 0.1], "q_upper": [2.1, 0.1]}, r"^q_lower \[-2\.6  0\.1\] must be below q_upper"),
        ({"qd_max": np.array([10.0, 0.0])}, r"^qd_max must be > 0, got \[10\.  0\.\]$"),
        ({"q0": np.array([0.0, 3.0])}, r"^q0 = \(0\.0°, 171\.9°\) lies outside the joint limits"),
    ],
)
def test_a_task_of_float_arrays_is_checked_as_lists_are(arm, kwargs, match):
    # float64 pairs (another task's, a trial's posture) take a shorter path through the checks than lists do
    base = {"q0": np.array([0.0, 1.0]), "q_lower": np.array([-2.6, 0.0]), "q_upper": np.array([2.1, 2.6])}
    with pytest.raises(ValueError, match=match):
        ReachingTask(arm, target_x=0.3, duration=0.7, **{**base, **kwargs})


def test_a_task_keeps_its_pairs_read_only_and_replace_checks_them_again(arm):
    import dataclasses

    q0 = np.array([0.0, 1.0])
    task = ReachingTask(arm, q0, 0.3, 0.7)
    assert q0.flags.writeable  # the caller's array is left as it was; the task's pair cannot be written
    with pytest.raises(ValueError, match="read-only"):
        task.q0[0] = 1.0
    longer = dataclasses.replace(task, duration=1.4)
    assert longer.q0 is task.q0 and longer.duration == 1.4  # a checked pair is taken as it is
    with pytest.raises(ValueError, match=r"^qd_max must be > 0"):
        dataclasses.replace(task, qd_max=np.array([-1.0, 10.0]))


def test_a_model_of_complex_weights_is_not_built():
    # the cast to float dropped the imaginary part, with a ComplexWarning only
    from reachirl.irl.model import LearnedModel

    with pytest.raises(ValueError, match=r"^weights must be real numbers, got complex numbers"):
        LearnedModel(weights=np.full((2, 7), 0.05) + 1e-3j, n_nodes=20)


def test_agrees_with_a_plain_multiple_shooting_formulation(arm):
    """An independent formulation (states and torques as variables, forward dynamics, IPOPT defaults)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from bench_doc import PlainDoc

    rng = np.random.default_rng(3)
    task = make_task(arm, TEST_POSTURES_DEG[4], n_nodes=50)
    w = random_weights(rng, 6)
    ours = solve_doc(task, w)
    plain = PlainDoc(task, 6).solve(w)
    assert ours.converged and plain["converged"]
    assert np.rad2deg(np.sqrt(np.mean((ours.q - plain["q"]) ** 2))) < 0.01
    np.testing.assert_allclose(plain["tau"], ours.tau, atol=1e-3 * np.abs(ours.tau).max())
    c_plain = trajectory_cost(arm, plain["q"], plain["qd"], plain["tau"], task.dt, w)
    assert c_plain == pytest.approx(ours.cost, rel=1e-5)


def test_falls_back_to_ipopt_when_fatrop_fails(arm, monkeypatch):
    """A cold fatrop solve that does not converge is solved again with IPOPT (forced: 2 fatrop iterations)."""
    from reachirl.doc import casadi as backend

    monkeypatch.setattr(backend, "FATROP_OPTIONS", {**backend.FATROP_OPTIONS, "fatrop.max_iter": 2})
    monkeypatch.setattr(backend, "build_nlp", backend.build_nlp.__wrapped__)  # a fresh NLP, outside the cache
    task = make_task(arm, TEST_POSTURES_DEG[0], n_nodes=40)
    w = random_weights(np.random.default_rng(5), 2)
    sol = solve_doc(task, w)
    assert sol.converged and sol.status.startswith("ipopt") and sol.iterations > 2
    assert sol.cost == pytest.approx(_cost_with_pinocchio(task, w, sol.q, sol.qd, sol.tau), rel=1e-8)
    assert arm.fk(sol.q[-1])[0] == pytest.approx(task.target_x, abs=1e-10)


def test_a_wrong_warm_start_or_nan_weights_are_refused_plainly(arm):
    task = ReachingTask(arm, q0=np.deg2rad([-90.0, 90.0]), target_x=0.9 * arm.length, duration=0.7, n_nodes=20)
    w = np.full((2, 7), 0.05)
    with pytest.raises(TypeError, match=r"warm_start must be a DocSolution .*, got int"):
        solve_doc(task, w, warm_start=5)
    sol = solve_doc(task, w)
    with pytest.raises(ValueError, match="weights must be finite"):
        trajectory_cost(arm, sol.q, sol.qd, sol.tau, task.dt, np.full((2, 7), np.nan))


def _solution(**changes):
    n = 4
    t = np.linspace(0.0, 0.5, n + 1)
    kw = dict(
        t=t,
        q=np.column_stack([np.linspace(-0.3, 0.2, n + 1), np.full(n + 1, 1.2)]),
        qd=np.zeros((n + 1, 2)),
        tau=np.ones((n, 2)),
        cost=1.5,
        converged=True,
        iterations=7,
        solve_time=0.01,
        status="Solve_Succeeded",
        backend="casadi",
    )
    kw.update(changes)
    return DocSolution(**kw)


def test_doc_solutions_compare_by_value():
    """``==`` of two solutions raised numpy's "truth value of an array ... is ambiguous" (dataclass equality
    compared the arrays with ==), and so did ``in``."""
    a = _solution()
    b = _solution(warm={"x": np.arange(3.0)})  # the solver's opaque state is not compared
    assert a == b and not a != b and b in [a]
    q = a.q.copy()
    q[2, 1] += 1e-9
    assert a != _solution(q=q)
    assert a != _solution(tau=np.ones((4, 2)) * 2.0)
    assert a != _solution(iterations=8) and a != _solution(status="Maximum_Iterations_Exceeded")
    assert a != "a solution" and (a == None) is False  # noqa: E711 - the comparison itself is tested
    failed = _solution(q=np.full((5, 2), np.nan), cost=float("nan"), converged=False)
    assert failed == _solution(q=np.full((5, 2), np.nan), cost=float("nan"), converged=False)  # NaN where NaN was
    assert failed != _solution(cost=float("nan"), converged=False)
    with pytest.raises(TypeError, match=r"unhashable type: 'DocSolution'"):
        hash(a)
