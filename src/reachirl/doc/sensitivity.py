"""How an optimal reach moves when its weights change: ``∂q_k / ∂ log ω_{s,j}`` by the implicit function theorem.

At a solution ``z*`` of the DOC (the NLP of :mod:`reachirl.doc.casadi`, which is exactly the problem both backends
solve), the KKT conditions on the free variables hold for every weight near ``ω``::

    ∇_z f(z, ω) + A(z)ᵀ λ = 0,    g(z) = 0        (A = ∂g/∂z, the dynamics and terminal constraints)

so, differentiating along a change ``dω`` with the active set held fixed::

    [ H   Aᵀ ] [ dz ]     [ −∂(∇_z f)/∂ω · dω ]
    [ A   0  ] [ dλ ]  =  [          0         ]         H = ∇²_zz (f + λᵀg)

The variables at a bound (the energy's zero slack ``s±`` at each knot, a joint limit or the speed bound where one
binds) are held (``dz = 0``). A knot whose joint power ``q̇ᵀτ`` is zero (below :data:`CORNER_TOL` of ``|q̇||τ|``:
the optimum sits on the energy's corner, where an interior point leaves it within its tolerance of zero) holds
both of its slacks, set to zero, so that its power stays zero. The multipliers are those of the returned point,
from the same KKT matrix with the objective's Hessian (at an optimum ``dz = 0`` solves it whatever the Hessian, so
one sparse solve gives ``λ``). The point is the solution rebuilt as the backends return it
(:func:`reachirl.doc.casadi._pack` of its knots: exact slacks), so a solution of either backend is differentiated
the same way.

One column per window and feature, each the derivative along ``d log ω_{s,j}`` (the weight of feature ``j`` in
window ``s`` multiplied by ``e^ε``): the directions MO-IRL's steps take. Tested against central differences of
the solver. Cost at N = 100: ~20 ms (two sparse LU factorisations of a 1700 × 1700 KKT matrix), about two warm
solves.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from ..features import N_FEATURES, window_index
from . import casadi as cb
from .task import DocSolution, ReachingTask, rest_to_rest_knots

__all__ = ["weight_jacobian"]


def _sparse(m) -> sps.csc_matrix:
    """A CasADi ``DM`` as a scipy CSC matrix."""
    r, c = m.sparsity().get_triplet()
    return sps.csc_matrix((np.asarray(m.nonzeros(), dtype=float), (r, c)), shape=m.shape)


#: a knot's joint power below this fraction of ``|q̇||τ|`` (the cosine of the angle between them) is on the corner
CORNER_TOL = 1e-3


def _corner_slacks(task: ReachingTask, q: np.ndarray) -> np.ndarray:
    """The indices in the decision vector (:func:`reachirl.doc.casadi._pack`) of the slacks ``(s⁺, s⁻)`` of the
    knots whose joint power is zero to :data:`CORNER_TOL`, shape ``(K, 2)`` (knot 0's power is zero by the rest at
    the start and has no slack variables)."""
    _, qd, tau = rest_to_rest_knots(task, q)
    power = np.sum(qd[:-1] * tau, axis=1)
    size = np.linalg.norm(qd[:-1], axis=1) * np.linalg.norm(tau, axis=1)
    k = np.flatnonzero(np.abs(power[1:]) <= CORNER_TOL * size[1:]) + 1
    first = 2 + (k - 1) * (cb.NX + cb.NU) + cb.NX + 2  # knot k's controls (q̈ (2), s⁺, s⁻) follow its state
    return np.stack([first, first + 1], axis=1)


def weight_jacobian(task: ReachingTask, weights: np.ndarray, sol: DocSolution) -> np.ndarray:
    """``∂q / ∂ log ω`` of the optimal reach ``sol`` of ``task`` under ``weights (S, 7)``: shape
    ``(N+1, 2, S, 7)``. ``q_0`` is fixed by the task (its rows are zero); so is the derivative of a weight that
    is zero. Raises ``ValueError`` for an unconverged solution or a singular KKT matrix (a degenerate optimum)."""
    weights = np.asarray(weights, dtype=float)
    n = task.n_nodes
    if not sol.converged:
        raise ValueError("the sensitivity of a DOC solution needs a converged solution")
    if sol.q.shape != (n + 1, 2):
        raise ValueError(f"the solution has {sol.q.shape[0]} knots, the task {n + 1}")
    nlp = cb.build_nlp(n)
    fun = nlp.kkt_functions()
    z = cb._pack(task, np.asarray(sol.q, dtype=float))
    p = nlp.params(task, weights, cb._objective_scale(task, weights, z))
    bounds = nlp.bounds(task)
    lb, ub = bounds["lbx"], bounds["ubx"]
    span = np.where(np.isfinite(ub - lb), ub - lb, 1.0)
    free = (z - lb > 1e-9 * span) & (ub - z > 1e-9 * span)  # exact slacks: the zero one is exactly at its bound
    corner = _corner_slacks(task, np.asarray(sol.q, dtype=float))  # (K, 2): s⁺, s⁻ of the knots on the corner
    z[corner] = 0.0
    free[corner] = False

    a = _sparse(fun["A"](z, p))[:, free]
    n_g = a.shape[0]
    grad = np.asarray(fun["grad"](z, p), dtype=float).ravel()[free]

    def kkt(lam: np.ndarray) -> spla.SuperLU:
        h = _sparse(fun["H"](z, p, lam))[free][:, free]
        k = sps.bmat([[h, a.T], [a, None]], format="csc")
        try:
            return spla.splu(k)
        except RuntimeError as e:  # "Factor is exactly singular"
            raise ValueError(f"the DOC's KKT matrix is singular at this solution ({e})") from None

    lam = kkt(np.zeros(n_g)).solve(np.r_[-grad, np.zeros(n_g)])[free.sum() :]
    lu = kkt(lam)
    # ∂(∇_z f)/∂w (per knot and feature) times d w / d log ω_{s,j} = ω_{s,j} on the knots of window s
    window = window_index(n, weights.shape[0])
    seeds = sps.csc_matrix(
        (
            weights[window].reshape(-1),
            (np.arange(n * N_FEATURES), (window[:, None] * N_FEATURES + np.arange(N_FEATURES)).reshape(-1)),
        ),
        shape=(n * N_FEATURES, weights.size),
    )
    rhs = -(_sparse(fun["B"](z, p))[free] @ seeds).toarray()
    dz = np.zeros((z.size, weights.size))
    dz[free] = lu.solve(np.vstack([rhs, np.zeros((n_g, weights.size))]))[: free.sum()]
    dq = np.stack([cb._unpack_q(task, dz[:, c]) for c in range(weights.size)], axis=-1)
    dq[0] = 0.0
    return dq.reshape(n + 1, 2, *weights.shape)
