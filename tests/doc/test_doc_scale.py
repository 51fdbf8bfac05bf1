"""The DOC never lies and never hangs: ω and c·ω are the same problem on both backends (c from 1e-20 to 1e20,
and 1e±300 without a native abort), and a reach outside a physical range is an input error, not a long solve."""

import numpy as np
import pytest

from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.errors import InputError

FEATURE_SCALE = np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])
W = np.array([[0.05, 0.5, 0.05, 3.0, 0.2, 0.05, 0.5], [0.05, 1.0, 0.05, 0.5, 0.2, 0.05, 0.5]]) / FEATURE_SCALE
SCALES = [1e-20, 1e-16, 1e-8, 1e-3, 1e3, 1e8, 1e16, 1e20]


@pytest.fixture(scope="module")
def task(arm):
    return ReachingTask(arm, np.deg2rad([-80.0, 90.0]), 0.9 * arm.length, 0.7, n_nodes=30)


@pytest.mark.parametrize("backend", ["casadi", "crocoddyl"])
def test_scaled_weights_give_the_same_trajectory(task, backend):
    ref = solve_doc(task, W, backend=backend)
    assert ref.converged, ref.status
    for c in SCALES:
        sol = solve_doc(task, c * W, backend=backend)
        assert sol.converged, (c, sol.status)
        np.testing.assert_allclose(sol.q, ref.q, rtol=0, atol=1e-9, err_msg=f"c = {c:g}")
        assert sol.cost == pytest.approx(c * ref.cost, rel=1e-9), c


def test_uniform_tiny_weights_are_not_a_silent_wrong_answer(task):
    # uniform 1e-16 weights made CasADi stop "converged" 3-15° away from the optimum of uniform 1 weights
    ref = solve_doc(task, np.ones((1, 7)))
    for c in (1e-16, 1e-18, 1e-300):
        sol = solve_doc(task, np.full((1, 7), c))
        assert sol.converged
        assert np.abs(np.rad2deg(sol.q - ref.q)).max() < 1e-9


def test_huge_weights_on_crocoddyl_do_not_abort(task):
    # 1e300 aborted the process inside Crocoddyl (terminate called ... crocoddyl::Exception, exit 134)
    sol = solve_doc(task, np.full((2, 7), 1e300), backend="crocoddyl")
    ref = solve_doc(task, np.ones((2, 7)), backend="crocoddyl")
    assert sol.converged and np.array_equal(sol.q, ref.q)
    assert np.isfinite(sol.cost)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"duration": 1e-6}, r"duration 1e-06 s is outside the range of a reach"),
        ({"duration": 1e4}, r"duration 10000 s is outside the range of a reach"),
        ({"n_nodes": 3}, r"n_nodes must be an integer in \[4, 1000\], got 3"),
        ({"n_nodes": 10**8}, r"n_nodes must be an integer in \[4, 1000\], got 100000000"),
        ({"n_nodes": 1e308}, r"n_nodes must be an integer in \[4, 1000\], got 1e\+308"),
        ({"n_nodes": 40.5}, r"n_nodes must be an integer"),
    ],
)
def test_reaches_outside_physical_ranges_are_input_errors(arm, kwargs, match):
    args = {"q0": np.deg2rad([-80.0, 90.0]), "target_x": 0.9 * arm.length, "duration": 0.7, "n_nodes": 30}
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        ReachingTask(arm, **args)


def test_an_arm_of_250_km_is_an_input_error():
    # an ArmModel this long is refused where it is made (lengths in metres: ArmModel's own bound, 3 m) ...
    with pytest.raises(ValueError, match=r"ArmModel\.l1 must be in metres, got 250000: longer than any arm segment"):
        ArmModel(l1=250e3, l2=0.3, m1=2.0, m2=1.5, c1=0.1, c2=0.15, i1=0.01, i2=0.01)
    # ... and the task's own bound (2 m) stands for an arm of 2.5 m, which ArmModel lets through
    big = ArmModel(l1=2.5, l2=0.3, m1=2.0, m2=1.5, c1=0.1, c2=0.15, i1=0.01, i2=0.01)
    with pytest.raises(InputError, match=r"arm l1 = 2.5 is outside the physical range \[0.02, 2\]"):
        ReachingTask(big, np.deg2rad([-80.0, 90.0]), 0.3, 0.7)
