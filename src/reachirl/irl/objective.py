"""The MO-IRL equations as pure functions (seed paper, Eqs. 2-4; Mehrdad et al. 2025).

Notation: ``ω``, ``Δω`` are weight matrices ``(n_windows, 7)``; ``Φ*_d`` the features of demonstration ``d`` and
``Φ_i`` those of a generated trajectory ``x_i ∈ x̄``, all ``(n_windows, 7)``.

* Cost mismatch (seed Eq. 4): ``C(x_i, Δω) = Σ_s Δω_sᵀ (Φ_{s,i} − Φ*_{s,d})``.
* Scaling: ``γ_i = exp(−C(x_i, ω))``.
* Subproblem: ``Δω* = argmin_{Δω ≥ −ω} Σ_d −log(1 / (1 + Σ_i γ_i exp(−C(x_i, Δω)))) + β/2 ‖Δω‖²``.

Since ``γ_i exp(−C(x_i, Δω)) = exp(−C(x_i, ω + Δω))``, each demonstration's term is
``log(1 + Σ_i exp(−C(x_i, ω + Δω)))``, evaluated with a log-sum-exp that never overflows. Turning γ off
(``gamma=False``) gives the classic MaxEnt form with ``γ_i = 1``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize
from scipy.special import logsumexp, softmax

__all__ = [
    "Group",
    "cost_mismatch",
    "gamma",
    "merit",
    "solve_delta",
    "subproblem_objective",
]


def cost_mismatch(delta_w: np.ndarray, phi_i: np.ndarray, phi_star: np.ndarray) -> np.ndarray:
    """``C(x_i, Δω) = Σ_s Δω_sᵀ (Φ_{s,i} − Φ*_{s,d})`` for every pair: ``phi_i (I, S, 7)``, ``phi_star (D, S, 7)``
    → ``(D, I)``."""
    diff = phi_i[None, :, :, :] - phi_star[:, None, :, :]
    return np.einsum("sj,disj->di", delta_w, diff)


def gamma(w: np.ndarray, phi_i: np.ndarray, phi_star: np.ndarray) -> np.ndarray:
    """``γ_i = exp(−C(x_i, ω))`` per (demonstration, trajectory), shape ``(D, I)``."""
    return np.exp(-cost_mismatch(w, phi_i, phi_star))


Group = tuple[np.ndarray, np.ndarray, np.ndarray]
"""``(phi_i (I, S, 7), phi_star (D, S, 7), c (D,))``: demonstrations compared with one set of trajectories ``x̄``."""


def _log_partition(shift: np.ndarray, group: Group) -> tuple[float, np.ndarray]:
    """``Σ_d c_d log(1 + Σ_i exp(−C(x_i, shift)))`` and its gradient in ``shift`` (a stable log-sum-exp)."""
    phi_i, phi_star, cd = group
    c = cost_mismatch(shift, phi_i, phi_star)  # (D, I)
    logits = np.hstack([np.zeros((c.shape[0], 1)), -c])  # log of [1, γ_i e^{−C(x_i, Δω)}]
    p = softmax(logits, axis=1)[:, 1:]
    diff = phi_i[None, :, :, :] - phi_star[:, None, :, :]
    return float(cd @ logsumexp(logits, axis=1)), -np.einsum("d,di,disj->sj", cd, p, diff)


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

    The search runs on the raw weights: scaling them by the features' sizes was tried and made L-BFGS-B take
    500 iterations instead of about 40, for a worse objective.
    """
    shape = w.shape

    def fun(x: np.ndarray) -> tuple[float, np.ndarray]:
        f, g = subproblem_objective(x.reshape(shape), w, groups, beta, use_gamma, l1)
        return f, g.reshape(-1)

    res = minimize(
        fun,
        np.zeros(w.size),
        jac=True,
        method="L-BFGS-B",
        bounds=list(zip((-(1.0 - min_ratio) * w).reshape(-1), [None] * w.size, strict=True)),
        options={"maxiter": max_iter, "ftol": 1e-15, "gtol": 1e-12},
    )
    dw = np.maximum(res.x.reshape(shape), -(1.0 - min_ratio) * w)  # exact feasibility: ω + Δω > 0
    return dw, {"fun": float(res.fun), "nit": int(res.nit), "success": bool(res.success), "message": str(res.message)}


def merit(x_demos: np.ndarray, x: np.ndarray) -> float:
    """``m(x) = (1/D) Σ_d (1/N) ‖x*_d − x‖²`` over the full state ``(q1, q2, q̇1, q̇2)`` on common knots.

    ``x_demos`` is ``(D, N+1, 4)`` and ``x`` either ``(N+1, 4)`` (one rollout compared with every demonstration)
    or ``(D, N+1, 4)`` (one rollout per demonstration).
    """
    x_demos = np.asarray(x_demos, dtype=float)
    x = np.asarray(x, dtype=float)
    n = x_demos.shape[1]
    return float(np.mean(np.sum((x_demos - x) ** 2, axis=(1, 2)) / n))
