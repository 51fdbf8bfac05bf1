"""CasADi backend of the reaching DOC: stage-wise multiple shooting, solved by fatrop (IPOPT as the fallback).

Formulation (exactly the problem of :mod:`reachirl.doc.task`):

* Multiple shooting on the ``N`` Euler intervals, stage by stage. The state of knot ``k`` is
  ``x_k = (q_k, q̇_k, τ_{k−1})`` (6) and the control of interval ``k`` is ``u_k = (q̈_k, s⁺_k, s⁻_k)`` (4).
  Stage 0 is known but for ``q̈_0`` (``q_0 = q0``, ``q̇_0 = 0``, no energy), so the decision vector is
  ``(q̈_0, x_1, u_1, …, x_{N−1}, u_{N−1}, x_N)``. The arm is fully actuated: the torque is the inverse
  dynamics ``τ_k = M(q_k) q̈_k + b(q_k, q̇_k)``, the exact inverse of the Euler step with
  ``q̈_k = M⁻¹(τ_k − b)``. Carrying ``τ_{k−1}`` in the state makes the torque-change term
  ``‖(τ_k − τ_{k−1})/dt‖²`` depend on one stage only; on interval 0, ``τ_{−1} = g(q0)`` (the arm held at rest, as
  in :mod:`reachirl.features`).
* The constraints of stage ``k`` are, in this order, the gap
  ``x_{k+1} = (q_k + dt(q̇_k + dt q̈_k), q̇_k + dt q̈_k, τ_k)`` (first: fatrop detects the stages from it)
  and the exact slack form of the energy ``|q̇_kᵀτ_k|``: ``q̇_kᵀτ_k − s⁺_k + s⁻_k = 0``, ``s± ≥ 0``. The terminal
  constraints are ``q̇_N = 0`` and the fingertip on the bar, ``P_x(q_N) = target``. Joint limits and the speed
  bound are variable bounds. No variable is fixed by equal bounds (fatrop's stage detection would then need
  far more iterations).
* The arm's parameters, ``q0``, the target, ``dt``, the objective scale and the weights are NLP *parameters*:
  one NLP is built per number of knots ``N``, cached, and reused for every arm, task and weight. The weights
  enter per knot (``N × 7``, each knot's row its window's weights), so 1, 6 or 8 windows share one NLP (and one
  compiled solver, :mod:`reachirl.doc.compiled`).
* The objective is normalised by the cost of the starting point, so the solvers see an order-one objective.
* The returned trajectory is rebuilt from the knots ``q_k``: ``q̇`` by differences, ``τ`` by inverse dynamics,
  the final posture moved onto the bar to machine precision (the solvers meet constraints to their
  feasibility tolerance), and the cost is :func:`reachirl.features.trajectory_cost` of the returned
  trajectory: the NLP objective there with exact slacks (tested against an independent Pinocchio
  computation), without a second evaluation of the symbolic objective.

Solvers (the measurements behind the choice are in ``docs/design-notes.md``, "DOC solvers"):

* **fatrop** (``structure_detection="auto"``) exploits the stage structure with a Riccati recursion; its initial
  barrier parameter is 1e-4 (:data:`FATROP_OPTIONS`).
* The cold and the warm fatrop solvers are compiled to C on long runs (:mod:`reachirl.doc.compiled`, once per
  number of knots and machine, cached on disk), with bit-identical results.
* fatrop takes no initial multipliers (CasADi passes it the primal point only), so a warm start is the
  previous primal point with a small initial barrier parameter and bound push (:data:`FATROP_WARM_OPTIONS`).
* **IPOPT** (:data:`IPOPT_OPTIONS`) is the fallback: a cold fatrop solve that does not converge is solved
  again cold with IPOPT.
* With ``newton`` (:func:`solve`), exact Newton on the knots (:mod:`reachirl.doc.newton`) comes first, from the
  same start, and with ``interior`` a warm start Newton gives way on goes to the interior point on the knots
  (:mod:`reachirl.doc.interior`); each answers only when it can vouch for its answer, and fatrop (then IPOPT)
  solves the rest.
"""

from __future__ import annotations

import functools
import hashlib
import json
import threading
import time
from pathlib import Path

import casadi as ca
import numpy as np

from ..errors import solver_interrupts
from ..features import N_FEATURES, euler_knots, trajectory_cost, window_index
from . import compiled, interior, newton
from .interior import interior_solve
from .newton import newton_solve
from .symbolic import ARM_FIELDS, fingertip, fingertip_jacobian, inverse_dynamics, mass_matrix
from .task import (
    DocSolution,
    ReachingTask,
    check_warm_start_knots,
    min_jerk,
    on_bar,
    rest_to_rest_knots,
    warm_start_key,
)

__all__ = [
    "FATROP_OPTIONS",
    "FATROP_WARM_OPTIONS",
    "IPOPT_OPTIONS",
    "build_nlp",
    "guess_knots",
    "initial_guess",
    "preload",
    "prepare",
    "solve",
]

NX, NU = 6, 4  # state (q, q̇, τ_prev) and control (q̈, s⁺, s⁻) sizes

# IPOPT (the fallback). Tuned on the former positions-only form and kept on this one:
# * the objective is normalised by the initial guess's cost and IPOPT's gradient scaling is capped at 1;
# * tol 1e-6 on that order-one objective, with feasibility kept at 1e-9;
# * the adaptive barrier halves the iterations of the monotone one.
IPOPT_OPTIONS: dict = {
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "print_time": False,
    "calc_lam_p": False,
    "ipopt.tol": 1e-6,
    "ipopt.acceptable_tol": 1e-5,
    "ipopt.acceptable_iter": 3,
    "ipopt.constr_viol_tol": 1e-9,
    "ipopt.max_iter": 1000,
    "ipopt.mu_strategy": "adaptive",
    "ipopt.nlp_scaling_max_gradient": 1.0,
    "ipopt.linear_solver": "mumps",
}
IPOPT_WARM_OPTIONS: dict = {
    "ipopt.max_iter": 100,
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-6,
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_bound_frac": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_frac": 1e-9,
}
WARM_OPTIONS = IPOPT_WARM_OPTIONS  # former name

# fatrop (the default), measured on the benchmark problems (cold, and warm after a 10 % weight change):
# * tolerance 1e-6 on the order-one objective, as IPOPT's: the default 1e-8 took 25 instead of 20 iterations
#   and failed 2 of 10 problems (it stalls with inertia corrections once the barrier parameter is at 1e-9);
# * a faster linear decrease of its monotone barrier parameter (0.1 instead of 0.2): 18 iterations, 20/20;
# * warm: the previous primal point, mu_init 1e-5 and a bound push of 1e-7 (12 iterations instead of 20 with
#   the cold options); a smaller mu_init (1e-7 … 1e-9) took as many or more iterations.
FATROP_OPTIONS: dict = {
    "print_time": False,
    "calc_lam_p": False,
    "expand": True,
    "structure_detection": "auto",
    "fatrop.print_level": 0,
    "fatrop.tolerance": 1e-6,
    # no "acceptable level" stop: fatrop 1.1.8 (CasADi 3.8) reports it with the same return code as an exceeded
    # iteration limit, unsuccessful, so a reach that had in fact converged was solved again by IPOPT (a third of
    # the cold solves at the built-in truth's weights, 1.5x their time); with tol_acceptable = tolerance the
    # solver stops only at the tolerance, one iteration later on those reaches
    "fatrop.tol_acceptable": 1e-6,
    "fatrop.mu_linear_decrease_factor": 0.1,
    # a small initial barrier parameter (fatrop's default is 0.1): the minimum-jerk start is interior and close
    # enough. On 612 predictions of the learned-weight sweep (benchmarks/learned_weights.json, every 3rd):
    # 16.3 -> 13.8 iterations, 18.9 -> 16.0 ms, all converged, at the same optima (q within 0.02 deg, cost
    # within 2e-5); 1e-5 and 1e-6 were no better
    "fatrop.mu_init": 1e-4,
    "fatrop.max_iter": 200,
}
FATROP_WARM_OPTIONS: dict = {
    "fatrop.mu_init": 1e-5,
    "fatrop.bound_push": 1e-7,
    "fatrop.bound_frac": 1e-7,
    "fatrop.max_iter": 60,  # a warm start that has not converged by then is worse than a cold one
}
_FATROP_SLOT = {"fatrop": "cold", "fatrop_warm": "warm"}  # each fatrop solver's compiled slot (reachirl.doc.compiled)

_BOUNDS_KEPT = 32  # sets of joint limits whose bounds an NLP keeps (~16 kB each at N = 100)


class _Nlp:
    """The NLP of a number of knots, with its solvers (built lazily, each used under ``lock``). Its symbolic graph
    (:attr:`nlp`) is built on first use: a process whose compiled solvers are cached never needs it."""

    def __init__(self, n: int):
        self.n = n
        self.n_z = 2 + (n - 1) * (NX + NU) + NX  # q̈_0, (x_k, u_k) for k = 1 … N−1, x_N
        self.n_g = n * NX + (n - 1) + 2 + 1  # the gaps, the energy splits, q̇_N = 0 and the bar
        self._solvers: dict = {}
        self._bounds: dict = {}
        self.lock = threading.Lock()
        self.slots = {
            kind: compiled.Slot(n, lambda: self.nlp, spec, kind=kind, recipe=_recipe(n, spec))
            for kind, spec in (("cold", self.cold_solver_spec()), ("warm", self.warm_solver_spec()))
        }

    @property
    def nlp(self) -> dict:
        """CasADi's NLP dict ``{"x", "p", "f", "g"}``."""
        return self._graph["nlp"]

    @property
    def objective(self):
        """The NLP's objective as a ``casadi.Function`` of ``(z, p)``."""
        return self._graph["objective"]

    @functools.cached_property
    def _graph(self) -> dict:
        n = self.n
        arm = ca.SX.sym("arm", len(ARM_FIELDS))
        q0 = ca.SX.sym("q0", 2)
        target = ca.SX.sym("target")
        dt = ca.SX.sym("dt")
        fscale = ca.SX.sym("fscale")  # objective normalisation: 1 / (cost of the starting point)
        w = ca.SX.sym("w", n * N_FEATURES)  # row-major (knot, feature): each knot's window's weights
        arm_l = [arm[i] for i in range(len(ARM_FIELDS))]

        # stage 0: the state (q0, q̇_0 = 0, no τ_prev) is known, so only q̈_0 is a variable
        xs = [None] + [ca.SX.sym(f"x{k}", NX) for k in range(1, n + 1)]
        us = [ca.SX.sym("u0", 2)] + [ca.SX.sym(f"u{k}", NU) for k in range(1, n)]
        z_blocks: list = [us[0]]
        obj = 0
        g: list = []
        for k in range(n):
            if k == 0:  # at rest before the reach: τ_{−1} = g(q0)
                q, qd = q0, ca.SX.zeros(2)
                tau_prev = inverse_dynamics(arm_l, q0, ca.SX.zeros(2), ca.SX.zeros(2))
                qdd, sp, sm = us[0], 0, 0
            else:
                x, u = xs[k], us[k]
                q, qd, tau_prev = x[0:2], x[2:4], x[4:6]
                qdd, sp, sm = u[0:2], u[2], u[3]
                z_blocks += [x, u]
            tau = inverse_dynamics(arm_l, q, qd, qdd)
            qd_next = qd + dt * qdd
            # the gap first: fatrop's structure detection starts a stage at it
            g.append(xs[k + 1] - ca.vertcat(q + dt * qd_next, qd_next, tau))
            if k > 0:
                g.append(ca.dot(qd, tau) - sp + sm)
            jac = fingertip_jacobian(arm_l, q)
            wk = w[k * N_FEATURES : (k + 1) * N_FEATURES]
            rates = [
                ca.sumsqr(jac @ qd),
                sp + sm,
                ca.bilin(mass_matrix(arm_l, q), qd, qd),
                ca.sumsqr(qdd),
                ca.sumsqr((tau - tau_prev) / dt),
                ca.sumsqr(qd),
                ca.sumsqr(tau),
            ]
            obj += dt * sum(wk[j] * rates[j] for j in range(N_FEATURES))
        z_blocks.append(xs[n])
        g.append(xs[n][2:4])  # q̇_N = 0 (a constraint: fatrop handles fixed bounds badly)
        g.append(fingertip(arm_l, xs[n][0:2])[0] - target)
        z = ca.vertcat(*z_blocks)
        gg = ca.vertcat(*g)
        if (z.numel(), gg.numel()) != (self.n_z, self.n_g):  # pragma: no cover - the counts above are the layout's
            raise AssertionError(f"the NLP has {z.numel()} variables and {gg.numel()} constraints")
        p = ca.vertcat(arm, q0, target, dt, fscale, w)
        nlp = {"x": z, "p": p, "f": fscale * obj, "g": gg}
        return {"nlp": nlp, "objective": ca.Function("objective", [z, p], [nlp["f"]])}

    def kkt_functions(self) -> dict:
        """CasADi functions of the KKT conditions (made on first use, for :mod:`reachirl.doc.sensitivity`):
        ``grad(z, p)`` = ∇_z f, ``A(z, p)`` = ∂g/∂z, ``H(z, p, λ)`` = ∇²_zz (f + λᵀg) and ``B(z, p)`` =
        ∂(∇_z f)/∂w (the per-knot weights, ``N × 7`` in row-major order). Loaded from the cache when an earlier
        process saved them (:func:`reachirl.doc.compiled.cached_functions`), else built from the NLP."""
        if "kkt" not in self._solvers:
            self._solvers["kkt"] = compiled.cached_functions(_recipe(self.n, ("kkt",)), self._kkt_build)
        return self._solvers["kkt"]

    def _kkt_build(self) -> dict:
        z, p, f, g = self.nlp["x"], self.nlp["p"], self.nlp["f"], self.nlp["g"]
        lam = ca.SX.sym("lam", g.numel())
        w = p[p.numel() - self.n * N_FEATURES :]
        grad = ca.gradient(f, z)
        return {
            "grad": ca.Function("kkt_grad", [z, p], [grad]),
            "A": ca.Function("kkt_A", [z, p], [ca.jacobian(g, z)]),
            "H": ca.Function("kkt_H", [z, p, lam], [ca.hessian(f + ca.dot(lam, g), z)[0]]),
            "B": ca.Function("kkt_B", [z, p], [ca.jacobian(grad, w)]),
        }

    def cold_solver_spec(self) -> tuple[str, str, dict]:
        """``(name, plugin, options)`` of the cold fatrop solver (the one :mod:`.compiled` compiles)."""
        return "doc_fatrop", "fatrop", {**FATROP_OPTIONS, "equality": [True] * self.n_g}

    def warm_solver_spec(self) -> tuple[str, str, dict]:
        """``(name, plugin, options)`` of the warm fatrop solver (the cold one's, with :data:`FATROP_WARM_OPTIONS`)."""
        _, plugin, opts = self.cold_solver_spec()
        return "doc_fatrop_warm", plugin, {**opts, **FATROP_WARM_OPTIONS}

    def fatrop(self, kind: str):
        """The ``"fatrop"`` (cold) or ``"fatrop_warm"`` solver: compiled when :mod:`.compiled` has (or makes)
        one, else CasADi's VM."""
        key = f"{kind}_compiled"
        if key not in self._solvers:
            solver = self.slots[_FATROP_SLOT[kind]].get()
            if solver is None:
                return self.solver(kind)
            self._solvers[key] = solver
        return self._solvers[key]

    def solver(self, kind: str):
        """``"fatrop"``, ``"fatrop_warm"``, ``"ipopt"`` or ``"ipopt_warm"`` on CasADi's VM; made on first use, and
        saved in the cache by the first process that makes it (:func:`reachirl.doc.compiled.cached_functions`:
        the others load it without building the NLP's graph)."""
        if kind not in self._solvers:
            if kind.startswith("fatrop"):
                name, plugin, opts = self.slots[_FATROP_SLOT[kind]].spec
            else:
                name, plugin, opts = f"doc_{kind}", "ipopt", dict(IPOPT_OPTIONS)
                if kind == "ipopt_warm":
                    opts.update(IPOPT_WARM_OPTIONS)
            recipe = _recipe(self.n, ("vm", name, plugin, opts))
            made = compiled.cached_functions(recipe, lambda: {name: ca.nlpsol(name, plugin, self.nlp, opts)})
            self._solvers[kind] = made[name]
        return self._solvers[kind]

    def params(self, task: ReachingTask, weights: np.ndarray, fscale: float) -> np.ndarray:
        a = task.arm
        arm = [getattr(a, f) for f in ARM_FIELDS]
        per_knot = weights[window_index(self.n, weights.shape[0])]  # (N, 7)
        return np.concatenate([arm, task.q0, [task.target_x, task.dt, fscale], per_knot.reshape(-1)])

    def bounds(self, task: ReachingTask) -> dict:
        """The variable and constraint bounds of ``task`` (read-only arrays, shared by every solve of the same
        joint limits and speed bound; the last :data:`_BOUNDS_KEPT` sets of limits are kept)."""
        key = (tuple(task.q_lower), tuple(task.q_upper), tuple(task.qd_max))
        found = self._bounds.get(key)
        if found is not None:
            return found
        inf = np.inf
        lb = np.r_[task.q_lower, -task.qd_max, -inf, -inf, -inf, -inf, 0.0, 0.0]
        ub = np.r_[task.q_upper, task.qd_max, inf, inf, inf, inf, inf, inf]
        out = {
            "lbx": np.r_[-inf, -inf, np.tile(lb, self.n - 1), lb[:NX]],
            "ubx": np.r_[inf, inf, np.tile(ub, self.n - 1), ub[:NX]],
            "lbg": np.zeros(self.n_g),
            "ubg": np.zeros(self.n_g),
        }
        for a in out.values():
            a.setflags(write=False)
        with self.lock:  # threads may share the NLP
            if len(self._bounds) >= _BOUNDS_KEPT:  # tasks with limits of their own: forget the oldest
                self._bounds.pop(next(iter(self._bounds)))
            self._bounds[key] = out
        return out


@functools.lru_cache(maxsize=1)
def _sources() -> bytes:
    """The code that builds the NLP and compiles its solvers (this module, the arm's symbolic equations, the
    features' count, :mod:`.compiled`); empty when it cannot be read."""
    here = Path(__file__).parent
    try:
        return b"\0".join(
            f.read_bytes()
            for f in (here / "casadi.py", here / "symbolic.py", here / "compiled.py", here.parent / "features.py")
        )
    except OSError:
        return b""


def _recipe(n: int, what: tuple) -> str:
    """A hash of the code that builds the NLP, CasADi's version, ``n`` and ``what`` (a solver's ``(name, plugin,
    options)``, or a name for functions made from the NLP): the cache's key of what is made from the NLP of ``n``
    knots, known without building it (:func:`reachirl.doc.compiled.remembered_path`,
    :func:`reachirl.doc.compiled.cached_functions`); empty when the code cannot be read."""
    code = _sources()
    if not code:
        return ""
    h = hashlib.sha256(code)
    h.update(json.dumps([ca.__version__, n, what], sort_keys=True, default=str).encode())
    return h.hexdigest()[:32]


@functools.lru_cache(maxsize=16)
def build_nlp(n: int) -> _Nlp:
    """The cached NLP of ``n`` knots (any number of windows)."""
    return _Nlp(n)


compiled.on_setting(build_nlp.cache_clear)  # each NLP holds its solvers: a change of compile mode drops them


def preload(n: int) -> None:
    """Load (or build) in this process what a solve on ``n`` knots uses: the cold and warm fatrop solvers (the
    compiled ones when cached) and the functions of Newton's and the interior point's steps (the banded LU's
    library among them). A worker does it before its first unit, while its coordinator is still starting."""
    nlp = build_nlp(n)
    for kind in _FATROP_SLOT:
        nlp.fatrop(kind)
    newton.preload(n)
    interior.preload(n)


def prepare(n: int) -> dict[str, bool]:
    """Compile and cache the cold and warm fatrop solvers of ``n`` knots where they are not cached yet, and wait
    (:func:`reachirl.doc.compiled.prepare`): ``{"cold": cached, "warm": cached}``."""
    return compiled.prepare(list(build_nlp(n).slots.values()))


def guess_knots(task: ReachingTask) -> np.ndarray:
    """The cold start's joint path, shape ``(N+1, 2)``: minimum jerk from ``q0`` to a posture with the
    fingertip on the bar, at the fingertip's starting height where reachable (within 98 % of the reach)."""
    arm, n = task.arm, task.n_nodes
    y0 = float(arm.fk(task.q0)[1])
    r_max = 0.98 * arm.length
    y_lim = np.sqrt(max(r_max**2 - task.target_x**2, 0.0))
    qf = arm.ik(np.array([task.target_x, np.clip(y0, -y_lim, y_lim)]))
    qf = np.clip(qf, task.q_lower + 1e-3, task.q_upper - 1e-3)
    s = min_jerk(np.linspace(0.0, 1.0, n + 1))[:, None]
    q = task.q0 + s * (qf - task.q0)
    q[-1] = q[-2]
    return q


def initial_guess(task: ReachingTask) -> np.ndarray:
    """A cold start (decision vector): the trajectory of :func:`guess_knots`."""
    return _pack(task, guess_knots(task))


def _pack(task: ReachingTask, q: np.ndarray) -> np.ndarray:
    """Decision vector of the trajectory through the knots ``q (N+1, 2)``, slacks ``s± = max(±q̇ᵀτ, 0)``.

    ``q_0`` is set to ``task.q0`` and ``q_{N−1}`` to ``q_N`` (``q̇_0 = q̇_N = 0``)."""
    return _pack_knots(task, *rest_to_rest_knots(task, q))


def _pack_knots(task: ReachingTask, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Decision vector of the knots ``(q, q̇, τ)`` of :func:`reachirl.doc.task.rest_to_rest_knots`."""
    n, dt = task.n_nodes, task.dt
    e = np.sum(qd[:-1] * tau, axis=1)
    z = np.zeros((n + 1, NX + NU))
    z[:, 0:2], z[:, 2:4] = q, qd
    z[1:, 4:6] = tau
    z[:n, 6:8] = np.diff(qd, axis=0) / dt
    z[:n, 8], z[:n, 9] = np.maximum(e, 0.0), np.maximum(-e, 0.0)
    return np.r_[z[0, 6:8], z[1:n].reshape(-1), z[n, :NX]]


def _unpack_q(task: ReachingTask, z: np.ndarray) -> np.ndarray:
    """Knots ``q (N+1, 2)`` of a decision vector."""
    n = task.n_nodes
    inner = np.asarray(z, dtype=float).reshape(-1)[2 : 2 + (NX + NU) * (n - 1)].reshape(n - 1, NX + NU)
    return np.vstack([task.q0, inner[:, 0:2], np.asarray(z)[-NX : -NX + 2]])


def _objective_scale(task: ReachingTask, weights: np.ndarray, z: np.ndarray) -> float:
    """``1 / cost`` of the starting point, so that the solver sees an objective of order one.

    No floor: a floor (it was 1e-8) made the objective of small weights tiny next to the solver's tolerance,
    and the solver then stopped "converged" far from the optimum. :func:`reachirl.doc.solve_doc` passes weights
    normalised to a maximum of 1, so the cost here is a physical quantity of order 1e-3 to 1e3."""
    q, qd, tau = euler_knots(task.arm, _unpack_q(task, z), task.dt)
    cost = trajectory_cost(task.arm, q, qd, tau, task.dt, weights)
    return 1.0 / cost if np.isfinite(cost) and cost > 1e-300 else 1.0


def _run(nlp: _Nlp, kind: str, args: dict) -> tuple[np.ndarray, dict, float]:
    """The solver's primal solution (a flat array), its stats and its wall time."""
    with nlp.lock:  # an nlpsol instance is not re-entrant
        solver = nlp.fatrop(kind) if kind.startswith("fatrop") else nlp.solver(kind)
        t0 = time.perf_counter()
        with solver_interrupts():  # Ctrl-C/SIGTERM stop the solver and are raised here, never a failed solve
            out = solver(**args)
        elapsed = time.perf_counter() - t0
        stats = solver.stats()
    return out["x"].full().reshape(-1), stats, elapsed


# fatrop's return flag, reported by CasADi as a number; only 0 is a success (see FATROP_OPTIONS)
_FATROP_STATUS = {0: "Success", 1: "MaxIterExceeded"}


def _status(kind: str, stats: dict) -> str:
    if kind in ("newton", "interior"):
        return f"{kind}: Success"
    status = str(stats.get("return_status", ""))
    if kind.startswith("fatrop"):
        try:
            status = _FATROP_STATUS.get(int(status), f"return flag {int(status)}")
        except ValueError:
            pass
    return f"{kind.split('_')[0]}: {status}"


def _converged(stats: dict, z: np.ndarray) -> bool:
    status = str(stats.get("return_status", ""))
    ok = bool(stats.get("success", False)) or status == "Solved_To_Acceptable_Level"
    return ok and bool(np.all(np.isfinite(z)))


def solve(
    task: ReachingTask,
    weights: np.ndarray,
    warm_start: DocSolution | None = None,
    retry_cold: bool = True,
    guess: np.ndarray | None = None,
    newton: bool = False,
    interior: bool = False,
) -> DocSolution:
    """Solve the DOC; warm from ``warm_start`` when it is the same task, cold when it is another task on the
    same knots, and cold again when the warm attempt fails and ``retry_cold``; a ``warm_start`` on another
    number of knots raises a ``ValueError``. A cold fatrop solve that fails is retried with IPOPT.

    With ``newton`` (predictions), a cold start from ``guess`` (a similar reach moved to this task) is first
    solved by exact Newton on the knots (:mod:`reachirl.doc.newton`), which either vouches for its answer or
    gives way to fatrop from the same start; so is a warm start (MO-IRL's line search, unless its
    ``warm_newton`` option is off). With ``interior`` too, a warm start that Newton gives way on (weights far from
    the warm start's: the uncertainty's checked samples) is solved by the interior point on the knots
    (:mod:`reachirl.doc.interior`) before fatrop.

    ``iterations`` and ``solve_time`` count every attempt.
    """
    check_warm_start_knots(task, warm_start)
    nlp = build_nlp(task.n_nodes)
    bounds = nlp.bounds(task)
    lbx, ubx = bounds["lbx"], bounds["ubx"]
    warm = warm_start.warm if warm_start is not None else None
    key = warm_start_key(task)
    iterations, elapsed, attempts = 0, 0.0, 0
    x = q = None
    stats: dict = {}
    ok = False
    fscale = 1.0
    cost = None  # Newton's answer comes with its objective

    kind = "fatrop_warm"
    same_task = warm is not None and warm.get("backend") == "casadi" and warm.get("task") == key
    if same_task and newton:
        # the same reach under new weights, by exact Newton from the previous solution (MO-IRL's
        # ``warm_newton``); fatrop from the same point where Newton cannot vouch for its answer
        t0 = time.perf_counter()
        found = newton_solve(task, weights, warm["knots"][0])
        elapsed, attempts = time.perf_counter() - t0, 1
        if found is not None:
            q, ok, kind, fscale, iterations, cost = found.q, True, "newton", found.fscale, found.iterations, found.cost
    if q is None and same_task and newton and interior:
        # where Newton cannot settle (the corners or the bounds move: weights far from the previous ones), the
        # interior point on the knots from the same solution; fatrop where it cannot vouch for its answer
        t0 = time.perf_counter()
        found = interior_solve(task, weights, warm["knots"][0])
        elapsed, attempts = elapsed + time.perf_counter() - t0, attempts + 1
        if found is not None:
            q, ok, kind, fscale, cost = found.q, True, "interior", found.fscale, found.cost
            iterations += found.iterations
    if q is None and same_task:
        # the same reach under new weights (MO-IRL's line search): reuse the primal point and the scale
        fscale = warm["fscale"]
        x0 = np.clip(_pack_knots(task, *warm["knots"]), lbx, ubx)
        args = {**bounds, "x0": x0, "p": nlp.params(task, weights, fscale)}
        x, stats, t = _run(nlp, kind, args)
        elapsed, iterations, attempts = elapsed + t, int(stats.get("iter_count", 0)), attempts + 1
        ok = _converged(stats, x)
    if q is None and x is None and newton and guess is not None:
        # a close start (a similar reach moved to this task): exact Newton first, which vouches for its answer
        # or gives way to fatrop from the same start
        start = np.array(guess, dtype=float)
        start[0], start[-2] = task.q0, start[-1]  # at rest at both ends, as _pack makes it
        start[1:] = np.clip(start[1:], task.q_lower, task.q_upper)
        t0 = time.perf_counter()
        found = newton_solve(task, weights, start)
        elapsed, attempts = elapsed + time.perf_counter() - t0, attempts + 1
        if found is not None:
            q, ok, kind, fscale, iterations, cost = found.q, True, "newton", found.fscale, found.iterations, found.cost
    if q is None and (x is None or (retry_cold and not ok)):
        # cold: a neighbouring reach's solution misleads the solver, and so does a warm start after a large
        # change of weights
        x0 = np.clip(initial_guess(task) if guess is None else _pack(task, guess), lbx, ubx)
        fscale = _objective_scale(task, weights, x0)
        args = {**bounds, "x0": x0, "p": nlp.params(task, weights, fscale)}
        for kind in ("fatrop", "ipopt"):
            x, stats, t = _run(nlp, kind, args)
            iterations += int(stats.get("iter_count", 0))
            attempts += 1
            elapsed += t
            ok = _converged(stats, x)
            if ok:
                break
    if q is None:
        q = _unpack_q(task, x)
    q[-1] = on_bar(task, q[-1])
    q, qd, tau = rest_to_rest_knots(task, q)
    return DocSolution(
        t=task.t,
        q=q,
        qd=qd,
        tau=tau,
        cost=trajectory_cost(task.arm, q, qd, tau, task.dt, weights) if cost is None else cost,
        converged=ok,
        iterations=iterations,
        solve_time=elapsed,
        attempts=attempts,
        status=_status(kind, stats),
        backend="casadi",
        warm={"backend": "casadi", "task": key, "fscale": fscale, "knots": (q, qd, tau)},  # packed if a warm
        # start uses them (predictions never do)
    )
