import numpy as np
import pytest

from reachirl import FEATURES, ArmModel
from reachirl.features import feature_rates, trajectory_cost, window_index, windowed_features

ARM = ArmModel(l1=0.3, l2=0.4, m1=2.0, m2=1.5, c1=0.15, c2=0.2, i1=0.01, i2=0.02, gravity=0.0)


def test_feature_order_is_the_papers():
    assert FEATURES == (
        "cartesian_velocity",
        "energy",
        "geodesic",
        "joint_acceleration",
        "torque_change",
        "joint_velocity",
        "joint_torque",
    )


def test_hand_computed_constant_velocity_case():
    # q2 fixed at 0 (straight arm), shoulder turning at 2 rad/s, constant torque (1, -1); dt = 0.5, N = 2
    dt = 0.5
    q = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    qd = np.array([[2.0, 0.0], [2.0, 0.0], [2.0, 0.0]])
    tau = np.array([[1.0, -1.0], [1.0, -1.0]])
    r = feature_rates(ARM, q, qd, tau, dt)
    # fingertip speed = (l1 + l2) * 2 = 1.4 m/s
    np.testing.assert_allclose(r[:, 0], [1.96, 1.96])
    np.testing.assert_allclose(r[:, 1], [2.0, 2.0])  # |2*1 + 0*(-1)|
    # q̇ᵀM q̇ with q2 = 0: M11 = i1 + i2 + m1 c1² + m2 (l1² + c2² + 2 l1 c2) = 0.03 + 0.045 + 1.5*0.25 = 0.45
    np.testing.assert_allclose(r[:, 2], [4 * 0.45, 4 * 0.45])
    np.testing.assert_allclose(r[:, 3], [0.0, 0.0])  # constant velocity
    # constant torque after the onset jump from τ_{−1} = g(q0) = 0 (no gravity): ‖(1, −1)/0.5‖² = 8
    np.testing.assert_allclose(r[:, 4], [8.0, 0.0])
    np.testing.assert_allclose(r[:, 5], [4.0, 4.0])
    np.testing.assert_allclose(r[:, 6], [2.0, 2.0])
    Phi = windowed_features(ARM, q, qd, tau, dt, 1)
    np.testing.assert_allclose(Phi[0], r.sum(axis=0) * dt)


def test_hand_computed_acceleration_and_torque_change():
    dt = 0.1
    qd = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0], [0.0, 0.0]])
    q = np.cumsum(qd * dt, axis=0)
    tau = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 4.0]])
    r = feature_rates(ARM, q, qd, tau, dt)
    np.testing.assert_allclose(r[:, 3], [100.0, 400.0, 500.0])  # ‖Δq̇/dt‖²
    np.testing.assert_allclose(r[:, 4], [0.0, 2500.0, 0.0])  # τ_0 = τ_{−1} = g(q0) = 0: no jump at onset
    np.testing.assert_allclose(r[:, 1], [0.0, 3.0, 11.0])  # |q̇ᵀτ| with the knot's own q̇
    np.testing.assert_allclose(r[:, 6], [0.0, 25.0, 25.0])


def test_torque_change_at_onset_is_measured_from_the_gravity_torque_at_rest():
    # with gravity, the arm is held at rest before the reach: τ_{−1} = g(q0). At q0 = 0 (arm horizontal)
    # g = 9.81 · (m1 c1 + m2 l1 + m2 c2, m2 c2) = 9.81 · (0.3 + 0.45 + 0.3, 0.3) = (10.3005, 2.943) N·m
    arm = ArmModel(l1=0.3, l2=0.4, m1=2.0, m2=1.5, c1=0.15, c2=0.2, i1=0.01, i2=0.02, gravity=9.81)
    dt = 0.1
    q = np.zeros((3, 2))
    qd = np.zeros((3, 2))
    held = np.array([[10.3005, 2.943], [10.3005, 2.943]])
    np.testing.assert_allclose(feature_rates(arm, q, qd, held, dt)[:, 4], [0.0, 0.0], atol=1e-18)
    jump = held + np.array([[1.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(feature_rates(arm, q, qd, jump, dt)[:, 4], [100.0, 0.0])  # ‖(1, 0)/0.1‖²


def test_energy_is_absolute_value():
    dt = 0.1
    q = np.zeros((3, 2))
    qd = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    tau = np.array([[-2.0, 0.0], [2.0, 0.0]])
    np.testing.assert_allclose(feature_rates(ARM, q, qd, tau, dt)[:, 1], [2.0, 2.0])


def test_windows_partition_intervals():
    idx = window_index(100, 8)
    assert idx[0] == 0 and idx[-1] == 7
    counts = np.bincount(idx)
    assert counts.sum() == 100 and set(counts) <= {12, 13}
    assert np.all(np.diff(idx) >= 0)
    np.testing.assert_array_equal(window_index(6, 6), np.arange(6))


def test_windowed_features_sum_to_single_window(rng):
    n, dt = 50, 0.014
    q, qd, tau = rng.normal(size=(n + 1, 2)), rng.normal(size=(n + 1, 2)), rng.normal(size=(n, 2))
    one = windowed_features(ARM, q, qd, tau, dt, 1)
    eight = windowed_features(ARM, q, qd, tau, dt, 8)
    assert eight.shape == (8, 7)
    np.testing.assert_allclose(eight.sum(axis=0), one[0], rtol=1e-12)
    w = rng.uniform(size=(8, 7))
    assert trajectory_cost(ARM, q, qd, tau, dt, w) == pytest.approx(float(np.sum(w * eight)))


def test_feature_errors():
    q = np.zeros((5, 2))
    with pytest.raises(ValueError, match=r"tau must have shape \(4, 2\)"):
        feature_rates(ARM, q, q, np.zeros((5, 2)), 0.1)
    with pytest.raises(ValueError, match="dt must be a positive"):
        feature_rates(ARM, q, q, np.zeros((4, 2)), 0.0)
    with pytest.raises(ValueError, match="NaN"):
        feature_rates(ARM, q, np.full((5, 2), np.nan), np.zeros((4, 2)), 0.1)
    with pytest.raises(ValueError, match=r"n_windows must be in 1\.\.4"):
        windowed_features(ARM, q, q, np.zeros((4, 2)), 0.1, 5)
    with pytest.raises(ValueError, match=r"weights must have shape \(n_windows, 7\)"):
        trajectory_cost(ARM, q, q, np.zeros((4, 2)), 0.1, np.ones(7))
