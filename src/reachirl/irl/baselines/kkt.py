"""Residual inverse optimal control (KKT residuals; Englert et al. 2017, Colombel et al. 2022).

If a demonstration ``z*`` solves the DOC of :mod:`reachirl.doc.casadi` (decision variables: the joint
positions at the inner knots, ``z = (q_1, …, q_{N−1})``), the stationarity of the DOC's Lagrangian holds
there::

    Σ_{s,j} ω_{s,j} ∇_z Φ_{s,j}(z*) + λ ∇_z g(z*) + Σ_{k ∈ Z} μ_k ∇_z e_k(z*) = 0

with ``g = P_x(q_N) − target`` the terminal fingertip constraint (``q̇_0 = q̇_N = 0`` and ``q_0`` are built into
the parametrisation) and ``e_k = q̇_kᵀτ_k`` the power on interval ``k``. The energy feature ``|e_k|`` has the
gradient ``sign(e_k) ∇e_k``; on the knots ``Z`` where the power is (numerically) zero its subgradient is any
``μ_k ∇e_k`` with ``|μ_k| ≤ ω_energy dt`` (in the DOC's slack form, the multiplier of ``e_k = s⁺ − s⁻``), so
those knots get a free multiplier. Joint limits and the speed bound are assumed inactive (they are, on
reaches).

The fit is one linear least-squares problem: the free multipliers (``λ`` and ``μ`` per demonstration) are
eliminated by projecting each demonstration's residual onto the orthogonal complement of their columns, which
leaves ``min ‖A ω̃‖²`` over ``ω̃ ≥ 0`` with the normalisation ``Σ ω̃ = 1``, solved as a non-negative least
squares (:func:`scipy.optimize.nnls`) with the normalisation as a heavily weighted extra row. ``ω̃ = ω ⊙ c``
puts the features on a common footing; ``normalisation`` picks ``c``:

* ``"gradient"`` (default): ``c_{s,j} = ‖∇_z Φ_{s,j}‖`` over the demonstrations, so every column of
  ``A`` has unit norm before projection;
* ``"cost"``: ``c = Φ̄``, the demonstrations' mean features, so ``ω̃`` is each cost's share of the mean cost.

On exact DOC solutions both find weights that satisfy the optimality conditions (residual ~1e-5); those are
the true weights only along the directions the demonstrations determine: features that shape a reach alike
(Cartesian velocity, geodesic, joint velocity) can trade weight at no cost in the residual. On demonstrations
that no single ``ω`` explains (trial-to-trial weight jitter, noise) both drift towards the features whose
gradients are smallest relative to the normalisation (measured in ``benchmarks/bench_irl.py``: "gradient" was
somewhat better on both). The DOC is invariant to the scale of ``ω``, so no rescaling is needed:
``weights_ = ω̃ / c``.

No DOC is solved in the fit (``n_doc_solves_ = 0``). The method needs the demonstrations' accelerations and
torque changes, i.e. second and third differences of the joint angles, so angle noise is amplified by
``1/dt²`` and ``1/dt³``: nearly exact on noise-free DOC solutions, it degrades fast with noise
(Colombel et al. 2022; Bečanović et al. 2024).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence

import casadi as ca
import numpy as np
from scipy.linalg import qr

from ...data.trial import Trial
from ...doc.symbolic import ARM_FIELDS, fingertip, fingertip_jacobian, inverse_dynamics, mass_matrix
from ...features import N_FEATURES, window_index
from ..base import WeightEstimator

__all__ = ["KKTIOC", "kkt_matrices", "kkt_residual"]


@functools.lru_cache(maxsize=8)
def _kkt_function(n: int, n_windows: int) -> ca.Function:
    """``(z, p) → (∂Φ/∂z (7S × nz), ∂g/∂z (nz), ∂e/∂z ((N−1) × nz), e (N−1), Φ (7S))`` for the DOC of shape
    ``(n, n_windows)``; ``p = (arm, q0, target, dt)``. The same equations as :mod:`reachirl.doc.casadi`."""
    arm = ca.SX.sym("arm", len(ARM_FIELDS))
    q0 = ca.SX.sym("q0", 2)
    target = ca.SX.sym("target")
    dt = ca.SX.sym("dt")
    z = ca.SX.sym("z", 2 * (n - 1))
    arm_l = [arm[i] for i in range(len(ARM_FIELDS))]
    qs = [q0] + [z[2 * (k - 1) : 2 * k] for k in range(1, n)]
    qs.append(qs[-1])  # q_N = q_{N−1}  ⇔  q̇_N = 0
    qd = [ca.SX.zeros(2)] + [(qs[k] - qs[k - 1]) / dt for k in range(1, n + 1)]
    win = window_index(n, n_windows)
    phi = [[0] * N_FEATURES for _ in range(n_windows)]
    power = []
    tau_prev = inverse_dynamics(arm_l, q0, ca.SX.zeros(2), ca.SX.zeros(2))  # at rest before: τ_{−1} = g(q0)
    for k in range(n):
        qdd = (qd[k + 1] - qd[k]) / dt
        tau = inverse_dynamics(arm_l, qs[k], qd[k], qdd)
        jac = fingertip_jacobian(arm_l, qs[k])
        e = ca.dot(qd[k], tau)
        if k > 0:
            power.append(e)
        rates = [
            ca.sumsqr(jac @ qd[k]),
            ca.fabs(e) if k > 0 else 0,  # d|e|/dz = sign(e) de/dz (CasADi: sign(0) = 0)
            ca.bilin(mass_matrix(arm_l, qs[k]), qd[k], qd[k]),
            ca.sumsqr(qdd),
            ca.sumsqr((tau - tau_prev) / dt),
            ca.sumsqr(qd[k]),
            ca.sumsqr(tau),
        ]
        for j in range(N_FEATURES):
            phi[win[k]][j] = phi[win[k]][j] + dt * rates[j]
        tau_prev = tau
    phi_v = ca.vertcat(*[phi[s][j] for s in range(n_windows) for j in range(N_FEATURES)])
    g = fingertip(arm_l, qs[n])[0] - target
    e_v = ca.vertcat(*power)
    p = ca.vertcat(arm, q0, target, dt)
    return ca.Function("kkt", [z, p], [ca.jacobian(phi_v, z), ca.gradient(g, z), ca.jacobian(e_v, z), e_v, phi_v])


def kkt_matrices(trial: Trial, n_nodes: int, n_windows: int, zero_power_tol: float = 1e-3) -> dict:
    """The stationarity terms of one demonstration resampled to the DOC's ``n_nodes`` knots.

    Returns ``G (nz, 7S)`` (feature gradients, columns row-major (window, feature)), ``free (nz, m)`` (the
    columns of the free multipliers: the terminal constraint and the zero-power knots), ``phi (7S,)``.
    A knot's power counts as zero when ``|e_k| ≤ zero_power_tol · max_k |e_k|``.
    """
    r = trial.resample(n_nodes + 1)
    z = r.q[1:n_nodes].reshape(-1)
    a = trial.arm
    p = np.concatenate(
        [[getattr(a, f) for f in ARM_FIELDS], trial.x0[:2], [trial.target_x], [trial.duration / n_nodes]]
    )
    jphi, dg, je, e, phi = (np.asarray(v) for v in _kkt_function(n_nodes, n_windows)(z, p))
    e = e.reshape(-1)
    zero = np.abs(e) <= zero_power_tol * max(float(np.max(np.abs(e))), 1e-300)
    free = np.column_stack([dg.reshape(-1), je[zero].T]) if np.any(zero) else dg.reshape(-1, 1)
    return {"G": jphi.T, "free": free, "phi": phi.reshape(-1), "n_zero_power": int(np.sum(zero))}


def _project_out(G: np.ndarray, free: np.ndarray) -> np.ndarray:
    """``(I − Q Qᵀ) G`` with ``Q`` an orthonormal basis of ``free``'s columns: the residual after the best
    free multipliers."""
    Q, R, _ = qr(free, mode="economic", pivoting=True)
    rank = int(np.sum(np.abs(np.diag(R)) > 1e-12 * max(abs(R[0, 0]), 1e-300)))
    Q = Q[:, :rank]
    return G - Q @ (Q.T @ G)


def kkt_residual(weights: np.ndarray, trials: Sequence[Trial], n_nodes: int, zero_power_tol: float = 1e-3) -> float:
    """Relative stationarity residual ``‖P Σ ω ∇Φ‖ / ‖Σ ω ∇Φ‖`` over the demonstrations (0 at an exact
    optimum)."""
    w = np.asarray(weights, dtype=float).reshape(-1)
    num = den = 0.0
    for t in trials:
        m = kkt_matrices(t, n_nodes, np.shape(weights)[0], zero_power_tol)
        num += float(np.sum((_project_out(m["G"], m["free"]) @ w) ** 2))
        den += float(np.sum((m["G"] @ w) ** 2))
    return float(np.sqrt(num / max(den, 1e-300)))


class KKTIOC(WeightEstimator):
    """Residual (KKT) inverse optimal control with ``n_windows`` time windows of weights; one NNLS, no DOC.

    ``zero_power_tol``: knots whose power is below this fraction of the peak get a free energy multiplier.
    The energy's absolute value makes the DOC hold the power at exactly zero over whole stretches (an L1
    effect: about half the knots on the test problem); a solver leaves it at ~1e-6 of the peak there, with an
    arbitrary sign, so 1e-6 was too tight (measured: residual at the truth 0.036 instead of 1e-7); the
    default is 1e-3. The bound ``|μ_k| ≤ ω_energy dt`` is dropped, so a window whose power is held at zero
    throughout says nothing about its energy weight (it is then set by the other demonstrations, or not at
    all with ``pooling="per_demo"``).
    ``norm_weight``: weight of the normalisation row ``Σ ω̃ = 1`` relative to the residual matrix's norm.
    ``normalisation``: ``"gradient"`` or ``"cost"``, the feature scaling ``c`` of ``ω̃ = ω ⊙ c`` (module
    docstring).
    ``pooling``: ``"joint"`` (one NNLS on every demonstration's rows: one ω explains them all) or
    ``"per_demo"`` (one NNLS per demonstration, then the mean of the normalised ``ω̃``: for demonstrations
    that are each optimal under their own weights, e.g. trial-to-trial variability).

    Fitted attributes: ``weights_ (n_windows, 7)``, ``relative_weights_`` (``ω̃``, summing to 1),
    ``residual_`` (relative stationarity residual), ``history_`` (one record), ``n_doc_solves_ = 0``,
    ``n_iter_ = 1``, ``fit_time_``, ``warnings_`` (none: the fit is one NNLS).
    """

    def __init__(
        self,
        n_windows: int = 8,
        *,
        n_nodes: int = 100,
        zero_power_tol: float = 1e-3,
        norm_weight: float = 1e3,
        normalisation: str = "gradient",
        pooling: str = "joint",
        backend: str = "casadi",
    ):
        self.n_windows = n_windows
        self.n_nodes = n_nodes
        self.zero_power_tol = zero_power_tol
        self.norm_weight = norm_weight
        self.normalisation = normalisation
        self.pooling = pooling
        self.backend = backend

    def _solve(self, A: np.ndarray, w_rel: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """``min ‖A ω̃‖`` over ``ω̃ ≥ 0``, ``Σ ω̃ = 1`` (or just the residual of ``w_rel``): ``(ω̃, residual)``
        with the residual relative to the RMS column norm of ``A``."""
        n = A.shape[1]
        R = qr(A, mode="r")[0][:n]  # ‖Aω̃‖ = ‖Rω̃‖: a square system for the NNLS
        if w_rel is None:
            from scipy.optimize import nnls  # here: the command's own process never needs scipy.optimize

            rho = self.norm_weight * max(float(np.linalg.norm(R)), 1e-300)
            w_rel, _ = nnls(np.vstack([R, rho * np.ones((1, n))]), np.r_[np.zeros(R.shape[0]), rho], maxiter=50 * n)
            w_rel = w_rel / max(w_rel.sum(), 1e-300)
        return w_rel, float(np.linalg.norm(R @ w_rel) / max(np.linalg.norm(R) / np.sqrt(n), 1e-300))

    def fit(self, trials: Sequence[Trial], y=None) -> KKTIOC:
        """Learn ``weights_`` from the demonstrations ``trials``; returns the estimator. ``y`` is ignored
        (scikit-learn's signature: the demonstrations are their own targets)."""
        trials = self._check_trials(trials)
        if self.normalisation not in ("cost", "gradient"):
            raise ValueError(f"normalisation must be 'cost' or 'gradient', got {self.normalisation!r}")
        if self.pooling not in ("joint", "per_demo"):
            raise ValueError(f"pooling must be 'joint' or 'per_demo', got {self.pooling!r}")
        for name, positive in (("norm_weight", True), ("zero_power_tol", False)):
            v = getattr(self, name)
            ok = isinstance(v, int | float | np.number) and not isinstance(v, bool) and bool(np.isfinite(v))
            if not (ok and (v > 0 if positive else v >= 0)):
                raise ValueError(f"{name} must be a finite number {'> 0' if positive else '>= 0'}, got {v!r}")
        t0 = time.perf_counter()
        mats = [kkt_matrices(t, self.n_nodes, self.n_windows, self.zero_power_tol) for t in trials]
        if self.normalisation == "cost":
            scale = np.mean([m["phi"] for m in mats], axis=0)
        else:
            scale = np.sqrt(np.sum([np.sum(m["G"] ** 2, axis=0) for m in mats], axis=0))
        scale = np.maximum(np.abs(scale), 1e-9 * np.max(np.abs(scale)))
        # rows of each demonstration, free multipliers projected out, columns in ω̃ = ω ⊙ scale
        blocks = [_project_out(m["G"], m["free"]) / scale for m in mats]
        if self.pooling == "joint":
            w_rel, res = self._solve(np.vstack(blocks))
            per_demo = []
        else:
            sols = [self._solve(b) for b in blocks]
            per_demo = [float(r) for _, r in sols]
            w_rel = np.mean([w for w, _ in sols], axis=0)
            res = self._solve(np.vstack(blocks), w_rel)[1]
        self.relative_weights_ = w_rel.reshape(self.n_windows, N_FEATURES)
        self.weights_ = (w_rel / scale).reshape(self.n_windows, N_FEATURES)
        self.residual_ = res
        self.n_doc_solves_ = 0
        self.n_doc_failures_ = 0
        self.n_iter_ = 1
        self.warnings_ = []
        self.fit_time_ = time.perf_counter() - t0
        self.history_ = [
            {
                "iteration": 1,
                "residual": self.residual_,
                "weights": self.weights_.tolist(),
                "zero_power_knots": [m["n_zero_power"] for m in mats],
                "per_demo_residuals": per_demo,
                "doc_solves": 0,
                "wall_time": self.fit_time_,
            }
        ]
        self._keep_fit_params()
        return self
