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
(LAPACK's ``dgbsv``) of about ``3N`` unknowns. The stages' derivatives are one call of a CasADi function mapped
over the stages (compiled to C when :mod:`.compiled` can), through CasADi's buffers.

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
from scipy.linalg.lapack import dgbsv as _gbsv
from scipy.linalg.lapack import dpbtrf as _pbtrf

from ..features import N_FEATURES, window_index
from . import compiled
from .symbolic import ARM_FIELDS, fingertip_jacobian, inverse_dynamics, mass_matrix
from .task import ReachingTask

__all__ = ["MAX_ITER", "NewtonResult", "newton_solve"]

MAX_ITER = 16  # Newton steps (measured: 3 to 15 from a fit's moved reach); then the interior point takes over
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
    objective's scale used and the bar's multiplier."""

    q: np.ndarray
    iterations: int
    n_kinks: int
    fscale: float
    bar_multiplier: float


@functools.lru_cache(maxsize=8)
def _stage_map(n: int) -> ca.Function:
    """The stages' derivatives (:func:`_stage`, compiled when it can be: :func:`.compiled.compiled_function`),
    mapped over ``n`` stages: inputs ``(8, n)``, ``(8, n)``, ``(1, n)`` and the shared arm, ``dt`` and scale;
    output ``(82, n)``."""
    stage = _stage()
    stage = compiled.compiled_function(stage) or stage
    return stage.map(f"newton_map_{n}", "serial", n, [3, 4, 5], [])


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
    return ca.Function("reachirl_newton_stage", [x, ws, lam, arm, dt, fscale], [out])


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
    size)`` column-major (``BW`` rows of fill-in above the band), where the matrix is assembled in place."""

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


def _workspace(n: int):
    """This thread's buffers of the mapped stage function of ``n`` stages: ``(trigger, x_in, ws_in, lam_in, arm,
    dt, fscale, out)``, the arrays the function reads and writes in place (made once per thread and size)."""
    spaces = getattr(_local, "spaces", None)
    if spaces is None:
        spaces = _local.spaces = {}
    space = spaces.get(n)
    if space is None:
        buf, trigger = _stage_map(n).buffer()
        arrays = (np.zeros(8 * n), np.zeros(8 * n), np.zeros(n), np.zeros(len(ARM_FIELDS)), np.zeros(1), np.zeros(1))
        for i, a in enumerate(arrays):
            buf.set_arg(i, a)
        out = np.zeros(_ROWS * n)
        buf.set_res(0, out)
        space = spaces[n] = (buf, trigger, *arrays, out)  # the buffer object keeps the trigger valid
    return space[1:]


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
    dt = float(task.dt)
    scale_known = fscale is not None
    fscale = 1.0 if fscale is None else float(fscale)
    w_e = fscale * dt * w_knot[:, 1]  # each stage's energy weight, as the Lagrangian sees it
    w_release = w_e * (1 + 1e-9)  # a kink whose multiplier exceeds it is released
    q0 = np.asarray(task.q0, dtype=float)
    path = _path(q0, np.asarray(q_start[1:n], dtype=float))  # q_{−2} … q_N; the unknowns q_1 … q_{N−1} inside
    q = path[6:-2].reshape(n - 1, 2)  # a view: a step moves the path (q_N = q_{N−1} is set after each step)
    lam, mu = np.zeros(n), 0.0
    kink = np.zeros(n, dtype=bool)
    sigma = np.zeros(n)
    last = lay.last
    g_rows, g_cols = lay.grad_terms
    b_rows, b_cols = lay.band_terms
    dq = None

    # the mapped stages evaluated in place, through CasADi's buffers (no conversion per call)
    trigger, x_in, ws_in, lam_in, arm_in, dt_in, fs_in, out = _workspace(n)
    arm_in[:] = _arm_params(task.arm)
    dt_in[0], fs_in[0] = dt, fscale
    ws_view = ws_in.reshape(8, n, order="F")
    ws_view[:N_FEATURES] = w_knot.T
    res = out.reshape(_ROWS, n, order="F")

    for it in range(max_iter + 1):
        np.take(path, lay.gather, out=x_in)
        side = np.where(kink, 0.0, sigma)
        ws_view[N_FEATURES] = side
        lam_in[:] = lam
        trigger()
        if not scale_known:  # 1 / the start's cost; λ = 0 here, so the derivatives scale with it
            cost = float(res[81].sum())
            fscale = 1.0 / cost if np.isfinite(cost) and cost > 1e-300 else 1.0
            fs_in[0] = fscale
            res[0:72] *= fscale
            w_e = fscale * dt * w_knot[:, 1]
            w_release = w_e * (1 + 1e-9)
            scale_known = True
        grad, e, de = res[0:8].ravel(order="F"), res[72], res[73:81]
        # the active set (see the module docstring): at the start, each knot's power on its own side; later, a
        # knot whose power changed side becomes a kink, and a kink whose multiplier left [−w, w] is released.
        # The gradient follows exactly (its terms in σ and λ are linear in ∇e); the Hessian's, one step late.
        coef = side * w_e + lam
        if it == 0:
            sigma = np.sign(e)
            sigma[0] = 0.0  # stage 0's power is identically zero (q̇_0 = 0)
            changed = True
        else:
            flip = ~kink & (sigma * e < 0)
            flip[0] = False
            release = kink & (np.abs(lam) > w_release)
            changed = bool(flip.any() or release.any())
            if changed:
                sigma = np.where(release, np.sign(lam), sigma)
                kink = (kink | flip) & ~release
                lam = np.where(kink, lam, 0.0)
        if changed:
            grad = (res[0:8] + de * (np.where(kink, 0.0, sigma) * w_e + lam - coef)).ravel(order="F")
        tip, jtip = _fingertip(task, q[-1])
        r = np.bincount(g_rows, weights=grad[g_cols], minlength=size)
        r[last] += mu * jtip
        r[lay.lam_rows] = np.where(kink[1:], e[1:], lam[1:])
        r[size - 1] = tip - task.target_x
        if it > 0 and not changed:
            g = float(np.max(np.abs(r[lay.q_rows])))
            stationary = g < GRAD_TOL or (g < LOOSE_GRAD_TOL and float(np.max(np.abs(dq))) < STEP_TOL)
            feasible = abs(r[-1]) < BAR_TOL and float(np.max(np.abs(r[lay.lam_rows]), initial=0.0)) < POWER_TOL
            if stationary and feasible:
                curv = mu * _fingertip_hessian(task, q[-1])  # the bar's curvature in the Lagrangian
                if not _verified(task, q0, q, kink, lam, w_e, sigma, e, out, de, jtip, curv):
                    return None
                qs = np.vstack([q0, q, q[-1:]])
                return NewtonResult(q=qs, iterations=it, n_kinks=int(kink.sum()), fscale=fscale, bar_multiplier=mu)
        if it == max_iter:
            return None
        # the banded KKT matrix, assembled in LAPACK's storage for a banded LU (``_BW`` rows of fill-in on top)
        lu = np.bincount(b_rows, weights=out[b_cols], minlength=lay.lu_size)
        ks = np.flatnonzero(kink)
        if ks.size:  # ∂e_k/∂q in the row and the column of λ_k
            vals = de[:, ks].T
            lu += np.bincount(
                lay.kink_pos[ks].reshape(-1), weights=np.hstack([vals, vals]).reshape(-1), minlength=lay.lu_size + 1
            )[:-1]
        lu[lay.lam_diag[~kink[1:]]] = 1.0  # λ_k = 0 off the kinks
        lu[lay.bar_pos[:2]] = jtip
        lu[lay.bar_pos[2:]] = jtip
        lu[lay.curv_pos] += mu * _fingertip_hessian(task, q[-1]).reshape(-1)
        _, _, step, info = _gbsv(
            _BW, _BW, lu.reshape(3 * _BW + 1, size, order="F"), -r, overwrite_ab=True, overwrite_b=True
        )
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
        lam[1:] += inner[:, 2]
        mu += step[-1]
    return None


def _fingertip(task: ReachingTask, q: np.ndarray) -> tuple[float, np.ndarray]:
    """The fingertip's ``P_x(q)`` and its gradient."""
    a = task.arm
    q1, q12 = float(q[0]), float(q[0] + q[1])
    c1, c12, s1, s12 = math.cos(q1), math.cos(q12), math.sin(q1), math.sin(q12)
    return a.l1 * c1 + a.l2 * c12, np.array([-a.l1 * s1 - a.l2 * s12, -a.l2 * s12])


def _fingertip_hessian(task: ReachingTask, q: np.ndarray) -> np.ndarray:
    """``∂²P_x/∂q² (2, 2)``."""
    a = task.arm
    c1, c12 = np.cos(q[0]), np.cos(q[0] + q[1])
    return -np.array([[a.l1 * c1 + a.l2 * c12, a.l2 * c12], [a.l2 * c12, a.l2 * c12]])


def _verified(task, q0, q, kink, lam, w_e, sigma, e, out, de, jtip, curv) -> bool:
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
    return _is_minimum(out, de, task.n_nodes, kink, jtip, curv)


def _is_minimum(out, de, n, kink, jtip, curv) -> bool:
    """Whether the Lagrangian's Hessian in the knots (the stages', and ``curv``: the bar's ``μ ∇²P_x`` on
    ``q_{N−1}``) is positive definite on the null space of the constraints (the bar, the kinks): a banded
    Cholesky factorisation of ``H + ρ Σ ĉĉᵀ`` (``ĉ``: each constraint's unit gradient) with ``ρ`` a thousand
    times the largest diagonal entry of ``H``."""
    _, pos, m = _q_scatter(n)
    rows, cols = _q_terms(n)
    ab = np.bincount(rows, weights=out[cols], minlength=(_QBW + 1) * m).reshape(_QBW + 1, m)  # ``op @ out``: the
    # upper band, row _QBW the diagonal
    ab[_QBW, m - 2 :] += np.diag(curv)
    ab[_QBW - 1, m - 1] += curv[0, 1]
    rho = 1e3 * max(1.0, float(np.max(np.abs(ab[_QBW]))))
    u = jtip / max(float(np.linalg.norm(jtip)), 1e-300)  # the bar's unit gradient, on q_{N−1}
    ab[_QBW, m - 2 :] += rho * u**2
    ab[_QBW - 1, m - 1] += rho * u[0] * u[1]
    ks = np.flatnonzero(kink)
    if ks.size:  # each kink's unit gradient over its stage's knots, its outer product added to the band
        v = de[:, ks].T
        v = v / np.maximum(np.linalg.norm(v, axis=1), 1e-300)[:, None]
        outer = (v[:, :, None] * v[:, None, :]).reshape(-1)
        ab += rho * np.bincount(pos[ks].reshape(-1), weights=outer, minlength=ab.size + 1)[:-1].reshape(ab.shape)
    _, info = _pbtrf(ab, lower=0)  # LAPACK's banded Cholesky (``scipy.linalg.cholesky_banded`` without its checks)
    return info == 0


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
