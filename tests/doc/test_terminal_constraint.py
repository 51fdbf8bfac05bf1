"""The terminal conditions are met by the trajectory each backend returns (checked on the returned arrays, not
on the solver's report): fingertip on the bar, at rest at both ends, and the returned knots follow the Euler
dynamics with the returned torques."""

import numpy as np
import pytest

from reachirl import ReachingTask, solve_doc

WEIGHTS = np.array([[0.5, 0.2, 2.0, 0.01, 0.002, 0.3, 0.02], [0.1, 0.4, 1.0, 0.003, 0.001, 0.1, 0.05]])


@pytest.mark.parametrize("backend", ["casadi", "crocoddyl"])
@pytest.mark.parametrize("q0_deg", [(0.0, 90.0), (-60.0, 60.0)])
def test_returned_trajectory_meets_the_terminal_constraints(arm, backend, q0_deg):
    if backend == "crocoddyl":
        pytest.importorskip("reachirl.doc.crocoddyl")
    task = ReachingTask(arm, np.deg2rad(q0_deg), 0.9 * arm.length, 0.7, n_nodes=40)
    sol = solve_doc(task, WEIGHTS, backend=backend)
    assert sol.converged, sol.status
    tip = arm.fk(sol.q[-1])
    assert abs(tip[0] - task.target_x) < 1e-5  # metres: the fingertip is on the bar
    assert np.max(np.abs(sol.qd[-1])) < 1e-5  # at rest at the end
    np.testing.assert_allclose(sol.q[0], task.q0, atol=1e-12)
    np.testing.assert_allclose(sol.qd[0], 0.0, atol=1e-12)
    # the returned knots are a trajectory of the model: semi-implicit Euler with the returned torques
    dt = task.dt
    qdd = arm.forward_dynamics(sol.q[:-1], sol.qd[:-1], sol.tau)
    np.testing.assert_allclose(sol.qd[1:], sol.qd[:-1] + dt * qdd, atol=1e-5)
    np.testing.assert_allclose(sol.q[1:], sol.q[:-1] + dt * sol.qd[1:], atol=1e-5)
    # and within the joint limits
    assert np.all(sol.q >= task.q_lower - 1e-6) and np.all(sol.q <= task.q_upper + 1e-6)
