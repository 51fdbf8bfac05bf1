"""A prediction's cold start from a similar reach (``reachirl.doc.task.moved_path``, the fit's own rollout in
``reproduce``): it is a start on the task, it reaches the same optimum as the minimum-jerk start with fewer
iterations, and a wrong path is refused."""

import numpy as np
import pytest

from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.doc.evaluation import evaluate_trials
from reachirl.doc.task import moved_path, on_bar
from reachirl.virtual import nominal_weights, posture_q

N = 50
ARM = ArmModel.from_anthropometrics(1.76, 70.0, "M")


def _task(dq_deg=(0.0, 0.0), reach=0.95, duration=0.8) -> ReachingTask:
    return ReachingTask(ARM, posture_q("P2") + np.deg2rad(dq_deg), reach * ARM.length, duration, n_nodes=N)


def test_the_moved_path_starts_at_the_task_and_ends_on_its_bar():
    mean = solve_doc(_task(), nominal_weights())
    task = _task((4.0, -3.0), reach=0.92)
    g = moved_path(task, mean.q)
    assert np.allclose(g[0], task.q0, atol=1e-12)
    assert abs(ARM.fk(g[-1])[0] - task.target_x) < 1e-12
    assert abs(ARM.fk(mean.q[-1])[0] - task.target_x) > 0.01  # the rollout itself ends on another bar
    # the middle keeps the rollout's shape: the offset between them is a smooth blend of the two end offsets
    assert np.allclose(g[N // 2] - mean.q[N // 2], 0.5 * ((task.q0 - mean.q[0]) + (g[-1] - mean.q[-1])), atol=1e-12)
    q = np.array([0.3, 1.2])
    assert abs(ARM.fk(on_bar(task, q))[0] - task.target_x) < 1e-12


def test_the_bar_projection_takes_the_steps_of_the_arms_own_kinematics():
    # on_bar works on scalars (every solve ends with it): its steps are the minimum-norm Newton steps of the arm's
    # fk and jacobian, number for number, from postures on the bar to a solver's tolerance and from farther
    rng = np.random.default_rng(3)
    task = _task((4.0, -3.0), reach=0.92)
    start = on_bar(task, np.array([0.3, 1.2]))
    for dq in [*rng.normal(0.0, 1e-6, (1000, 2)), *rng.normal(0.0, 0.05, (1000, 2))]:
        q = start + dq
        ref = q.copy()
        for _ in range(20):
            r = task.target_x - float(ARM.fk(ref)[0])
            if abs(r) < 1e-15:
                break
            j = ARM.jacobian(ref)[0]
            ref += j * (r / float(j @ j))
        np.testing.assert_array_equal(on_bar(task, q), ref)


def test_starting_from_a_similar_reach_finds_the_same_optimum_in_fewer_iterations():
    w = nominal_weights()
    mean = solve_doc(_task(), w)
    cold_it, moved_it = 0, 0
    for dq, reach, duration in (((3.0, -2.0), 0.93, 0.75), ((-4.0, 3.0), 0.97, 0.85), ((2.0, 4.0), 0.94, 0.8)):
        task = _task(dq, reach, duration)
        cold = solve_doc(task, w)
        moved = solve_doc(task, w, guess=moved_path(task, mean.q))
        assert cold.converged and moved.converged
        assert np.degrees(np.max(np.abs(cold.q - moved.q))) < 0.01
        assert abs(moved.cost - cold.cost) <= 1e-4 * cold.cost
        cold_it += cold.iterations
        moved_it += moved.iterations
    assert moved_it < cold_it


def test_evaluate_trials_takes_the_path_and_refuses_a_wrong_one():
    from reachirl.data.trial import trial_from_solution

    w = nominal_weights()
    task = _task((3.0, -2.0), 0.93, 0.75)
    trial = trial_from_solution(solve_doc(task, w), ARM, task.target_x)
    mean = solve_doc(_task(), w)
    plain, moved = evaluate_trials(w, [trial], N), evaluate_trials(w, [trial], N, path=mean.q)
    assert plain[0].converged and moved[0].converged
    assert abs(plain[0].rmse_q - moved[0].rmse_q) < 1e-3
    assert moved[0].prediction.iterations < plain[0].prediction.iterations
    with pytest.raises(ValueError, match=r"path must be a finite joint path of shape \(51, 2\), got \(50, 2\)"):
        evaluate_trials(w, [trial], N, path=mean.q[:-1])
    bad = mean.q.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="path must be a finite joint path"):
        moved_path(task, bad)
