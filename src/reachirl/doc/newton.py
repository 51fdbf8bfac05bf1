"""Exact Newton on the reach's knots: the DOC's optimum from a close start, in a few iterations.

The reaching DOC of :mod:`reachirl.doc.task` has, once the dynamics are eliminated, the joint knots
``q_1 … q_{N−1}`` as its only unknowns. Under the semi-implicit Euler step the velocities and accelerations are
differences of the knots, ``q̇_k = (q_k − q_{k−1})/dt`` and ``q̈_k = (q_{k+1} − 2q_k + q_{k−1})/dt²``, the torque is
the inverse dynamics ``τ_k = ID(q_k, q̇_k, q̈_k)``, the rest at the start is ``q_{−2} = q_{−1} = q_0`` (so that
``q̇_0 = 0`` and ``τ_{−1} = g(q_0)``) and the rest at the end is ``q_N = q_{N−1}`` (``q̇_N = 0``). Stage ``k``'s
cost then depends on the four knots ``q_{k−2} … q_{k+1}`` only, and what is left of the constraints is the
fingertip on the bar, ``P_x(q_{N−1}) = target``, and the bounds (joint limits, joint speeds). It is the same
problem as :mod:`reachirl.doc.casadi`'s multiple-shooting NLP, whose other variables are functions of the knots.

The energy term ``|q̇_kᵀτ_k|`` is not smooth where the joint power changes sign. With the sign ``σ_k`` of each
knot's power held fixed, or ``q̇_kᵀτ_k = 0`` imposed at a *kink* (where the optimum sits on the corner), the
problem is smooth, and Newton's method on its KKT conditions converges quadratically from a close start. The
signs and kinks are updated after each step as a semismooth Newton (primal-dual active set) method does: a knot
whose power changes sign becomes a kink, and a kink whose multiplier leaves the subdifferential ``[−w, w]`` is
released on the side its multiplier points to.

The KKT system is banded: with one multiplier per knot (zero and decoupled where the knot is not a kink) and
the unknowns ordered knot by knot, ``(q_k, λ_k)``, its half-bandwidth is 10, and one step is one banded LU
(LAPACK's ``dgbsv``, :mod:`.banded`) of about ``3N`` unknowns. The rest of a step (the stages' derivatives, the
active set's update, the residual and the banded matrix in LAPACK's storage) is one call of a CasADi function
(:func:`_step_function`, compiled to C when :mod:`.compiled` can), through CasADi's buffers, so that Python
does little more per step than call it and the LU.

:func:`newton_solve` returns None whenever it cannot vouch for its answer: no convergence within
:data:`MAX_ITER` steps, a power on the wrong side or a kink's multiplier outside ``[−w, w]``, a bound active or
violated, or a Lagrangian Hessian (the stages' and the bar's curvature) that is not positive definite on the
constraints' null space (a saddle or a maximum). The caller then solves the DOC as before
(:func:`reachirl.doc.casadi.solve`: fatrop from the same start).
"""

from __future__ import annotations

import functools
import math
import threading
from dataclasses import dataclass
from typing import NamedTuple

import casadi as ca
import numpy as np
from scipy import sparse
from scipy.linalg.lapack import dpbtrf as _pbtrf

from ..features import N_FEATURES, window_index
from . import banded, compiled
from .symbolic import ARM_FIELDS, fingertip_jacobian, inverse_dynamics, mass_matrix
from .task import ReachingTask, fingertip_x

__all__ = ["MAX_ITER", "NewtonResult", "newton_solve", "preload"]

MAX_ITER = 16  # Newton steps (measured: 3 to 15 from a fit's moved reach); then fatrop, or the interior point
STEP_TOL = 1e-6  # rad: a last step this small, with the gradient below LOOSE_GRAD_TOL, is converged (quadratic
# convergence: the next step would be ~1e-12 rad)
LOOSE_GRAD_TOL = 1e-5
GRAD_TOL = 1e-8  # the Lagrangian's gradient (objective normalised to order one; round-off leaves ~1e-9)
MAX_STEP = 0.2  # rad: a longer Newton step is shortened to this (a start far from the answer)
BAR_TOL = 1e-10  # m: the fingertip's distance from the bar
POWER_TOL = 1e-9  # W: a kink's joint power
_BW = 10  # the KKT matrix's half-bandwidth with the unknowns ordered (q_k, λ_k) knot by knot
_QBW = 7  # the knots-only Hessian's half-bandwidth (a stage couples four knots)
_ROWS = 82  # the stage function's output: gradient (8), Hessian (64), power, its gradient (8), cost


@dataclass(frozen=True)
class NewtonResult:
    """The knots ``q (N+1, 2)`` of the optimum (``q_N = q_{N−1}``), the steps taken, the kinks at the end, the
    objective's scale used, the bar's multiplier and the objective at the optimum (unscaled: the stages' costs of
    the last step, the DOC's objective to rounding)."""

    q: np.ndarray
    iterations: int
    n_kinks: int
    fscale: float
    bar_multiplier: float
    cost: float


@functools.lru_cache(maxsize=8)
def _stage_map(n: int) -> ca.Function:
    """The stages' derivatives (:func:`_stage`) mapped over ``n`` stages: inputs ``(8, n)``, ``(8, n)``, ``(1, n)``
    and the shared arm, ``dt`` and scale; output ``(82, n)``."""
    return _stage().map(f"newton_map_{n}", "serial", n, [3, 4, 5], [])


@functools.lru_cache(maxsize=1)
def _stage() -> ca.Function:
    """One stage's derivatives. Inputs: the stage's four knots ``x (8,)``, its weights and the power's sign
    ``(8,)``, its kink multiplier, the arm, ``dt`` and the objective's scale. Output ``(82,)``: the Lagrangian's
    gradient ``(8,)`` and Hessian ``(8, 8)`` in the stage's knots, the power ``e``, its gradient ``(8,)`` and the
    stage's cost (with ``|e|``)."""
    x = ca.SX.sym("x", 8)  # (q_{k−2}, q_{k−1}, q_k, q_{k+1})
    ws = ca.SX.sym("ws", N_FEATURES + 1)  # the stage's weights, then σ_k
    lam = ca.SX.sym("lam")
    arm = ca.SX.sym("arm", len(ARM_FIELDS))
    dt = ca.SX.sym("dt")
    fscale = ca.SX.sym("fscale")
    a = [arm[i] for i in range(len(ARM_FIELDS))]
    qa, qb, qc, qn = x[0:2], x[2:4], x[4:6], x[6:8]
    qd_prev, qd = (qb - qa) / dt, (qc - qb) / dt
    qdd_prev, qdd = (qc - 2 * qb + qa) / dt**2, (qn - 2 * qc + qb) / dt**2
    tau_prev = inverse_dynamics(a, qb, qd_prev, qdd_prev)
    tau = inverse_dynamics(a, qc, qd, qdd)
    jac = fingertip_jacobian(a, qc)
    e = ca.dot(qd, tau)
    rates = [
        ca.sumsqr(jac @ qd),
        ws[N_FEATURES] * e,  # |e| on the side σ_k; at a kink σ_k = 0 and e = 0 is a constraint
        ca.bilin(mass_matrix(a, qc), qd, qd),
        ca.sumsqr(qdd),
        ca.sumsqr((tau - tau_prev) / dt),
        ca.sumsqr(qd),
        ca.sumsqr(tau),
    ]
    lag = fscale * dt * sum(ws[j] * rates[j] for j in range(N_FEATURES)) + lam * e
    hess, grad = ca.hessian(lag, x)
    cost = fscale * dt * sum(ws[j] * (ca.fabs(e) if j == 1 else rates[j]) for j in range(N_FEATURES))
    out = ca.vertcat(grad, ca.vec(hess), e, ca.gradient(e, x), cost)
    # common subexpressions computed once (the same operations: bit-identical results, 14 % fewer instructions)
    return ca.Function("reachirl_newton_stage", [x, ws, lam, arm, dt, fscale], [out], {"cse": True})


@functools.lru_cache(maxsize=8)
def _step_function(n: int) -> ca.Function:
    """One Newton step's work but the linear solve, for ``n`` stages, in one function (compiled to C when
    :func:`.compiled.compiled_function` can): the stages' derivatives, the active set's update (see the module
    docstring), the residual and the banded KKT matrix in LAPACK's storage for a banded LU.

    Inputs: the flat path ``q_{−2} … q_N``, the stages' weights ``(7, n)`` column-major, the power's sides
    ``σ``, the kinks (0/1), their multipliers ``λ`` (each ``(n,)``), the bar's ``μ``, ``first`` (1 at the first
    step: the sides are set from the powers, and with ``auto`` the derivatives scaled by ``1 / cost``), ``auto``,
    the arm, ``dt``, the objective's scale and the bar's ``target``. Outputs: the LU storage, the residual, the
    updated ``σ``, kinks and ``λ``, whether the active set changed, the scale used and the stage function's
    output ``(82, n)`` (at the objective's scale from the second step on)."""
    lay = _scatter(n)
    path = ca.MX.sym("path", 2 * (n + 3))
    wk = ca.MX.sym("w", N_FEATURES * n)
    sigma, kink, lam = ca.MX.sym("sigma", n), ca.MX.sym("kink", n), ca.MX.sym("lam", n)
    mu, first, auto = ca.MX.sym("mu"), ca.MX.sym("first"), ca.MX.sym("auto")
    arm, dt, fscale = ca.MX.sym("arm", len(ARM_FIELDS)), ca.MX.sym("dt"), ca.MX.sym("fscale")
    target = ca.MX.sym("target")
    side = ca.if_else(kink, 0, sigma)
    ws = ca.vertcat(ca.reshape(wk, N_FEATURES, n), side.T)
    x = ca.reshape(path[lay.gather.tolist()], 8, n)
    raw = _stage_map(n)(x, ws, lam.T, arm, dt, fscale)  # (82, n)
    # with ``auto``, the first step runs at scale 1 and its derivatives are scaled by 1 / the start's cost
    # (λ = 0 there, so they scale with it)
    cost = ca.sum2(raw[81, :])
    start_scale = ca.if_else(ca.logic_and(cost > 1e-300, cost < ca.inf), 1 / cost, 1)
    scale = ca.if_else(auto, start_scale, 1)
    used = ca.if_else(auto, start_scale, fscale)
    e, de = raw[72, :].T, raw[73:81, :]
    w_e = used * dt * wk[1::N_FEATURES]
    coef = side * w_e + lam
    not0 = ca.DM([0.0] + [1.0] * (n - 1))  # stage 0's power is identically zero (q̇_0 = 0)
    flip = ca.logic_and(ca.logic_and(ca.logic_not(kink), sigma * e < 0), not0)
    release = ca.logic_and(kink, ca.fabs(lam) > w_e * (1 + 1e-9))
    sigma_new = ca.if_else(first, ca.sign(e) * not0, ca.if_else(release, ca.sign(lam), sigma))
    kink_new = ca.if_else(first, kink, ca.logic_and(ca.logic_or(kink, flip), ca.logic_not(release)))
    lam_new = ca.if_else(kink_new, lam, 0)
    changed = ca.logic_or(first, ca.sum1(flip) + ca.sum1(release) > 0)
    # the gradient follows the new active set exactly (its terms in σ and λ are linear in ∇e); the Hessian's,
    # one step late
    delta = (ca.if_else(kink_new, 0, sigma_new) * w_e + lam_new) - coef
    qb = path[2 * (n + 1) : 2 * (n + 2)]  # q_{N−1}
    tip, jtip, hess_tip = _bar_terms(arm, qb)
    # the residual and the LU storage: sums of 0/1 operators applied to what they gather (:func:`_gather_sum`);
    # the stages' gradients and Hessians are read where the stage function wrote them
    g_rows, g_cols = lay.grad_terms
    g_raw = (g_cols % 8) + _ROWS * (g_cols // 8)
    scaled = ca.vec(raw) * scale
    r = _gather_sum(
        lay.size,
        [
            (g_rows, g_raw, _ROWS * n, scaled),
            (g_rows, g_cols, 8 * n, ca.vec(de * ca.repmat(delta.T, 8, 1))),
            (lay.last, [0, 1], 2, mu * jtip),
            (lay.lam_rows, range(n - 1), n - 1, ca.if_else(kink_new[1:], e[1:], lam_new[1:])),
            ([lay.size - 1], [0], 1, tip - target),
        ],
    )
    b_rows, b_cols = lay.band_terms
    kk, jj = np.nonzero(lay.kink_pos < lay.lu_size)
    lu = _gather_sum(
        lay.lu_size,
        [
            (b_rows, b_cols, _ROWS * n, scaled),
            # ∂e_k/∂q in the row and the column of λ_k (stage 0 has no λ)
            (lay.kink_pos[kk, jj], (jj % 8) + 8 * kk, 8 * n, ca.vec(de * ca.repmat(kink_new.T, 8, 1))),
            (lay.lam_diag, range(n - 1), n - 1, 1 - kink_new[1:]),  # λ_k = 0 off the kinks
            (lay.bar_pos, [0, 1, 0, 1], 2, jtip),
            (lay.curv_pos, range(4), 4, mu * hess_tip),
        ],
    )
    return ca.Function(
        f"reachirl_newton_step_{n}",
        [path, wk, sigma, kink, lam, mu, first, auto, arm, dt, fscale, target],
        [lu, r, sigma_new, kink_new, lam_new, changed, used, ca.vec(raw)],
    )


def _bar_terms(arm: ca.MX, qn: ca.MX) -> tuple[ca.MX, ca.MX, ca.MX]:
    """The fingertip's ``P_x`` at ``q_{N−1} = qn`` (the bar's constraint is ``P_x − target``), its gradient and its
    Hessian (row-major), for the arm's parameters ``arm`` (:data:`~reachirl.doc.symbolic.ARM_FIELDS`)."""
    l1, l2 = arm[ARM_FIELDS.index("l1")], arm[ARM_FIELDS.index("l2")]
    c1, c12, s1, s12 = ca.cos(qn[0]), ca.cos(qn[0] + qn[1]), ca.sin(qn[0]), ca.sin(qn[0] + qn[1])
    jac = ca.vertcat(-l1 * s1 - l2 * s12, -l2 * s12)
    curv = -ca.vertcat(l1 * c1 + l2 * c12, l2 * c12, l2 * c12, l2 * c12)
    return l1 * c1 + l2 * c12, jac, curv


def _gather_sum(n_rows: int, ops) -> ca.MX:
    """``Σ_i op_i @ v_i`` as one dense vector of ``n_rows``: each ``(rows, cols, n_cols, v_i)`` a 0/1 operator
    (its nonzeros at ``(rows, cols)``) and the vector it applies to. Summed as gathers (each row's first term,
    then its second … where it has one), which compiled code runs several times faster than a sparse product."""
    rows, cols, offset = [], [], 0
    for r, c, width, _ in ops:
        rows.append(np.asarray(r, dtype=int))
        cols.append(offset + np.asarray(list(c), dtype=int))
        offset += width
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    order = np.argsort(rows, kind="stable")  # each row's terms in the order given
    rows, cols = rows[order], cols[order]
    rank = np.arange(rows.size) - np.searchsorted(rows, rows)  # the term's place among its row's
    source = ca.vertcat(*[v for *_, v in ops], 0)  # the last entry: a zero, for rows without terms
    first = np.full(n_rows, offset)
    first[rows[rank == 0]] = cols[rank == 0]
    total = source[first.tolist()]
    for j in range(1, int(rank.max(initial=0)) + 1):
        at = rows[rank == j].tolist()
        total[at] = total[at] + source[cols[rank == j].tolist()]
    return total


@functools.lru_cache(maxsize=8)
def _layout(n: int):
    """Where each stage's local derivatives go in the banded KKT matrix of ``n`` stages.

    Unknowns, knot by knot: ``(q_k (2), λ_k)`` for ``k = 1 … N−1`` (``λ_k``: the kink multiplier of stage ``k``),
    then ``μ`` (the bar). Returns ``(var (n, 8), n_unknowns)``: each stage-local variable's unknown (−1 for the
    fixed start knots; ``q_N`` is ``q_{N−1}``)."""
    var = np.full((n, 8), -1, dtype=int)
    for k in range(n):
        for j, knot in enumerate((k - 2, k - 1, k, k + 1)):
            knot = min(knot, n - 1)  # q_N = q_{N−1}
            if knot >= 1:
                var[k, 2 * j : 2 * j + 2] = 3 * (knot - 1) + np.arange(2)
    return var, 3 * (n - 1) + 1


def _band_index(rows: np.ndarray, cols: np.ndarray, size: int) -> np.ndarray:
    """Flat indices into LAPACK's banded storage ``(2·BW + 1, size)``, column-major, of the entries
    ``(rows, cols)``."""
    return (_BW + rows - cols) + (2 * _BW + 1) * cols


class _Layout(NamedTuple):
    """Precomputed indices of the banded KKT system of ``n`` stages (:func:`_scatter`).

    The positions ``*_pos`` and ``lam_diag`` are flat indices into LAPACK's storage for the banded LU, ``(3·BW + 1,
    size)`` column-major (``BW`` rows of fill-in above the band), where :func:`_step_function` assembles the
    matrix."""

    size: int  # unknowns
    last: np.ndarray  # (2,): q_{N−1}'s unknowns (the bar's knot); μ is the last unknown
    grad_op: sparse.csr_matrix  # the stages' gradients (8, n) (column-major) → the residual's rows
    band_op: sparse.csr_matrix  # the stage function's output (82, n) (column-major) → the Hessian's band
    lam_rows: np.ndarray  # λ_1 … λ_{N−1} among the unknowns
    q_rows: np.ndarray  # the knots' unknowns
    gather: np.ndarray  # (8 n,): stage k's knot values, column-major (8, n), from the flat path q_{−2} … q_N
    kink_pos: np.ndarray  # (n, 16): where ∂e_k/∂(stage k's knots) goes, as λ_k's column, then row
    lam_diag: np.ndarray  # (N−1,): the diagonal entries of λ_1 … λ_{N−1}
    bar_pos: np.ndarray  # (4,): q_{N−1}'s two entries in μ's column, then in μ's row
    curv_pos: np.ndarray  # (4,): q_{N−1}'s 2 × 2 block, row by row
    # grad_op and band_op as sums over index arrays (their nonzeros are ones, summed in the operators' own order,
    # so that a sum is bit for bit the sparse product): output position, then input position, of each term
    grad_terms: tuple[np.ndarray, np.ndarray]
    band_terms: tuple[np.ndarray, np.ndarray]  # output positions in the LU storage
    lu_size: int  # (3·BW + 1) · size


@functools.lru_cache(maxsize=8)
def _scatter(n: int) -> _Layout:
    var, size = _layout(n)
    k, i = np.nonzero(var >= 0)
    grad_op = sparse.csr_matrix((np.ones(k.size), (var[k, i], i + 8 * k)), shape=(size, 8 * n))
    r = np.repeat(var[:, :, None], 8, axis=2)  # (n, 8, 8) row unknown of H[k, i, j]
    c = np.repeat(var[:, None, :], 8, axis=1)
    kk, ii, jj = np.nonzero((r >= 0) & (c >= 0))
    band_op = sparse.csr_matrix(
        (np.ones(kk.size), (_band_index(r[kk, ii, jj], c[kk, ii, jj], size), 8 + ii + 8 * jj + _ROWS * kk)),
        shape=((2 * _BW + 1) * size, _ROWS * n),
    )
    lam_rows = 3 * np.arange(n - 1) + 2
    # stage k's knots are q_{k−2} … q_{k+1}: entries 2(k + j) + c of the flat path q_{−2}, q_{−1}, q_0 … q_N
    stage, j, c = np.meshgrid(np.arange(n), np.arange(4), np.arange(2), indexing="ij")
    outside = (2 * _BW + 1) * size  # one past the band: where the entries on the fixed start knots go
    jl = np.broadcast_to((3 * (np.arange(n) - 1) + 2)[:, None], var.shape)  # λ_k's unknown (stage 0 has none)
    valid = (var >= 0) & (jl >= 0)
    kink_pos = np.hstack(
        [np.where(valid, _band_index(var, jl, size), outside), np.where(valid, _band_index(jl, var, size), outside)]
    )
    last = np.array([size - 4, size - 3])  # q_{N−1}'s unknowns (then λ_{N−1}); μ is the last one
    mu = np.full(2, size - 1)
    lu_size = (3 * _BW + 1) * size

    def to_lu(band_pos: np.ndarray) -> np.ndarray:  # band storage (2·BW + 1 rows) → LU storage (BW more on top)
        band_pos = np.asarray(band_pos)
        return np.where(
            band_pos < outside, _BW + band_pos % (2 * _BW + 1) + (3 * _BW + 1) * (band_pos // (2 * _BW + 1)), lu_size
        )

    return _Layout(
        size=size,
        last=last,
        grad_op=grad_op,
        band_op=band_op,
        lam_rows=lam_rows,
        q_rows=np.setdiff1d(np.arange(size - 1), lam_rows),
        gather=(2 * (stage + j) + c).reshape(-1),
        kink_pos=to_lu(kink_pos),
        lam_diag=to_lu(_band_index(lam_rows, lam_rows, size)),
        bar_pos=to_lu(np.r_[_band_index(last, mu, size), _band_index(mu, last, size)]),
        curv_pos=to_lu(_band_index(last[[0, 0, 1, 1]], last[[0, 1, 0, 1]], size)),
        grad_terms=_terms(grad_op),
        band_terms=(to_lu(_terms(band_op)[0]), _terms(band_op)[1]),
        lu_size=lu_size,
    )


def _terms(op: sparse.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """A 0/1 operator's ``(rows, columns)`` of its nonzeros, in the order its product sums them (row by row, in
    its stored column order): ``np.bincount(rows, weights=x[columns])`` is then ``op @ x`` to the last bit."""
    if not np.all(op.data == 1.0):
        raise ValueError("not a 0/1 operator")
    return np.repeat(np.arange(op.shape[0]), np.diff(op.indptr)), op.indices.copy()


@functools.lru_cache(maxsize=8)
def _arm_params(arm) -> np.ndarray:
    params = np.array([getattr(arm, f) for f in ARM_FIELDS], dtype=float)
    params.setflags(write=False)
    return params


@functools.lru_cache(maxsize=64)
def _knot_windows(n: int, n_windows: int) -> np.ndarray:
    return window_index(n, n_windows)


_local = threading.local()


def _params(task: ReachingTask) -> tuple[np.ndarray, float]:
    return _arm_params(task.arm), float(task.dt)


def _path(q0: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The flat path ``q_{−2}, q_{−1}, q_0, q_1 … q_{N−1}, q_N = q_{N−1}`` (at rest at both ends) from the inner
    knots ``q (N−1, 2)``."""
    full = np.empty((q.shape[0] + 4, 2))
    full[:3] = q0
    full[3:-1] = q
    full[-1] = q[-1]
    return full.reshape(-1)


def _stage_knots(q0: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(8, n)``: each stage's knots ``(q_{k−2}, q_{k−1}, q_k, q_{k+1})`` from the inner knots ``q (N−1, 2)``."""
    n = q.shape[0] + 1
    return _path(q0, q)[_scatter(n).gather].reshape(8, n, order="F")


def _workspace(build, n: int):
    """This thread's buffers of the CasADi function ``build(n)`` (compiled when :func:`.compiled.compiled_function`
    can): ``(trigger, inputs, outputs)``, the arrays it reads and writes in place (made once per thread, function
    and size)."""
    spaces = getattr(_local, "spaces", None)
    if spaces is None:
        spaces = _local.spaces = {}
    space = spaces.get((build, n))
    if space is None:
        f = build(n)
        f = compiled.compiled_function(f) or f
        buf, trigger = f.buffer()
        inputs = [np.zeros(f.nnz_in(i)) for i in range(f.n_in())]
        outputs = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        for i, a in enumerate(inputs):
            buf.set_arg(i, a)
        for i, a in enumerate(outputs):
            buf.set_res(i, a)
        space = spaces[build, n] = (buf, trigger, inputs, outputs)  # the buffer object keeps the trigger valid
    return space[1:]


def preload(n: int) -> None:
    """Build (or load, compiled) this thread's functions of ``n`` intervals: Newton's step and its check of the
    minimum; and the compiled banded LU (:mod:`.banded`)."""
    for build in (_step_function, _minimum_band):
        _workspace(build, n)
    banded.native()


def newton_solve(
    task: ReachingTask,
    weights: np.ndarray,
    q_start: np.ndarray,
    fscale: float | None = None,
    max_iter: int = MAX_ITER,
) -> NewtonResult | None:
    """The DOC's optimum from the joint path ``q_start (N+1, 2)`` (a close start: a neighbouring reach moved to
    this task, or this task's solution under other weights), or None when Newton's method cannot vouch for it
    (see the module docstring). ``weights (n_windows, 7)``; ``fscale``: the objective's scale (the tolerances are
    relative to an objective of order one), by default ``1 / cost`` of the start, as the CasADi backend's."""
    n = task.n_nodes
    lay = _scatter(n)
    size = lay.size
    w_knot = np.asarray(weights, dtype=float)[_knot_windows(n, weights.shape[0])]  # (n, 7)
    q0 = np.asarray(task.q0, dtype=float)
    trigger, inputs, outputs = _workspace(_step_function, n)
    path, w_in, sigma, kink, lam, mu, first, auto, arm_in, dt_in, fs_in, target = inputs
    lu_out, r, sigma_new, kink_new, lam_new, changed_out, used, out = outputs
    path[:] = _path(q0, np.asarray(q_start[1:n], dtype=float))  # q_{−2} … q_N; the unknowns q_1 … q_{N−1} inside
    q = path[6:-2].reshape(n - 1, 2)  # a view: a step moves the path (q_N = q_{N−1} is set after each step)
    w_in[:] = w_knot.reshape(-1)
    sigma[:], kink[:], lam[:], mu[0], first[0] = 0.0, 0.0, 0.0, 0.0, 1.0
    auto[0] = 1.0 if fscale is None else 0.0
    arm_in[:] = _arm_params(task.arm)
    dt_in[0], fs_in[0], target[0] = float(task.dt), 1.0 if fscale is None else float(fscale), task.target_x
    dq = None
    for it in range(max_iter + 1):
        trigger()
        if it == 0:  # from here on at the scale the first step set
            fs_in[0], first[0], auto[0] = used[0], 0.0, 0.0
        if it > 0 and not changed_out[0]:
            g = float(np.max(np.abs(r[lay.q_rows])))
            stationary = g < GRAD_TOL or (g < LOOSE_GRAD_TOL and float(np.max(np.abs(dq))) < STEP_TOL)
            feasible = abs(r[-1]) < BAR_TOL and float(np.max(np.abs(r[lay.lam_rows]), initial=0.0)) < POWER_TOL
            if stationary and feasible:
                return _answer(task, q0, q, kink_new > 0, lam_new, mu[0], sigma_new, w_knot, used[0], out, it)
        if it == max_iter:
            return None
        # the banded LU (``_BW`` rows of fill-in on top of the band, in place)
        step = -r
        info = banded.solve(_BW, _BW, lu_out.reshape(3 * _BW + 1, size, order="F"), step)
        size_of = np.abs(step)
        if info != 0 or not math.isfinite(size_of.max()):  # the largest entry is NaN or infinite if any is
            return None
        inner = step[: size - 1].reshape(n - 1, 3)
        longest = float(size_of[: size - 1].reshape(n - 1, 3)[:, :2].max())
        if longest > MAX_STEP:
            step *= MAX_STEP / longest
        dq = inner[:, :2]
        q += dq
        path[-2:] = path[-4:-2]  # q_N = q_{N−1}
        sigma[:], kink[:] = sigma_new, kink_new
        lam[:] = lam_new
        lam[1:] += inner[:, 2]
        mu[0] += step[-1]
    return None


def _answer(task, q0, q, kink, lam, mu, sigma, w_knot, fscale, out, it) -> NewtonResult | None:
    """The converged point as a :class:`NewtonResult`, or None if it is not the DOC's optimum
    (:func:`_verified`)."""
    n = task.n_nodes
    res = out.reshape(_ROWS, n, order="F")
    e = res[72]
    w_e = fscale * float(task.dt) * w_knot[:, 1]
    _, jtip = fingertip_x(task, q[-1])
    curv = mu * _fingertip_hessian(task, q[-1])  # the bar's curvature in the Lagrangian
    if not _verified(task, q0, q, kink, lam, w_e, sigma, e, out, jtip, curv):
        return None
    qs = np.vstack([q0, q, q[-1:]])
    return NewtonResult(
        q=qs,
        iterations=it,
        n_kinks=int(kink.sum()),
        fscale=float(fscale),
        bar_multiplier=float(mu),
        cost=float(np.sum(res[_ROWS - 1])) / float(fscale),
    )


def _fingertip_hessian(task: ReachingTask, q: np.ndarray) -> np.ndarray:
    """``∂²P_x/∂q² (2, 2)``."""
    a = task.arm
    c1, c12 = np.cos(q[0]), np.cos(q[0] + q[1])
    return -np.array([[a.l1 * c1 + a.l2 * c12, a.l2 * c12], [a.l2 * c12, a.l2 * c12]])


def _verified(task, q0, q, kink, lam, w_e, sigma, e, out, jtip, curv) -> bool:
    """Whether the converged point is the DOC's optimum: every knot's power on its side, every kink's multiplier
    inside ``[−w, w]``, the bounds inactive, and the Hessian positive definite on the constraints' null space."""
    off = ~kink
    off[0] = False
    if np.any(sigma[off] * e[off] < 0) or np.any(np.abs(lam[kink]) > w_e[kink] * (1 + 1e-6)):
        return False
    qs = np.vstack([q0, q, q[-1:]])
    qd = np.diff(qs, axis=0) / task.dt
    if np.any(qs[1:] <= task.q_lower) or np.any(qs[1:] >= task.q_upper) or np.any(np.abs(qd) >= task.qd_max):
        return False
    return _is_minimum(out, task.n_nodes, kink, jtip, curv)


def _is_minimum(out, n, kink, jtip, curv) -> bool:
    """Whether the Lagrangian's Hessian in the knots (the stages', and ``curv``: the bar's ``μ ∇²P_x`` on
    ``q_{N−1}``) is positive definite on the null space of the constraints (the bar, the kinks): a banded
    Cholesky factorisation of ``H + ρ Σ ĉĉᵀ`` (``ĉ``: each constraint's unit gradient) with ``ρ`` a thousand
    times the largest diagonal entry of ``H``, assembled by :func:`_minimum_band`."""
    trigger, (out_in, kink_in, jtip_in, curv_in), (ab,) = _workspace(_minimum_band, n)
    out_in[:] = out
    kink_in[:] = kink
    jtip_in[:] = jtip
    curv_in[:] = np.ravel(curv)
    trigger()
    _, info = _pbtrf(ab.reshape(_QBW + 1, -1), lower=0)  # LAPACK's banded Cholesky (``scipy.linalg.cholesky_banded``
    # without its checks); it factorises a copy: ``ab`` is C-ordered
    return info == 0


@functools.lru_cache(maxsize=8)
def _minimum_band(n: int) -> ca.Function:
    """The upper band ``(_QBW + 1, m)`` (row ``_QBW`` the diagonal, row-major) of :func:`_is_minimum`'s matrix
    ``H + ρ Σ ĉĉᵀ`` for ``n`` stages. Inputs: the stage function's output ``(82, n)``, the kinks (0/1), the bar's
    gradient ``(2,)`` and its curvature ``(2, 2)`` row-major."""
    _, pos, m = _q_scatter(n)
    rows, cols = _q_terms(n)
    size = (_QBW + 1) * m
    out, kink = ca.MX.sym("out", _ROWS * n), ca.MX.sym("kink", n)
    jtip, curv = ca.MX.sym("jtip", 2), ca.MX.sym("curv", 4)
    diag = _QBW * m + np.arange(m)
    corner = [diag[m - 2], diag[m - 1], (_QBW - 1) * m + m - 1]  # q_{N−1}'s 2 × 2 block: diagonal, then off it
    hess = _gather_sum(size, [(rows, cols, _ROWS * n, out), (corner, range(3), 3, curv[[0, 3, 1]])])
    rho = 1e3 * ca.fmax(1, ca.mmax(ca.fabs(hess[diag.tolist()])))
    u = jtip / ca.fmax(ca.norm_2(jtip), 1e-300)  # the bar's unit gradient, on q_{N−1}
    de = ca.reshape(out, _ROWS, n)[73:81, :]
    v = de / ca.repmat(ca.fmax(ca.sqrt(ca.sum1(de**2)), 1e-300), 8, 1) * ca.repmat(kink.T, 8, 1)  # each kink's
    # unit gradient over its stage's knots (zero off the kinks)
    k, ij = np.nonzero(pos < size)
    i, j = ij % 8, ij // 8
    outer = v[(i + 8 * k).tolist()] * v[(j + 8 * k).tolist()]
    rank_one = _gather_sum(
        size,
        [
            (corner, range(3), 3, ca.vertcat(u[0] ** 2, u[1] ** 2, u[0] * u[1])),
            (pos[k, ij], range(k.size), k.size, outer),
        ],
    )
    return ca.Function(f"reachirl_newton_minimum_{n}", [out, kink, jtip, curv], [hess + rho * rank_one])


@functools.lru_cache(maxsize=8)
def _q_terms(n: int) -> tuple[np.ndarray, np.ndarray]:
    return _terms(_q_scatter(n)[0])


@functools.lru_cache(maxsize=8)
def _q_scatter(n: int):
    """The stage function's output (82, n) → the upper band ``(_QBW + 1, m)`` of the knots-only Hessian (``m``
    knot unknowns), and each stage's 8 × 8 local entries' flat positions in that band, ``(n, 64)`` (``ab.size``
    where an entry is below the diagonal or on a fixed start knot)."""
    var, _ = _layout(n)
    qvar = np.where(var >= 0, var - var // 3, -1)  # unknown → index among the knots' unknowns
    r = np.repeat(qvar[:, :, None], 8, axis=2)
    c = np.repeat(qvar[:, None, :], 8, axis=1)
    upper = (r >= 0) & (c >= 0) & (r <= c)
    kk, ii, jj = np.nonzero(upper)
    m = 2 * (n - 1)
    rows = (_QBW + r[kk, ii, jj] - c[kk, ii, jj]) * m + c[kk, ii, jj]
    op = sparse.csr_matrix((np.ones(kk.size), (rows, 8 + ii + 8 * jj + _ROWS * kk)), shape=((_QBW + 1) * m, _ROWS * n))
    pos = np.where(upper, (_QBW + r - c) * m + c, (_QBW + 1) * m).reshape(n, 64)
    return op, pos, m
