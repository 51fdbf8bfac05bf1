"""The Crocoddyl shooting problem of one ``(arm, N, n_windows)`` shape, built once and cached."""

from __future__ import annotations

import functools
import logging
import threading
import time

import crocoddyl
import mim_solvers
import numpy as np
import pinocchio as pin

from ...arm import ArmModel
from ...features import N_FEATURES, window_index
from ..task import ReachingTask
from .knots import _NX
from .native import knot_class
from .options import DEFAULT_OPTIONS, CsqpOptions

log = logging.getLogger(__name__)


def _com_frames(model, arm: ArmModel) -> tuple[int, int]:
    """Add a frame at each segment's centre of mass; return their ids."""
    ids = []
    for name, joint, c in (("upper_arm_com", 1, arm.c1), ("forearm_com", 2, arm.c2)):
        ids.append(
            model.addFrame(
                pin.Frame(name, joint, 0, pin.SE3(np.eye(3), np.array([c, 0.0, 0.0])), pin.FrameType.OP_FRAME)
            )
        )
    return ids[0], ids[1]


class ReachingProblem:
    """The Crocoddyl shooting problem of one ``(arm, N, n_windows)`` shape; tasks and weights go in in place."""

    def __init__(self, arm: ArmModel, n: int, n_windows: int, options: CsqpOptions = DEFAULT_OPTIONS):
        self.arm, self.n, self.n_windows, self.options = arm, n, n_windows, options
        self.window = window_index(n, n_windows)
        model = arm.pinocchio_model()
        com1, com2 = _com_frames(model, arm)
        self.pin_model = model
        state = crocoddyl.StateMultibody(model)
        actuation = crocoddyl.ActuationModelFull(state)
        nu = actuation.nu
        tip = model.getFrameId("fingertip")
        zero_motion = pin.Motion.Zero()
        local = pin.ReferenceFrame.LOCAL  # not LOCAL_WORLD_ALIGNED: see the module docstring

        def cost(residual, activation=None):
            if activation is None:
                return crocoddyl.CostModelResidual(state, residual)
            return crocoddyl.CostModelResidual(state, activation, residual)

        # Cost models are stateless; the knots share them and keep their own weights in their sums.
        cost_models = {
            "cartesian_velocity": cost(
                crocoddyl.ResidualModelFrameVelocity(state, tip, zero_motion, local, nu),
                crocoddyl.ActivationModelWeightedQuad(np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])),
            ),
            "geodesic": cost(
                crocoddyl.ResidualModelFrameVelocity(state, com1, zero_motion, local, nu),
                crocoddyl.ActivationModelWeightedQuad(np.array([arm.m1] * 3 + [0.0, 0.0, arm.i1])),
            ),
            "geodesic/forearm": cost(
                crocoddyl.ResidualModelFrameVelocity(state, com2, zero_motion, local, nu),
                crocoddyl.ActivationModelWeightedQuad(np.array([arm.m2] * 3 + [0.0, 0.0, arm.i2])),
            ),
            "joint_acceleration": cost(crocoddyl.ResidualModelJointAcceleration(state, nu)),
            "joint_velocity": cost(
                crocoddyl.ResidualModelState(state, np.zeros(4), nu),
                crocoddyl.ActivationModelWeightedQuad(np.array([0.0, 0.0, 1.0, 1.0])),
            ),
            "joint_torque": cost(crocoddyl.ResidualModelControl(state, nu)),
        }
        inf = np.full(4, np.inf)
        bounds_residual = crocoddyl.ResidualModelState(state, np.zeros(4), nu)
        tip_residual = crocoddyl.ResidualModelFrameTranslation(state, tip, np.zeros(3), nu)

        knot = knot_class(options.compiled_knots)
        dt = 1.0 / n
        running = []
        for k in range(n):
            costs = crocoddyl.CostModelSum(state, nu)
            for name, c in cost_models.items():
                costs.addCost(name, c, 0.0)
            constraints = crocoddyl.ConstraintModelManager(state, nu)
            if k > 0:  # x_0 is fixed
                constraints.addConstraint(
                    "state_bounds", crocoddyl.ConstraintModelResidual(state, bounds_residual, -inf, inf)
                )
            dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, costs, constraints)
            running.append(
                knot(
                    crocoddyl.IntegratedActionModelEuler(dam, dt),
                    first=(k == 0),
                    terminal=False,
                    energy_smoothing=options.energy_smoothing,
                )
            )
        costs = crocoddyl.CostModelSum(state, nu)
        constraints = crocoddyl.ConstraintModelManager(state, nu)
        constraints.addConstraint("state_bounds", crocoddyl.ConstraintModelResidual(state, bounds_residual, -inf, inf))
        constraints.addConstraint(
            "fingertip",
            crocoddyl.ConstraintModelResidual(state, tip_residual, np.full(3, -np.inf), np.full(3, np.inf)),
        )
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, costs, constraints)
        terminal = knot(
            crocoddyl.IntegratedActionModelEuler(dam, 0.0),
            first=False,
            terminal=True,
            energy_smoothing=options.energy_smoothing,
        )
        self.running, self.terminal = running, terminal
        self.problem = crocoddyl.ShootingProblem(np.zeros(_NX), running, terminal)
        # One thread: with knots all in C++, Crocoddyl would evaluate them over its OpenMP threads, which changes the
        # solves' last bits (and a fit's decisions with them) and competes with the worker processes. (Set only
        # when it is not 1 already: Crocoddyl warns on stderr at every setting once a Python model exists.)
        if self.problem.nthreads != 1:
            self.problem.nthreads = 1
        self.lock = threading.Lock()

    def update(self, task: ReachingTask, weights: np.ndarray, running_bounds: bool = True) -> None:
        """Write the task's numbers and the weights into the problem (no rebuild). With ``running_bounds``
        false the running knots' joint-limit and speed rows get infinite bounds: CSQP's ADMM then gives them
        its minimal penalty and never projects them (the terminal knot keeps all of its constraints)."""
        if task.arm != self.arm or task.n_nodes != self.n or weights.shape != (self.n_windows, N_FEATURES):
            raise ValueError("task or weights do not match this problem's shape")
        self.problem.x0 = np.r_[task.q0, 0.0, 0.0, task.arm.gravity_torque(task.q0)]  # at rest: τ_{−1} = g(q0)
        if running_bounds:
            lb = np.r_[task.q_lower, -task.qd_max]
            ub = np.r_[task.q_upper, task.qd_max]
        else:
            lb, ub = np.full(4, -np.inf), np.full(4, np.inf)
        for k, m in enumerate(self.running):
            m.exact_hessian = self.options.energy_exact_hessian
            m.set_dt(task.dt)
            m.set_weights(weights[self.window[k]])
            if m.n_constraints:
                m.g_lb, m.g_ub = lb, ub
        # the manager stacks its constraints in the order of their names: "fingertip", then "state_bounds"
        t = self.terminal
        t.g_lb = np.r_[task.target_x, -np.inf, -np.inf, task.q_lower, 0.0, 0.0]
        t.g_ub = np.r_[task.target_x, np.inf, np.inf, task.q_upper, 0.0, 0.0]

    def make_solver(self, tolerance: float, eps: float, callbacks=()):
        """A fresh CSQP solver (no state carried over from earlier solves, so results are reproducible) with the
        KKT tolerance ``tolerance`` and QP tolerance ``eps``.
        """
        o = self.options
        solver = mim_solvers.SolverCSQP(self.problem)
        solver.termination_tolerance = tolerance
        solver.max_qp_iters = o.max_qp_iters
        solver.eps_abs = eps
        solver.eps_rel = 0.0
        solver.reset_rho = o.reset_rho
        solver.alpha = o.admm_relaxation
        solver.rho_update_interval = o.rho_update_interval
        solver.adaptive_rho_tolerance = o.adaptive_rho_tolerance
        solver.mu_dynamic = solver.mu_constraint = o.merit_penalty
        solver.use_filter_line_search = o.use_filter_line_search
        solver.with_callbacks = False
        if callbacks:
            solver.setCallbacks(list(callbacks))
        return solver


def build_problem(arm: ArmModel, n: int, n_windows: int, options: CsqpOptions | None = None) -> ReachingProblem:
    """The cached problem of one ``(arm, N, n_windows)`` shape (and solver options)."""
    return _cached_problem(arm, int(n), int(n_windows), options or DEFAULT_OPTIONS)


@functools.lru_cache(maxsize=8)
def _cached_problem(arm: ArmModel, n: int, n_windows: int, options: CsqpOptions) -> ReachingProblem:
    t0 = time.perf_counter()
    p = ReachingProblem(arm, n, n_windows, options)
    log.debug("built the Crocoddyl problem N=%d, %d windows in %.3f s", n, n_windows, time.perf_counter() - t0)
    return p
