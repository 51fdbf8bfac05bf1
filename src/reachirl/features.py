"""The seven cost features Φ1..Φ7 of the seed paper (its Table I), with one numpy definition.

Every part of reachirl uses these functions: the DOC backends are tested against them, MO-IRL compares
demonstrations and rollouts with them, and trials from data go through them.

A trajectory is discretised on ``N`` intervals of length ``dt``: states at the knots ``k = 0..N`` (``q``, ``qd``
of shape ``(N+1, 2)``) and torques on the intervals ``k = 0..N-1`` (``tau`` of shape ``(N, 2)``). The running
feature rates ``φ_j(k)`` are evaluated on the intervals and summed per window times ``dt``:
``Φ_{s,j} = Σ_{k ∈ window s} φ_j(k) · dt``.

Choices the paper leaves open, fixed here:

* **Acceleration** on interval ``k`` is the Euler one, ``qdd_k = (qd_{k+1} - qd_k) / dt``. On a DOC solution it
  equals the forward dynamics ``M⁻¹(τ_k - b)`` exactly.
* **Energy** ``φ2 = |qd_kᵀ τ_k|`` is used as is (no smoothing). The CasADi backend makes it smooth with the
  exact slack form ``qd_kᵀ τ_k = s⁺ - s⁻``, ``s± ≥ 0``, which equals it at the optimum; the Crocoddyl backend,
  which has no slack variables, uses ``√(r² + ε²) − ε`` with ε = 1 mW (at most ε × duration off).
* **Torque change** is a finite difference across intervals, ``τ̇_k = (τ_k - τ_{k-1}) / dt``. Before the reach the
  arm is held at rest, so ``τ_{-1} = g(q_0)``, the gravity torque at the initial posture: the torque jump at onset
  is counted like any other.
* **Geodesic** is the kinetic-energy form of the paper's table, ``qdᵀ M(q) qd`` (no square root).
* **Windows**: interval ``k`` belongs to window ``floor(k · n_windows / N)``, so windows are equal up to one
  interval.
* **No scaling**: features are raw SI quantities; see :data:`FEATURE_UNITS`.
"""

from __future__ import annotations

import numpy as np

from .arm import ArmModel

__all__ = [
    "FEATURES",
    "FEATURE_LABELS",
    "FEATURE_UNITS",
    "cost_shares",
    "euler_knots",
    "feature_rates",
    "trajectory_cost",
    "window_index",
    "windowed_features",
]

FEATURES: tuple[str, ...] = (
    "cartesian_velocity",
    "energy",
    "geodesic",
    "joint_acceleration",
    "torque_change",
    "joint_velocity",
    "joint_torque",
)
FEATURE_LABELS: dict[str, str] = {
    "cartesian_velocity": "Cartesian velocity",
    "energy": "Energy",
    "geodesic": "Geodesic",
    "joint_acceleration": "Joint acceleration",
    "torque_change": "Torque change",
    "joint_velocity": "Joint velocity",
    "joint_torque": "Joint torque",
}
# Units of each Φ_j (a rate integrated over time).
FEATURE_UNITS: dict[str, str] = {
    "cartesian_velocity": "m²/s",
    "energy": "J",
    "geodesic": "kg·m²/s",
    "joint_acceleration": "rad²/s³",
    "torque_change": "N²m²/s",
    "joint_velocity": "rad²/s",
    "joint_torque": "N²m²·s",
}
N_FEATURES = len(FEATURES)


def _check(q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float) -> tuple[np.ndarray, ...]:
    q, qd, tau = (np.asarray(a, dtype=float) for a in (q, qd, tau))
    if q.ndim != 2 or q.shape[1] != 2 or q.shape[0] < 3:
        raise ValueError(f"q must have shape (N+1, 2) with N >= 2, got {q.shape}")
    n = q.shape[0] - 1
    if qd.shape != q.shape:
        raise ValueError(f"qd must have shape {q.shape}, got {qd.shape}")
    if tau.shape != (n, 2):
        raise ValueError(f"tau must have shape ({n}, 2), got {tau.shape}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be a positive number, got {dt}")
    for name, a in (("q", q), ("qd", qd), ("tau", tau)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} contains NaN or infinite values")
    return q, qd, tau


def euler_knots(
    arm: ArmModel, q: np.ndarray, dt: float, qd0: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q, q̇, τ)`` of a knot path ``q (N+1, 2)`` read as the DOC reads its own: semi-implicit Euler velocities
    ``q̇_k = (q_k − q_{k−1})/dt`` (``q̇_0 = qd0``, at rest when ``None``), accelerations
    ``q̈_k = (q̇_{k+1} − q̇_k)/dt`` and inverse-dynamics torques ``τ_k = M(q_k) q̈_k + b(q_k, q̇_k)`` on the ``N``
    intervals. Both backends, the demonstrations (:meth:`reachirl.data.trial.Trial.knots`) and the observed
    rollouts (:func:`reachirl.doc.observation.observed_knots`) go through it."""
    qd = np.vstack([np.zeros(2) if qd0 is None else qd0, np.diff(q, axis=0) / dt])
    tau = arm.inverse_dynamics(q[:-1], qd[:-1], np.diff(qd, axis=0) / dt)
    return q, qd, tau


def feature_rates(arm: ArmModel, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
    """Running feature rates ``φ_j(k)`` on each interval, shape ``(N, 7)`` in :data:`FEATURES` order."""
    q, qd, tau = _check(q, qd, tau, dt)
    qk, qdk = q[:-1], qd[:-1]
    qdd = np.diff(qd, axis=0) / dt
    tau_dot = np.diff(np.vstack([arm.gravity_torque(q[0]), tau]), axis=0) / dt  # τ_{-1} = g(q_0): at rest
    pdot = arm.fingertip_velocity(qk, qdk)
    M = arm.mass_matrix(qk)
    return np.column_stack(
        [
            np.sum(pdot**2, axis=1),  # Φ1 Cartesian velocity ‖Ṗ‖²
            np.abs(np.sum(qdk * tau, axis=1)),  # Φ2 energy |q̇ᵀτ|
            np.einsum("ki,kij,kj->k", qdk, M, qdk),  # Φ3 geodesic q̇ᵀM q̇
            np.sum(qdd**2, axis=1),  # Φ4 joint acceleration ‖q̈‖²
            np.sum(tau_dot**2, axis=1),  # Φ5 torque change ‖τ̇‖²
            np.sum(qdk**2, axis=1),  # Φ6 joint velocity ‖q̇‖²
            np.sum(tau**2, axis=1),  # Φ7 joint torque ‖τ‖²
        ]
    )


def window_index(n_intervals: int, n_windows: int) -> np.ndarray:
    """Window of each interval ``k = 0..N-1``: ``floor(k · n_windows / N)``."""
    if n_windows < 1 or n_windows > n_intervals:
        raise ValueError(f"n_windows must be in 1..{n_intervals} for {n_intervals} intervals, got {n_windows}")
    return (np.arange(n_intervals) * n_windows) // n_intervals


def cost_shares(weights: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Each feature's share of its window's cost, ``ω_sj Φ_sj / Σ_j ω_sj Φ_sj``: weights ``(..., S, 7)`` (a
    stack of weight matrices broadcasts) on features ``(S, 7)``; rows sum to 1, or are 0 where a window has no
    cost."""
    c = np.asarray(weights, dtype=float) * np.asarray(phi, dtype=float)
    tot = c.sum(axis=-1, keepdims=True)
    return np.divide(c, tot, out=np.zeros_like(c), where=tot > 0)


def windowed_features(
    arm: ArmModel, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float, n_windows: int
) -> np.ndarray:
    """Φ of a trajectory per window, shape ``(n_windows, 7)``: ``Φ_{s,j} = Σ_{k∈s} φ_j(k) dt``."""
    rates = feature_rates(arm, q, qd, tau, dt)
    idx = window_index(rates.shape[0], n_windows)
    out = np.zeros((n_windows, N_FEATURES))
    np.add.at(out, idx, rates * dt)
    return out


def trajectory_cost(
    arm: ArmModel, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float, weights: np.ndarray
) -> float:
    """The DOC objective ``Σ_s Σ_j ω_{s,j} Φ_{s,j}`` of a trajectory."""
    weights = np.asarray(weights, dtype=float)
    if weights.ndim != 2 or weights.shape[1] != N_FEATURES:
        raise ValueError(f"weights must have shape (n_windows, {N_FEATURES}), got {weights.shape}")
    if not np.all(np.isfinite(weights)):
        raise ValueError("weights must be finite")
    return float(np.sum(weights * windowed_features(arm, q, qd, tau, dt, weights.shape[0])))
