"""A primal-dual interior point on the reach's knots: the DOC's optimum from a far start, with the energy's corners
and the bounds inside the method.

:mod:`reachirl.doc.newton` solves the DOC on its knots ``q_1 … q_{N−1}`` (the dynamics eliminated) by exact Newton,
which needs the energy's corners and the active bounds known near its start. From a start far from the answer
(the fit's reach under weights a factor 10-250 from the fit's, as the uncertainty's checked samples are) the corners
move at every step and Newton rarely settles. This method keeps the knots as its unknowns and handles what moves
as an interior point does (fatrop's and IPOPT's method, on the same problem):

* The energy ``w|e_k|`` of stage ``k`` (``e_k = q̇_kᵀτ_k``) is ``w(s⁺_k + s⁻_k)`` with ``e_k = s⁺_k − s⁻_k``,
  ``s± ≥ 0`` (the NLP's exact slack form), with dual variables ``z±_k`` and the multiplier ``y_k`` of the split.
* The joint limits and the speed bound are ``s_b(q) ≥ 0``, linear in the knots, with duals ``z_b``.
* The barrier ``−μ Σ ln s`` and the perturbed complementarity ``s z = μ``, for ``μ`` from :data:`MU_START` down
  to :data:`MU_END` (IPOPT's monotone rule: ``μ ← min(0.2 μ, μ^1.5)`` once the error is below ``10 μ``).

Each Newton step of the primal-dual equations is condensed stage by stage: the slacks and duals of stage ``k``
depend on its own power only, so they add ``D_k ∇e_k ∇e_kᵀ`` (``D_k`` from ``z±/s±``) to the stage's 8 × 8
Hessian, and the bounds add ``Aᵀ diag(z_b/s_b) A`` on neighbouring knots. The system is the knots' banded one
(half-bandwidth 7, with the bar's multiplier last), solved by one banded LU (LAPACK's ``dgbsv``, :mod:`.banded`).
That system and its residual are one CasADi function (:func:`_kkt_function`), and the stages' derivatives (the
Lagrangian ``f + Σ y_k e_k``, by :mod:`reachirl.doc.newton`'s stage function) with the barrier function below another
(:func:`_barrier_function`), both compiled to C when :mod:`reachirl.doc.compiled` can: Python does little more
per step than call them, the factorisations and the line search.

Globalisation: the step is damped until the primal barrier function (the slacks at their optimum for the power,
``φ_μ(e) = r − μ ln(μ + r)``, ``r = √(w²e² + μ²)``, the bounds' barrier and ``ν|c|`` for the bar, ``ν`` twice
the bar's new multiplier) falls by an Armijo fraction of its directional derivative (a backtracking line search
after the fraction to the boundary).
The Hessian is regularised (``+δI``) until it is positive definite on the bar's null space (a banded Cholesky of
``H + ρ ĉĉᵀ``), so that the step is a descent direction. After each step the slacks are reset to their optimum
for the new power (``s±(e)``, which keeps the split exact), and a step whose duals point uphill is taken again
with the duals at their central values (the primal barrier's Newton step).

:func:`interior_solve` returns None whenever it cannot vouch for its answer: no convergence within
:data:`MAX_ITER` steps, a failed factorisation or line search, or a regularised Hessian at the end (a saddle).
The caller then solves the DOC as before (fatrop).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import casadi as ca
import numpy as np
from scipy.linalg.lapack import dpbtrf as _pbtrf

from ..features import N_FEATURES
from . import banded
from .newton import (
    _ROWS,
    NewtonResult,
    _arm_params,
    _bar_terms,
    _gather_sum,
    _knot_windows,
    _layout,
    _path,
    _scatter,
    _stage_map,
    _workspace,
)
from .symbolic import ARM_FIELDS
from .task import ReachingTask

__all__ = ["MAX_ITER", "interior_solve", "preload"]

MAX_ITER = 150  # steps (`make run`'s checked samples: median 17, at most 106)
MU_START = 1e-5  # the barrier parameter at the start (fatrop's warm start's, on the same order-one objective)
MU_END = 1e-9
TOL = 1e-7  # the primal-dual equations' error at MU_END (fatrop stops at 1e-6)
BAR_TOL = 1e-10  # m: the fingertip's distance from the bar
_BW = 7  # half-bandwidth of the knots' system (a stage couples four knots; the bar's multiplier sits last)
_FRACTION = 0.99  # of the way to the boundary, at most (slacks and duals stay positive)
_ARMIJO = 1e-4


class _Layout:
    """Where each stage's derivatives go in the banded system of ``n`` stages (LAPACK's LU storage,
    ``(3·BW + 1, size)`` column-major; ``A[i, j]`` at row ``2·BW + i − j``): the gradient's and the Hessian's
    scatter, the bounds' diagonal and off-diagonal entries (a knot and the one before it), and the bar's."""

    def __init__(self, n: int) -> None:
        var, _ = _layout(n)
        qvar = np.where(var >= 0, var - var // 3, -1)  # (n, 8): each stage-local coordinate's knot unknown
        self.m = m = 2 * (n - 1)
        self.size = m + 1
        k, i = np.nonzero(qvar >= 0)
        self.g_rows, self.g_src = qvar[k, i], i + 8 * k  # into the (8, n) gradient, column-major
        rows = np.repeat(qvar[:, :, None], 8, axis=2)
        cols = np.repeat(qvar[:, None, :], 8, axis=1)
        kk, ii, jj = np.nonzero((rows >= 0) & (cols >= 0))
        self.h_pos = self.band(rows[kk, ii, jj], cols[kk, ii, jj])
        self.h_src = ii + 8 * jj + 64 * kk  # into the (64, n) Hessians, column-major
        self.lu_size = (3 * _BW + 1) * self.size
        unknowns = np.arange(m)
        self.diag = self.band(unknowns, unknowns)
        self.below = self.band(unknowns[2:], unknowns[2:] - 2)  # (q_k, q_{k−1}), joint by joint
        self.above = self.band(unknowns[2:] - 2, unknowns[2:])
        last = np.array([m - 2, m - 1])
        self.tip_block = self.band(last[[0, 0, 1, 1]], last[[0, 1, 0, 1]])
        self.tip_col = self.band(last, np.full(2, m))
        self.tip_row = self.band(np.full(2, m), last)
        self.gather = _scatter(n).gather

    @staticmethod
    def band(rows, cols) -> np.ndarray:
        return (2 * _BW + np.asarray(rows) - np.asarray(cols)) + (3 * _BW + 1) * np.asarray(cols)


@functools.lru_cache(maxsize=8)
def _lay(n: int) -> _Layout:
    return _Layout(n)


def _split(e: np.ndarray, c: np.ndarray, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """The slacks ``(s⁺, s⁻)`` of the powers ``e`` that minimise ``c(s⁺ + s⁻) − μ ln s⁺ − μ ln s⁻`` subject to
    ``s⁺ − s⁻ = e`` (``c > 0``): ``s⁻ = (μ − ce + r) / (2c)``, ``r = √(c²e² + μ²)``."""
    r = np.sqrt(c**2 * e**2 + mu**2)
    sm = (mu - c * e + r) / (2 * c)
    return e + sm, sm


def _energy_barrier(e: np.ndarray, c: np.ndarray, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """That minimum (up to a constant) and its derivative in ``e``: ``φ = r − μ ln(μ + r)``, ``φ' = c²e / (μ + r)``;
    ``φ → c|e|`` as ``μ → 0``."""
    r = np.sqrt(c**2 * e**2 + mu**2)
    return r - mu * np.log(mu + r), c**2 * e / (mu + r)


def _to_boundary(v: np.ndarray, dv: np.ndarray) -> float:
    """The longest step (at most 1) keeping ``v + α dv`` at least ``1 − _FRACTION`` of ``v``."""
    neg = dv < 0
    if not neg.any():
        return 1.0
    return min(1.0, float(np.min(-_FRACTION * v[neg] / dv[neg])))


def _bounds_gradient(a, v: ca.MX, m: int) -> ca.MX:
    """``Aᵀ v`` for ``v`` on the bounds' slacks (``(4, N−1, 2)`` row-major, ``4m`` long): ``(m,)`` on the knots.
    ``a``: ``∂s_b/∂q_k`` of each slack kind; ``∂/∂q_{k−1}`` is minus the speeds'."""
    v0, v1, v2, v3 = (v[i * m : (i + 1) * m] for i in range(4))
    g = a[0] * v0 + a[1] * v1 + a[2] * v2 + a[3] * v3
    return ca.vertcat(g[: m - 2] - (a[2] * v2[2:] + a[3] * v3[2:]), g[m - 2 :])


@functools.lru_cache(maxsize=8)
def _barrier_function(n: int) -> ca.Function:
    """The stages' derivatives and the primal barrier function at a point, in one function (compiled to C when
    :func:`reachirl.doc.compiled.compiled_function` can).

    Inputs: the flat path ``q_{−2} … q_N``, the stages' weights and zero sides ``(8, n)`` column-major, the split's
    multipliers ``y`` (zero on the stages without energy), the arm, ``dt``, the objective's scale, the stages with
    energy (1/0) and their ``c`` (zero elsewhere), ``μ``, the joint limits, the speed bound and the bar. Outputs:
    the stage function's output ``(82, n)`` (the Lagrangian ``f + Σ y_k e_k``), the barrier function without the
    bar's penalty (the smooth terms, the energy's barrier :func:`_energy_barrier`, the bounds' ``−μ Σ ln s_b``;
    infinite outside the bounds) and the bar's ``|P_x − target|``."""
    lay = _lay(n)
    m = lay.m
    path = ca.MX.sym("path", 2 * (n + 3))
    ws = ca.MX.sym("ws", (N_FEATURES + 1) * n)
    y, mask, c = ca.MX.sym("y", n), ca.MX.sym("mask", n), ca.MX.sym("c", n)
    arm = ca.MX.sym("arm", len(ARM_FIELDS))
    dt, fscale, mu, target = ca.MX.sym("dt"), ca.MX.sym("fscale"), ca.MX.sym("mu"), ca.MX.sym("target")
    lo, hi, vmax = ca.MX.sym("lo", 2), ca.MX.sym("hi", 2), ca.MX.sym("vmax", 2)
    x = ca.reshape(path[lay.gather.tolist()], 8, n)
    out = _stage_map(n)(x, ca.reshape(ws, N_FEATURES + 1, n), y.T, arm, dt, fscale)  # (82, n)
    q, v = path[6 : 6 + m], (path[6 : 6 + m] - path[4 : 4 + m]) / dt  # the inner knots and their speeds
    lo_, hi_, vmax_ = (ca.repmat(b, n - 1, 1) for b in (lo, hi, vmax))
    s_b = ca.vertcat(q - lo_, hi_ - q, vmax_ - v, v + vmax_)
    e = out[72, :].T
    smooth = ca.sum1(out[_ROWS - 1, :].T) - ca.sum1(c * ca.fabs(e))
    r = ca.sqrt(c**2 * e**2 + mu**2)
    energy = ca.sum1(mask * (r - mu * ca.log(mu + r)))
    phi = ca.if_else(ca.mmin(s_b) > 0, smooth + energy - mu * ca.sum1(ca.log(s_b)), ca.inf)
    tip = _bar_terms(arm, path[2 * (n + 1) : 2 * (n + 2)])[0] - target
    return ca.Function(
        f"reachirl_interior_barrier_{n}",
        [path, ws, y, arm, dt, fscale, mask, c, mu, lo, hi, vmax, target],
        [ca.vec(out), phi, ca.fabs(tip)],
    )


@functools.lru_cache(maxsize=8)
def _kkt_function(n: int) -> ca.Function:
    """One condensed primal-dual Newton step's system (module docstring) but its factorisation, in one function
    (compiled to C when :func:`reachirl.doc.compiled.compiled_function` can).

    Inputs: the stage function's output ``(82, n)`` (column-major), the stages with energy (1/0) and their ``c``,
    the split's ``y``, ``s±`` and ``z±`` (each ``(n,)``; on the stages without energy ``y = 0`` and the others 1),
    the bounds' slacks and duals (``(4, N−1, 2)`` row-major), ``∂s_b/∂q_k`` of each slack kind ``(4,)``, the bar's
    multiplier, ``μ``, ``q_{N−1}``, the arm and the bar. Outputs: the knots' system in LAPACK's LU storage
    (``(3·BW + 1, size)`` column-major; the bar's multiplier last), its right-hand side ``−(g, bar)``, the
    largest residual of the primal-dual equations at ``μ`` (stationarity in the knots and in ``s±``, the
    complementarity of the split and of the bounds), the split's condensed curvature ``D`` and right-hand side
    ``b`` per stage, and the bar's gradient."""
    lay = _lay(n)
    m = lay.m
    raw = ca.MX.sym("out", _ROWS * n)
    mask, c, y = ca.MX.sym("mask", n), ca.MX.sym("c", n), ca.MX.sym("y", n)
    sp, sm, zp, zm = (ca.MX.sym(name, n) for name in ("sp", "sm", "zp", "zm"))
    s_b, zb = ca.MX.sym("s_b", 4 * m), ca.MX.sym("zb", 4 * m)
    a = ca.MX.sym("a", 4)
    lam, mu, qn = ca.MX.sym("lam"), ca.MX.sym("mu"), ca.MX.sym("qn", 2)
    arm, target = ca.MX.sym("arm", len(ARM_FIELDS)), ca.MX.sym("target")
    out = ca.reshape(raw, _ROWS, n)
    de = out[73:81, :]
    tip, cj, ccurv = _bar_terms(arm, qn)
    r_sp, r_sm = c - y - zp, c + y - zm
    d = mask * (1.0 / (sp / zp + sm / zm))  # the split's curvature in the power, from z±/s±
    b = (mu - sm * zm - sm * r_sm) / zm - (mu - sp * zp - sp * r_sp) / zp  # the split itself is exact
    pairs = list(range(64))
    hess = out[8:72, :] + (de[[k // 8 for k in pairs], :] * de[[k % 8 for k in pairs], :]) * ca.repmat(d.T, 64, 1)
    g_loc = out[0:8, :] + de * ca.repmat((d * b).T, 8, 1)
    last = [m - 2, m - 1]
    g = _gather_sum(m, [(lay.g_rows, lay.g_src, 8 * n, ca.vec(g_loc)), (last, [0, 1], 2, lam * cj)])
    g = g - _bounds_gradient(a, mu / s_b, m)
    # the bounds' Hessian Aᵀ diag(z_b/s_b) A: a knot, and a knot with the one before it
    sig = zb / s_b
    s0, s1, s2, s3 = (sig[i * m : (i + 1) * m] for i in range(4))
    a2 = a**2
    hd = a2[0] * s0 + a2[1] * s1 + a2[2] * s2 + a2[3] * s3
    hd = ca.vertcat(hd[: m - 2] + (a2[2] * s2[2:] + a2[3] * s3[2:]), hd[m - 2 :])
    ho = -(a2[2] * s2[2:] + a2[3] * s3[2:])  # (q_{k+1}, q_k) for k = 1 … N−2
    ab = _gather_sum(
        lay.lu_size,
        [
            (lay.h_pos, lay.h_src, 64 * n, ca.vec(hess)),
            (lay.diag, range(m), m, hd),
            (lay.below, range(m - 2), m - 2, ho),
            (lay.above, range(m - 2), m - 2, ho),
            (lay.tip_block, range(4), 4, lam * ccurv),
            (lay.tip_col, range(2), 2, cj),
            (lay.tip_row, range(2), 2, cj),
        ],
    )
    grad = _gather_sum(m, [(lay.g_rows, lay.g_src, 8 * n, ca.vec(out[0:8, :])), (last, [0, 1], 2, lam * cj)])
    r_q = grad - _bounds_gradient(a, zb, m)
    error = ca.mmax(
        ca.vertcat(
            ca.fabs(r_q),
            mask * ca.fabs(r_sp),
            mask * ca.fabs(r_sm),
            mask * ca.fabs(sp * zp - mu),
            mask * ca.fabs(sm * zm - mu),
            ca.fabs(s_b * zb - mu),
        )
    )
    return ca.Function(
        f"reachirl_interior_kkt_{n}",
        [raw, mask, c, y, sp, sm, zp, zm, s_b, zb, a, lam, mu, qn, arm, target],
        [ab, -ca.vertcat(g, tip - target), error, d, b, cj],
    )


def preload(n: int) -> None:
    """Build (or load, compiled) this thread's functions of ``n`` stages: the barrier function and the step's
    system."""
    for build in (_barrier_function, _kkt_function):
        _workspace(build, n)


class _System(NamedTuple):
    """One step's system at an iterate (:meth:`_Reach.kkt`)."""

    ab: np.ndarray  # LAPACK's LU storage (3·BW + 1, size): the reach's buffer, overwritten by the next call
    rhs: np.ndarray  # −(the gradient in the knots, the bar)
    error: float  # the largest residual of the primal-dual equations
    d: np.ndarray  # the split's condensed curvature, on the stages with energy
    b: np.ndarray  # and its right-hand side
    cj: np.ndarray  # the bar's gradient


class _Reach:
    """One DOC on its knots: the task's constants, in the buffers of the two compiled functions every step calls
    (:func:`_barrier_function`, :func:`_kkt_function`), and the bounds' slacks."""

    def __init__(self, task: ReachingTask, weights: np.ndarray, q: np.ndarray, fscale: float | None) -> None:
        n = self.n = task.n_nodes
        self.lay = _lay(n)
        w_knot = np.asarray(weights, dtype=float)[_knot_windows(n, weights.shape[0])]  # (n, 7)
        self.dt = float(task.dt)
        self.q0 = np.asarray(task.q0, dtype=float)
        self.lo, self.hi, self.vmax = (np.asarray(a, dtype=float) for a in (task.q_lower, task.q_upper, task.qd_max))
        arm = _arm_params(task.arm)
        self.trigger, inputs, (self.out_flat, self.phi_out, self.tip_out) = _workspace(_barrier_function, n)
        self.path_in, ws_in, self.y_in, arm_in, dt_in, self.fs_in, mask_in, c_in, self.mu_in, *fixed = inputs
        ws_in[:] = np.vstack([w_knot.T, np.zeros(n)]).reshape(-1, order="F")  # σ = 0: the energy is the split's
        arm_in[:], dt_in[0], self.y_in[:], mask_in[:], c_in[:] = arm, self.dt, 0.0, 0.0, 0.0
        for buffer, value in zip(fixed, (self.lo, self.hi, self.vmax, task.target_x), strict=True):
            buffer[:] = value
        self.act = np.zeros(0, dtype=int)
        if fscale is None:  # 1 / the start's cost: an objective of order one
            self.fs_in[0] = 1.0
            cost = float(np.sum(self.evaluate(q, np.zeros(0), MU_START)[0][_ROWS - 1]))
            fscale = 1.0 / cost if math.isfinite(cost) and cost > 1e-300 else 1.0
        self.fscale = self.fs_in[0] = fscale
        w_e = fscale * self.dt * w_knot[:, 1]
        act = np.flatnonzero(w_e > 0)
        self.act = act[act > 0]  # the stages with an energy term (stage 0's power is zero: q̇_0 = 0)
        self.c = w_e[self.act]
        mask_in[self.act], c_in[self.act] = 1.0, self.c
        self.kkt_trigger, k_in, (self.ab_out, self.rhs_out, self.err_out, self.d_out, self.b_out, self.cj_out) = (
            _workspace(_kkt_function, n)
        )
        self.k_raw, k_mask, k_c, *self.k_split, self.k_sb, self.k_zb, k_a, self.k_lam, self.k_mu, self.k_qn = k_in[:14]
        k_arm, k_target = k_in[14:]
        k_mask[:], k_c[:] = mask_in, c_in
        for buffer in self.k_split:  # y, s±, z± off the stages with energy: y = 0, the others 1
            buffer[:] = 1.0
        self.k_split[0][:] = 0.0
        # ∂s_b/∂q_k of each slack kind (q − lo, hi − q, vmax − q̇, vmax + q̇); ∂/∂q_{k−1} is minus the speeds'
        k_a[:], k_arm[:], k_target[0] = [1.0, -1.0, -1.0 / self.dt, 1.0 / self.dt], arm, task.target_x

    def evaluate(self, q: np.ndarray, y: np.ndarray, mu: float) -> tuple[np.ndarray, float, float]:
        """At the inner knots ``q (N−1, 2)``, with the split's multipliers ``y`` on the stages :attr:`act`: the
        stage function's output ``(82, n)`` (the Lagrangian ``f + Σ y_k e_k``), the barrier function at ``μ``
        without the bar's penalty (infinite outside the bounds) and the bar's ``|P_x − target|``
        (:func:`_barrier_function`)."""
        self.path_in[:] = _path(self.q0, q)
        self.y_in[self.act] = y
        self.mu_in[0] = mu
        self.trigger()
        return self.out_flat.reshape(_ROWS, self.n, order="F").copy(), float(self.phi_out[0]), float(self.tip_out[0])

    def kkt(self, x: _Iterate, mu: float) -> _System:
        """The step's system at ``x`` (:func:`_kkt_function`)."""
        self.k_raw[:] = x.out.reshape(-1, order="F")
        for buffer, value in zip(self.k_split, (x.y, x.sp, x.sm, x.zp, x.zm), strict=True):
            buffer[self.act] = value
        self.k_sb[:], self.k_zb[:] = x.s_b.reshape(-1), x.zb.reshape(-1)
        self.k_lam[0], self.k_mu[0], self.k_qn[:] = x.lam, mu, x.q[-1]
        self.kkt_trigger()
        act = self.act
        return _System(
            self.ab_out.reshape(3 * _BW + 1, self.lay.size, order="F"),
            self.rhs_out.copy(),
            float(self.err_out[0]),
            self.d_out[act],
            self.b_out[act],
            self.cj_out.copy(),
        )

    def slacks(self, q: np.ndarray) -> np.ndarray:
        """The bounds' slacks ``(4, N−1, 2)``: ``q − lo``, ``hi − q``, ``vmax − q̇``, ``vmax + q̇``."""
        s = np.empty((4, self.n - 1, 2))
        v = s[3]
        v[0] = q[0] - self.q0
        np.subtract(q[1:], q[:-1], out=v[1:])
        v /= self.dt
        np.subtract(self.vmax, v, out=s[2])
        v += self.vmax
        np.subtract(q, self.lo, out=s[0])
        np.subtract(self.hi, q, out=s[1])
        return s


@dataclass
class _Iterate:
    """The method's point: the inner knots ``q``, the stage function's output there, the barrier function (at the
    current ``μ``, without the bar's penalty) and the bar's ``|P_x − target|``, the energy split's slacks ``s±``,
    duals ``z±`` and multipliers ``y`` (on the stages with energy), the bounds' slacks and duals, the bar's
    multiplier."""

    q: np.ndarray
    out: np.ndarray
    phi: float
    tip: float
    sp: np.ndarray
    sm: np.ndarray
    s_b: np.ndarray
    zp: np.ndarray | None = None  # None until :meth:`center` sets the duals
    zm: np.ndarray | None = None
    y: np.ndarray | None = None
    zb: np.ndarray | None = None
    lam: float = 0.0

    def center(self, reach: _Reach, mu: float) -> None:
        """The duals at their central values for the slacks (``z = μ / s``, ``y = c − z⁺``), the stages' output
        evaluated at the new ``y``."""
        self.zp, self.zm, self.zb = mu / self.sp, mu / self.sm, mu / self.s_b
        self.y = reach.c - self.zp
        self.out, self.phi, self.tip = reach.evaluate(self.q, self.y, mu)


def interior_solve(
    task: ReachingTask, weights: np.ndarray, q_start: np.ndarray, fscale: float | None = None, max_iter: int = MAX_ITER
) -> NewtonResult | None:
    """The DOC's optimum from the joint path ``q_start (N+1, 2)`` (strictly inside the joint limits and the speed
    bound), or None when the method cannot vouch for it (module docstring). ``weights (n_windows, 7)``;
    ``fscale``: the objective's scale, by default ``1 / cost`` of the start (the tolerances are relative to an
    objective of order one)."""
    q = np.array(q_start[1 : task.n_nodes], dtype=float)
    reach = _Reach(task, weights, q, fscale)
    s_b = reach.slacks(q)
    if np.any(s_b <= 0):
        return None
    mu = MU_START
    out, phi, tip = reach.evaluate(q, np.zeros(reach.act.size), mu)
    sp, sm = _split(out[72, reach.act], reach.c, mu)
    x = _Iterate(q, out, phi, tip, sp, sm, s_b)
    x.center(reach, mu)  # the duals start at their central values
    nu, delta, central, m0, it = 0.0, 0.0, False, None, 0
    while True:
        system = reach.kkt(x, mu)
        solved = system.error <= max(10.0 * mu, TOL) and x.tip < BAR_TOL
        if not solved:
            if it >= max_iter:
                return None
            step = _step(reach, x, system, delta)
            if step is None:
                return None
            dq, dlam, dx, dy, dzp, dzm, delta = step
            ds_b = reach.slacks(x.q + dq) - x.s_b
            dzb = mu / x.s_b - x.zb - x.zb / x.s_b * ds_b
            # the bar's penalty: above its new multiplier, set afresh each step (design-notes, "the bar's penalty")
            nu_new = 2.0 * abs(x.lam + dlam) + 1e-3
            if m0 is None or nu_new != nu:
                nu = nu_new
                m0 = x.phi + nu * x.tip
            dm = _slope(reach, x, mu, nu, dx, ds_b)
            solved = dm > -1e-13 * max(1.0, abs(m0))  # nothing left to gain above round-off
            if solved and dm > 1e-10:  # uphill: the duals' own step; again with the duals at their centre
                if central:
                    return None
                x.center(reach, mu)
                central, m0 = True, None
                continue
        if solved:
            if mu <= MU_END:
                if delta > 0.0:
                    return None  # a saddle or a maximum: the Hessian needed regularising at the end
                return _result(x, reach, it)
            mu = max(MU_END, min(0.2 * mu, mu**1.5))
            x.sp, x.sm = _split(x.out[72, reach.act], reach.c, mu)
            x.out, x.phi, x.tip = reach.evaluate(x.q, x.y, mu)  # the barrier function at the new μ
            central, m0 = False, None
            continue
        it += 1
        alpha_d = min(_to_boundary(x.zp, dzp), _to_boundary(x.zm, dzm), _to_boundary(x.zb.ravel(), dzb.ravel()))
        alpha = _to_boundary(x.s_b.ravel(), ds_b.ravel())
        for _ in range(30):  # backtracking (Armijo) on the barrier function
            q_try = x.q + alpha * dq
            out_try, phi_try, tip_try = reach.evaluate(q_try, x.y + alpha * dy, mu)
            m_try = phi_try + nu * tip_try
            if math.isfinite(m_try) and m_try <= m0 + _ARMIJO * alpha * dm:
                break
            alpha *= 0.5
        else:
            return None
        x.q, x.out, x.phi, x.tip, m0 = q_try, out_try, phi_try, tip_try, m_try
        x.lam += alpha * dlam
        x.y = x.y + alpha * dy
        x.zp, x.zm, x.zb = x.zp + alpha_d * dzp, x.zm + alpha_d * dzm, x.zb + alpha_d * dzb
        x.s_b = reach.slacks(x.q)
        x.sp, x.sm = _split(x.out[72, reach.act], reach.c, mu)  # the split exact again
        central = False


def _slope(reach: _Reach, x: _Iterate, mu: float, nu: float, dx: np.ndarray, ds_b: np.ndarray) -> float:
    """The barrier function's directional derivative along the step (``dx (8, n)``: each stage's knots' step;
    ``ds_b``: the bounds' slacks' step); the step meets the linearised bar, so ``ν |bar|`` falls by itself."""
    e, de = x.out[72, reach.act], x.out[73:81, reach.act]
    slope = x.out[0:8].copy()
    slope[:, reach.act] += de * (_energy_barrier(e, reach.c, mu)[1] - x.y)  # the Lagrangian's y e taken out
    return float(np.sum(slope * dx)) - mu * float(np.sum(ds_b / x.s_b)) - nu * x.tip


def _step(reach: _Reach, x: _Iterate, system: _System, last: float):
    """One condensed primal-dual Newton step (module docstring) from ``system`` (:meth:`_Reach.kkt` at ``x``):
    ``(dq, dλ, dx, dy, dz⁺, dz⁻, δ)``, with ``dx (8, n)`` the stages' local steps and ``δ`` the regularisation used
    (tried from ``last / 3`` after a regularised step, as IPOPT does); None if the factorisations fail."""
    lay, act, c = reach.lay, reach.act, reach.c
    m, n = lay.m, reach.n
    ab, d, b = system.ab, system.d, system.b
    delta = _regularisation(ab, m, system.cj, last)
    if delta is None:
        return None
    ab[2 * _BW, :m] += delta
    step = system.rhs  # the system's own copy (_Reach.kkt), solved in place
    info = banded.solve(_BW, _BW, ab, step)
    if info != 0 or not np.all(np.isfinite(step)):
        return None
    dpath = np.zeros(2 * (n + 3))
    dpath[6 : 6 + m] = step[:m]
    dpath[-2:] = step[m - 2 : m]  # q_N = q_{N−1}
    dx = dpath[lay.gather].reshape(8, n, order="F")
    de = x.out[73:81, act]
    dy = d * (np.sum(de * dx[:, act], axis=0) + b)
    r_sp, r_sm = c - x.y - x.zp, c + x.y - x.zm
    return step[:m].reshape(-1, 2), float(step[m]), dx, dy, r_sp - dy, r_sm + dy, delta


def _regularisation(ab: np.ndarray, m: int, cj: np.ndarray, last: float) -> float | None:
    """The smallest ``δ`` tried (0, then from ``last / 3`` or 1e-10 of the diagonal, growing eightfold) that makes
    the knots' Hessian in the LU storage ``ab`` plus ``δI`` positive definite on the bar's null space: a banded
    Cholesky of ``H + δI + ρ ĉĉᵀ`` (``ĉ`` the bar's unit gradient ``cj``, ``ρ`` a thousand times the largest
    diagonal entry); None if 40 tries do not."""
    upper = ab[_BW : 2 * _BW + 1, :m].copy()  # the upper band, diagonal last, as LAPACK's dpbtrf reads it
    scale = max(1.0, float(np.max(np.abs(upper[_BW]))))
    u = cj / max(float(np.hypot(cj[0], cj[1])), 1e-300)
    rho = 1e3 * scale
    upper[_BW, m - 2] += rho * u[0] ** 2
    upper[_BW, m - 1] += rho * u[1] ** 2
    upper[_BW - 1, m - 1] += rho * u[0] * u[1]
    delta = 0.0
    for k in range(40):
        trial = upper.copy()
        trial[_BW] += delta
        if _pbtrf(trial, lower=0)[1] == 0:
            return delta
        delta = last / 3.0 if k == 0 and last > 0 else max(1e-10 * scale, 8.0 * delta)
    return None


def _result(x: _Iterate, reach: _Reach, it: int) -> NewtonResult:
    """The answer as :mod:`.newton`'s result: the knots ``(N+1, 2)``, the steps, the corners (stages whose power is
    below a thousandth of its largest), the scale, the bar's multiplier and the objective (unscaled, with the
    exact ``|e|``: the stages' costs)."""
    e = np.abs(x.out[72, reach.act])
    return NewtonResult(
        q=np.vstack([reach.q0, x.q, x.q[-1:]]),
        iterations=it,
        n_kinks=int(np.sum(e < 1e-3 * max(float(e.max(initial=0.0)), 1e-300))),
        fscale=float(reach.fscale),
        bar_multiplier=float(x.lam),
        cost=float(np.sum(x.out[_ROWS - 1])) / float(reach.fscale),
    )
