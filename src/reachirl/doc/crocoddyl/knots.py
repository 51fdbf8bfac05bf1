"""The knot of the Crocoddyl shooting problem: its action model, the reaching cost and its derivatives."""

from __future__ import annotations

import math

import crocoddyl
import numpy as np

from ...features import FEATURES

# Feature -> the Crocoddyl cost items that carry it (built-in, inside each knot's CostModelSum).
CROCODDYL_COST_ITEMS: dict[str, tuple[str, ...]] = {
    "cartesian_velocity": ("cartesian_velocity",),
    "geodesic": ("geodesic", "geodesic/forearm"),
    "joint_acceleration": ("joint_acceleration",),
    "joint_velocity": ("joint_velocity",),
    "joint_torque": ("joint_torque",),
}
_J_ENERGY = FEATURES.index("energy")
_J_TORQUE_CHANGE = FEATURES.index("torque_change")
_NX, _NU = 6, 2  # augmented state (q, q̇, τ_prev) and control τ


class KnotData(crocoddyl.ActionDataAbstract):
    """The knot's data, with numpy views of its own and the inner model's arrays made once (the arrays never
    move): each eigenpy attribute access builds a new view (~1 µs), and copying into a ready view with
    ``np.copyto`` costs half of a sliced assignment."""

    def __init__(self, model: KnotModel):
        crocoddyl.ActionDataAbstract.__init__(self, model)
        self.inner = di = model.inner.createData()
        self.Fu[4:, :] = np.eye(_NU)  # τ_prev at the next knot is this knot's τ
        Fx, Fu, Lx, Lu, Lxx, Lxu, Luu = self.Fx, self.Fu, self.Lx, self.Lu, self.Lxx, self.Lxu, self.Luu
        self.xnext_, self.g_, self.Lx_, self.Lu_, self.Lxx_, self.Lxu_, self.Luu_ = (
            self.xnext,
            self.g,
            Lx,
            Lu,
            Lxx,
            Lxu,
            Luu,
        )
        # (destination view, source view) pairs copied after the inner model's calcDiff
        self.copies_running = [
            (Fx[:4, :4], di.Fx),
            (Fu[:4], di.Fu),
            (Lx[:4], di.Lx),
            (Lu, di.Lu),
            (Lxx[:4, :4], di.Lxx),
            (Lxu[:4], di.Lxu),
            (Luu, di.Luu),
        ]
        self.copies_terminal = [(Lx[:4], di.Lx), (Lxx[:4, :4], di.Lxx)]
        if model.n_constraints:
            self.copies_running += [(self.Gx[:, :4], di.Gx), (self.Gu, di.Gu)]
            self.copies_terminal.append((self.Gx[:, :4], di.Gx))
        self.inner_xnext, self.inner_g = di.xnext, di.g
        self.xnext4, self.xnext_tau = self.xnext[:4], self.xnext[4:]


class KnotSettings:
    """What the Python knot and the compiled one (:mod:`reachirl.doc.crocoddyl.native`) share: the handles on
    the inner model and its cost items, and setting the knot's time step and weights."""

    def _settings(self, inner, first: bool, n_constraints: int) -> None:
        self.inner = inner
        self.dam = inner.differential
        self.costs = self.dam.costs
        self.first = first
        self.n_constraints = n_constraints
        # keep the cost items (shared with the C++ sum) to change their weights without a map lookup
        self._items = (
            {name: self.costs.costs[name] for names in CROCODDYL_COST_ITEMS.values() for name in names}
            if not self.terminal
            else {}
        )

    def set_dt(self, dt: float) -> None:
        self.dt = float(dt)
        if not self.terminal:
            self.inner.dt = self.dt

    def set_weights(self, w: np.ndarray) -> None:
        """This knot's row of ω (7 numbers in FEATURES order)."""
        for feature, names in CROCODDYL_COST_ITEMS.items():
            weight = 2.0 * float(w[FEATURES.index(feature)])
            for name in names:
                self._items[name].weight = weight
        self.w_energy = float(w[_J_ENERGY])
        self.w_torque_change = float(w[_J_TORQUE_CHANGE])


class KnotModel(KnotSettings, crocoddyl.ActionModelAbstract):
    """One knot of the reach with the augmented state ``x = (q, q̇, τ_prev)`` and control ``u = τ``.

    ``inner`` is the knot's ``IntegratedActionModelEuler`` on ``(q, q̇)``; it holds the built-in costs (its
    differential model's ``costs``) and constraints. This model adds ``energy`` and ``torque_change`` and owns
    the constraint bounds ``g_lb``/``g_ub``. Set the knot's weights with :meth:`set_weights`.
    """

    def __init__(self, inner, first: bool, terminal: bool, energy_smoothing: float):
        dam = inner.differential
        ng = int(dam.constraints.ng) if dam.constraints is not None else 0
        crocoddyl.ActionModelAbstract.__init__(self, crocoddyl.StateVector(_NX), _NU, 1, ng, 0)
        self.terminal = terminal
        self.eps = float(energy_smoothing)
        self.exact_hessian = False
        self.dt = float(inner.dt)
        self.w_energy = 0.0
        self.w_torque_change = 0.0
        self._settings(inner, first, ng)

    def createData(self):  # noqa: N802  (Crocoddyl's API)
        return KnotData(self)

    # Crocoddyl calls calc(data, x) on the terminal knot and calc(data, x, u) on the others.
    def calc(self, data, x, u=None):
        di = data.inner
        if u is None or self.terminal:
            self.inner.calc(di, x[:4])
            data.cost = di.cost
            np.copyto(data.xnext_, x)
        else:
            self.inner.calc(di, x[:4], u)
            cost = di.cost
            if self.w_energy > 0.0 or self.w_torque_change > 0.0:
                _, _, v0, v1, p0, p1 = x.tolist()
                u0, u1 = u.tolist()
                if self.w_energy > 0.0:
                    r = v0 * u0 + v1 * u1
                    cost += self.w_energy * self.dt * (math.sqrt(r * r + self.eps * self.eps) - self.eps)
                if self.w_torque_change > 0.0:
                    d0, d1 = u0 - p0, u1 - p1
                    cost += self.w_torque_change / self.dt * (d0 * d0 + d1 * d1)
            data.cost = cost
            np.copyto(data.xnext4, data.inner_xnext)
            np.copyto(data.xnext_tau, u)
        if self.n_constraints:
            np.copyto(data.g_, data.inner_g)

    def calcDiff(self, data, x, u=None):  # noqa: N802  (Crocoddyl's API)
        di = data.inner
        if u is None or self.terminal:
            self.inner.calcDiff(di, x[:4])
            for dst, src in data.copies_terminal:
                np.copyto(dst, src)
            return
        self.inner.calcDiff(di, x[:4], u)
        for dst, src in data.copies_running:
            np.copyto(dst, src)
        Lx, Lu, Lxx, Lxu, Luu = data.Lx_, data.Lu_, data.Lxx_, data.Lxu_, data.Luu_
        # the two Python terms, in scalars (numpy calls on 2-vectors cost more than the arithmetic)
        _, _, v0, v1, p0, p1 = x.tolist()
        u0, u1 = u.tolist()
        if self.w_energy > 0.0:
            r = v0 * u0 + v1 * u1
            s = math.sqrt(r * r + self.eps * self.eps)
            c = self.w_energy * self.dt
            d1 = c * r / s  # first and second derivative of the smooth |r|
            d2 = c * self.eps * self.eps / (s * s * s)
            Lx[2] += d1 * u0
            Lx[3] += d1 * u1
            Lu[0] += d1 * v0
            Lu[1] += d1 * v1
            # Gauss-Newton, like Crocoddyl's residual costs: the term d1·∂²r/∂q̇∂τ = d1·I is left out
            a, b, e = d2 * u0 * u0, d2 * u0 * u1, d2 * u1 * u1
            Lxx[2, 2] += a
            Lxx[2, 3] += b
            Lxx[3, 2] += b
            Lxx[3, 3] += e
            h = d1 if self.exact_hessian else 0.0  # d1·∂²r/∂q̇∂τ = d1·I
            Lxu[2, 0] += d2 * u0 * v0 + h
            Lxu[2, 1] += d2 * u0 * v1
            Lxu[3, 0] += d2 * u1 * v0
            Lxu[3, 1] += d2 * u1 * v1 + h
            a, b, e = d2 * v0 * v0, d2 * v0 * v1, d2 * v1 * v1
            Luu[0, 0] += a
            Luu[0, 1] += b
            Luu[1, 0] += b
            Luu[1, 1] += e
        # always written (τ_prev's entries are not copied from the inner model, and a weight may become 0)
        c = 2.0 * self.w_torque_change / self.dt
        d0, d1 = c * (u0 - p0), c * (u1 - p1)
        Lx[4], Lx[5] = -d0, -d1
        Lxx[4, 4] = Lxx[5, 5] = c
        Lxu[4, 0] = Lxu[5, 1] = -c
        if c > 0.0:
            Lu[0] += d0
            Lu[1] += d1
            Luu[0, 0] += c
            Luu[1, 1] += c
