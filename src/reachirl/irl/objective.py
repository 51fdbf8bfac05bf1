"""The MO-IRL equations as pure functions (seed paper, Eqs. 2-4; Mehrdad et al. 2025).

Notation: ``ω``, ``Δω`` are weight matrices ``(n_windows, 7)``; ``Φ*_d`` the features of demonstration ``d`` and
``Φ_i`` those of a generated trajectory ``x_i ∈ x̄``, all ``(n_windows, 7)``.

* Cost mismatch (seed Eq. 4): ``C(x_i, Δω) = Σ_s Δω_sᵀ (Φ_{s,i} − Φ*_{s,d})``.
* Scaling: ``γ_i = exp(−C(x_i, ω))``.
* Subproblem: ``Δω* = argmin_{Δω ≥ −ω} Σ_d −log(1 / (1 + Σ_i γ_i exp(−C(x_i, Δω)))) + β/2 ‖Δω‖²``.

Since ``γ_i exp(−C(x_i, Δω)) = exp(−C(x_i, ω + Δω))``, each demonstration's term is
``log(1 + Σ_i exp(−C(x_i, ω + Δω)))``, evaluated with a log-sum-exp that never overflows. Turning γ off
(``gamma=False``) sets ``γ_i = 1``.

**Scale-free steps** (:func:`solve_step`, MO-IRL's default). The subproblem only sees the products
``ω_{s,j} Φ_{s,j}``, but its raw form (:func:`solve_delta`) is solved in SI coordinates: ``β``, the bound
``Δω > −ω`` and L-BFGS-B's path then depend on the features' units, and one step can move a weight by three
orders of magnitude. :func:`solve_step` instead

* works in normalised coordinates: features divided by a per-(window, feature) scale ``σ_{s,j}`` taken from the
  demonstrations (:func:`feature_scale`), weights multiplied by it (``θ = ω ⊙ σ``), so ``C`` is unchanged;
* takes a multiplicative step ``ω + Δω = ω ⊙ exp(η)`` with ``|η| ≤ log(max_ratio)`` (a trust region: one step
  moves a weight by at most ``max_ratio``), so ``Δω > −ω`` holds strictly by construction;
* regularises ``β/2 ‖η‖²`` (unit-free) and, optionally, the roughness of the weights across adjacent windows,
  ``λ/2 Σ_{s,j} (log ω'_{s+1,j} − log ω'_{s,j})²`` (``λ → ∞`` ties the windows into one).

Changing a feature's unit rescales its weight and leaves every step, in ω-space, the same.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "Group",
    "channel_scale",
    "cost_mismatch",
    "feature_scale",
    "gamma",
    "gauss_newton_step",
    "merit",
    "merit_model_step",
    "minimize_in_box",
    "solve_delta",
    "solve_step",
    "step_objective",
    "subproblem_objective",
]


def cost_mismatch(delta_w: np.ndarray, phi_i: np.ndarray, phi_star: np.ndarray) -> np.ndarray:
    """``C(x_i, Δω) = Σ_s Δω_sᵀ (Φ_{s,i} − Φ*_{s,d})`` for every pair: ``phi_i (I, S, 7)``, ``phi_star (D, S, 7)``
    → ``(D, I)``."""
    return _mismatch(delta_w, phi_i, phi_star)[1]


def _mismatch(delta_w: np.ndarray, phi_i: np.ndarray, phi_star: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The differences ``Φ_i − Φ*_d`` of every pair, flattened to ``(D·I, S·7)``, and ``C(x_i, Δω)``, ``(D, I)``:
    one matrix-vector product (on these tiny arrays ``einsum`` costs several times the arithmetic)."""
    n_d, n_i = phi_star.shape[0], phi_i.shape[0]
    diff = (phi_i[None, :, :, :] - phi_star[:, None, :, :]).reshape(n_d * n_i, -1)
    return diff, (diff @ delta_w.reshape(-1)).reshape(n_d, n_i)


def gamma(w: np.ndarray, phi_i: np.ndarray, phi_star: np.ndarray) -> np.ndarray:
    """``γ_i = exp(−C(x_i, ω))`` per (demonstration, trajectory), shape ``(D, I)``."""
    return np.exp(-cost_mismatch(w, phi_i, phi_star))


Group = tuple[np.ndarray, np.ndarray, np.ndarray]
"""``(phi_i (I, S, 7), phi_star (D, S, 7), c (D,))``: demonstrations compared with one set of trajectories ``x̄``."""


def _log_partition(shift: np.ndarray, group: Group) -> tuple[float, np.ndarray]:
    """``Σ_d c_d log(1 + Σ_i exp(−C(x_i, shift)))`` and its gradient in ``shift`` (a stable log-sum-exp).

    Written with plain array products: the solver of the subproblem calls it ~20 times per MO-IRL iteration on
    tiny arrays, where scipy's ``logsumexp``/``softmax`` cost several times the arithmetic."""
    phi_i, phi_star, cd = group
    diff, c = _mismatch(shift, phi_i, phi_star)
    neg = -c  # the logits −C(x_i, shift), (D, I)
    top = np.maximum(neg.max(axis=1), 0.0)  # the largest of the logits [0, −C(x_i, shift)]
    e = np.exp(neg - top[:, None])
    z = np.exp(-top) + e.sum(axis=1)  # Σ exp(logit − top), the leading 1 included
    value = float(cd @ (top + np.log(z)))
    weights = (cd / z)[:, None] * e  # c_d · p_di, the softmax's probabilities of the trajectories
    return value, -(weights.reshape(-1) @ diff).reshape(shift.shape)


def subproblem_objective(
    delta_w: np.ndarray,
    w: np.ndarray,
    groups: list[Group],
    beta: float = 1e-10,
    use_gamma: bool = True,
    l1: float = 0.0,
    l1_smoothing: float = 1e-9,
) -> tuple[float, np.ndarray]:
    """The Δω subproblem's objective and gradient (seed Eq. 4).

    ``f(Δω) = Σ_d c_d · −log(1 / (1 + Σ_i γ_i exp(−C(x_i, Δω)))) + β/2 ‖Δω‖² + λ Σ √(Δω² + ε²)``

    The demonstrations come in ``groups``, each compared with its own trajectory set (one group when every
    demonstration is compared with the same rollout). ``c_d`` weights each term (1 in the seed; the suffix
    sub-sampling of the original MO-IRL adds truncated copies weighted ``(T − d + 1)/(T + 1)``). ``l1`` is the
    original MO-IRL's elastic-net λ, smoothed by ``ε`` so the bounded quasi-Newton solver applies (0 in the seed).
    ``use_gamma=False`` sets ``γ_i = 1``: the classic MaxEnt form.
    """
    shift = w + delta_w if use_gamma else delta_w  # γ_i e^{−C(x_i, Δω)} = e^{−C(x_i, ω + Δω)}
    value = 0.5 * beta * float(np.sum(delta_w**2))
    grad = beta * delta_w
    for group in groups:
        v, g = _log_partition(shift, group)
        value, grad = value + v, grad + g
    if l1 > 0:
        root = np.sqrt(delta_w**2 + l1_smoothing**2)
        value += l1 * float(np.sum(root))
        grad = grad + l1 * delta_w / root
    return value, grad


def solve_delta(
    w: np.ndarray,
    groups: list[Group],
    beta: float = 1e-10,
    use_gamma: bool = True,
    l1: float = 0.0,
    max_iter: int = 500,
    min_ratio: float = 1e-3,
) -> tuple[np.ndarray, dict]:
    """``Δω* = argmin_{Δω > −ω} f(Δω)`` with L-BFGS-B (scipy), from ``Δω = 0``. Returns ``Δω`` and solver info.

    The strict bound is ``Δω ≥ −(1 − min_ratio) ω``: a step can shrink a weight by at most ``1/min_ratio`` but
    never to zero. (At ``ω = 0`` the DOC has no cost left, returns its initial guess, and a fit can lock there.)

    This is the seed's raw form (``MOIRL(scaling=None)``): it runs on the SI weights, so β, the bound and
    L-BFGS-B's path depend on the features' units; :func:`solve_step` is the scale-free form MO-IRL uses by
    default.
    """
    lower = -(1.0 - min_ratio) * w
    x, info = minimize_in_box(lambda d: subproblem_objective(d, w, groups, beta, use_gamma, l1), lower, None, max_iter)
    return np.maximum(x, lower), info  # exact feasibility: ω + Δω > 0


def minimize_in_box(fun, lower: np.ndarray, upper: np.ndarray | None, max_iter: int) -> tuple[np.ndarray, dict]:
    """Minimise ``fun(x) -> (value, gradient)`` over a matrix ``x`` of ``lower``'s shape within the bounds, from
    ``x = 0``, with scipy's L-BFGS-B. Returns ``x`` and the solver's report."""
    from scipy.optimize import Bounds, minimize  # here: the command's own process never needs scipy.optimize

    shape = lower.shape

    def flat(x: np.ndarray) -> tuple[float, np.ndarray]:
        f, g = fun(x.reshape(shape))
        return f, g.reshape(-1)

    res = minimize(
        flat,
        np.zeros(lower.size),
        jac=True,
        method="L-BFGS-B",
        bounds=Bounds(lower.reshape(-1), np.inf if upper is None else upper.reshape(-1)),
        options={"maxiter": max_iter, "ftol": 1e-15, "gtol": 1e-12},
    )
    info = {"fun": float(res.fun), "nit": int(res.nit), "success": bool(res.success), "message": str(res.message)}
    return res.x.reshape(shape), info


def merit(x_demos: np.ndarray, x: np.ndarray, channel_weights: np.ndarray | None = None) -> float:
    """``m(x) = (1/D) Σ_d (1/N) ‖x*_d − x‖²`` over the full state ``(q1, q2, q̇1, q̇2)`` on common knots.

    ``x_demos`` is ``(D, N+1, 4)`` and ``x`` either ``(N+1, 4)`` (one rollout compared with every demonstration)
    or ``(D, N+1, 4)`` (one rollout per demonstration). ``channel_weights (4,)`` weighs each channel's squared
    error (the seed: all 1, so rad/s errors outweigh rad ones; :func:`channel_scale` makes them unit-free).
    """
    x_demos = np.asarray(x_demos, dtype=float)
    x = np.asarray(x, dtype=float)
    n = x_demos.shape[1]
    sq = (x_demos - x) ** 2
    if channel_weights is not None:
        sq = sq * np.asarray(channel_weights, dtype=float)
    return float(np.mean(np.sum(sq, axis=(1, 2)) / n))


def channel_scale(x_demos: np.ndarray) -> np.ndarray:
    """Weights ``1/σ_c²`` of the normalised merit: ``σ_c²`` is the demonstrations' variance of channel ``c``
    (pooled over demonstrations and knots), so each of ``q1, q2, q̇1, q̇2`` counts by its error relative to
    its own range. Shape ``(4,)``."""
    var = np.var(np.asarray(x_demos, dtype=float).reshape(-1, 4), axis=0)
    return 1.0 / np.maximum(var, 1e-12 * max(float(var.max()), 1e-300))


def feature_scale(phi_star: np.ndarray, floor: float = 1e-3) -> np.ndarray:
    """The per-(window, feature) scale ``σ_{s,j}`` of the normalised coordinates: the demonstrations' mean
    ``Φ*_{s,j}``, floored at ``floor`` times that feature's largest window (a feature nearly absent from a
    window would otherwise be blown up). ``phi_star (D, S, 7)`` → ``(S, 7)``, every entry > 0."""
    phi = np.abs(np.asarray(phi_star, dtype=float))
    sigma = phi.reshape(-1, *phi.shape[-2:]).mean(axis=0)
    top = sigma.max(axis=0, keepdims=True)
    top = np.where(top > 0, top, 1.0)
    return np.maximum(sigma, floor * top)


def _roughness(log_w: np.ndarray) -> tuple[float, np.ndarray]:
    """``½ Σ_{s,j} (log ω_{s+1,j} − log ω_{s,j})²`` and its gradient in ``log ω``."""
    d = np.diff(log_w, axis=0)
    g = np.zeros_like(log_w)
    g[1:] += d
    g[:-1] -= d
    return 0.5 * float(np.sum(d**2)), g


def step_objective(
    eta: np.ndarray,
    theta: np.ndarray,
    groups: list[Group],
    beta: float,
    smoothness: float = 0.0,
    log_sigma: np.ndarray | None = None,
) -> tuple[float, np.ndarray]:
    """The scale-free subproblem in the log-step ``η`` (normalised coordinates; see the module docstring).

    ``f(η) = Σ_d log(1 + Σ_i exp(−C(x_i, θ ⊙ e^η))) + β/2 ‖η‖² + λ/2 Σ (Δ_s log ω')²`` with
    ``log ω' = log θ + η − log σ``. ``groups`` hold normalised features ``Φ/σ``. Returns ``f`` and ``∂f/∂η``.
    """
    theta_new = theta * np.exp(eta)
    value = 0.5 * beta * float(np.sum(eta**2))
    grad = beta * eta
    g_theta = np.zeros_like(theta)
    for group in groups:
        v, g = _log_partition(theta_new, group)
        value, g_theta = value + v, g_theta + g
    grad = grad + g_theta * theta_new
    if smoothness > 0 and theta.shape[0] > 1:
        log_w = np.log(theta_new) - (0.0 if log_sigma is None else log_sigma)
        r, g = _roughness(log_w)
        value += smoothness * r
        grad = grad + smoothness * g
    return value, grad


def solve_step(
    w: np.ndarray,
    sigma: np.ndarray,
    groups: list[Group],
    beta: float = 1e-10,
    max_ratio: float = 10.0,
    smoothness: float = 0.0,
    max_iter: int = 500,
    free: np.ndarray | None = None,
    present: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """The scale-free MO-IRL step: ``Δω = ω ⊙ (exp(η*) − 1)`` with
    ``η* = argmin_{|η| ≤ log(max_ratio)} f(η)`` (:func:`step_objective`, L-BFGS-B from ``η = 0``).

    ``w (S, 7)`` are the current weights (> 0), ``sigma (S, 7)`` the scale of :func:`feature_scale`, and
    ``groups`` hold features already divided by ``sigma``. ``Δω > −ω`` holds strictly, and no weight moves by
    more than a factor ``max_ratio``. ``free (S, 7)``: the weights that may move (``η = 0`` elsewhere);
    ``present (S, 7)``: the features in the cost (the others are left out of the likelihood).
    """
    w = np.asarray(w, dtype=float)
    if np.any(w <= 0):
        raise ValueError("the scale-free step needs weights > 0")
    if not max_ratio > 1:
        raise ValueError(f"max_ratio must be > 1, got {max_ratio}")
    theta = w * sigma
    if present is not None:
        theta = np.where(present, theta, 1e-12 * theta)  # absent from the likelihood, still > 0 for the log-step
    log_sigma = np.log(sigma)
    bound = np.full(w.shape, float(np.log(max_ratio)))
    if free is not None:
        bound = np.where(free, bound, 0.0)

    eta, info = minimize_in_box(
        lambda e: step_objective(e, theta, groups, beta, smoothness, log_sigma), -bound, bound, max_iter
    )
    return w * np.expm1(np.clip(eta, -bound, bound)), info


def merit_model_step(m: float, m_plus: np.ndarray, m_minus: np.ndarray, h: float) -> np.ndarray:
    """The log-step ``η (7,)`` of a per-feature quadratic model of the merit in ``log ω``.

    ``m`` is the merit at ``ω``; ``m_plus[j]`` and ``m_minus[j]`` the merits with feature ``j``'s weights (in
    every window) multiplied by ``e^{±h}``. Central differences give the slope ``g_j`` and curvature ``c_j``;
    ``η_j = −g_j / c_j`` where the model is convex, ``−sign(g_j) h`` where it is not, bounded by ``|η_j| ≤ h``.
    A feature whose probe failed (non-finite merit) is not moved.
    """
    m_plus, m_minus = np.asarray(m_plus, dtype=float), np.asarray(m_minus, dtype=float)
    if not (np.isfinite(m) and h > 0):
        raise ValueError(f"the merit model needs a finite merit at ω and h > 0, got {m} and {h}")
    ok = np.isfinite(m_plus) & np.isfinite(m_minus)
    mp, mm = np.where(ok, m_plus, m), np.where(ok, m_minus, m)
    slope = (mp - mm) / (2.0 * h)
    curv = (mp - 2.0 * m + mm) / h**2
    convex = curv > 0
    eta = np.where(convex, -slope / np.where(convex, curv, 1.0), -np.sign(slope) * h)
    return np.clip(np.where(ok, eta, 0.0), -h, h)


def gauss_newton_step(residuals: np.ndarray, jacobians: np.ndarray, bound: float, ridge: float = 1e-6) -> np.ndarray:
    """The log-step ``η (P,)`` of the Gauss-Newton model of a least-squares merit, in a box.

    ``residuals (D, M)`` are each demonstration's weighted errors ``r_d = √c (x_d − x*_d)`` (the merit is
    ``(1/D) Σ_d ‖r_d‖²``) and ``jacobians (D, M, P)`` their derivatives ``∂x_d/∂η`` (same weighting) along the
    ``P`` log-weight directions. Returns ``argmin_{|η| ≤ bound} (1/D) Σ_d ‖r_d + J_d η‖² + ρ ‖η‖²`` with
    ``ρ = ridge · tr(JᵀJ)/(D P)``: the damping settles the directions the merit cannot see (scaling every weight
    by one factor changes no reach) at zero. Solved by scipy's bounded linear least squares.
    """
    r = np.asarray(residuals, dtype=float)
    jac = np.asarray(jacobians, dtype=float)
    if r.ndim != 2 or jac.shape[:2] != r.shape or jac.ndim != 3:
        raise ValueError(f"residuals (D, M) and jacobians (D, M, P) do not match: {r.shape} and {jac.shape}")
    if not (np.isfinite(bound) and bound > 0):
        raise ValueError(f"the step bound must be a number > 0, got {bound}")
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(jac))):
        raise ValueError("the Gauss-Newton model needs finite residuals and Jacobians")
    d, _, n_dir = jac.shape
    a = jac.reshape(-1, n_dir) / np.sqrt(d)
    rho = ridge * max(float(np.sum(a * a)) / n_dir, 1e-300)
    a = np.vstack([a, np.sqrt(rho) * np.eye(n_dir)])
    b = np.concatenate([-r.reshape(-1) / np.sqrt(d), np.zeros(n_dir)])
    from scipy.optimize import lsq_linear

    res = lsq_linear(a, b, bounds=(-bound, bound), method="bvls")
    return np.clip(res.x, -bound, bound)
