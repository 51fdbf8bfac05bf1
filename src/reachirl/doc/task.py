"""The reaching DOC problem (seed Eq. 1) and its solution, independent of any solver.

The problem, on ``N = n_nodes`` Euler intervals of ``dt = duration / N``::

    min_τ   Σ_s Σ_j ω_{s,j} Φ_{s,j}(q, q̇, τ)                      (features.py)
    s.t.    q̇_{k+1} = q̇_k + dt · M(q_k)⁻¹ (τ_k − b(q_k, q̇_k))    semi-implicit Euler, as Crocoddyl's
            q_{k+1} = q_k + dt · q̇_{k+1}                          IntegratedActionModelEuler
            q_0 = q0,   q̇_0 = 0,   q̇_N = 0
            P_x(q_N) = target_x                                   fingertip on the vertical bar
            q_lower ≤ q_k ≤ q_upper,   |q̇_k| ≤ qd_max (per joint)

Default bounds (documented choices; the seed gives none): the joint ranges of :mod:`reachirl.arm`, the shoulder
``q1 ∈ [-150°, 120°]`` (full extension behind the body to well overhead) and the elbow ``q2 ∈ [-5°, 160°]`` (slight
hyper-extension to full flexion), and a joint speed of at most 10 rad/s (about 570 °/s, above human reaching peaks
of 3-6 rad/s, so it binds only on outlandish weights). The speed bound is per joint (the seed writes ``‖q̇‖ ≤ q̇⁺``
with a vector ``q̇⁺``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from ..arm import DEFAULT_Q_LOWER, DEFAULT_Q_UPPER, DEFAULT_QD_MAX, ArmModel
from ..features import euler_knots
from ..validation import brief, check_arm, check_duration, check_n_nodes, not_real, number

__all__ = [
    "DEFAULT_QD_MAX",
    "DEFAULT_Q_LOWER",
    "DEFAULT_Q_UPPER",
    "DocSolution",
    "ReachingTask",
    "check_warm_start_knots",
    "fingertip_x",
    "min_jerk",
    "moved_path",
    "on_bar",
    "rest_to_rest_knots",
    "warm_start_key",
]


def _vec2(name: str, v) -> np.ndarray:
    if type(v) is np.ndarray and v.dtype == np.float64 and v.shape == (2,):  # e.g. another task's (a replace)
        if not (math.isfinite(v[0]) and math.isfinite(v[1])):
            raise ValueError(f"{name} must be finite, got {v}")
        if v.flags.writeable or v.base is not None:  # the caller's, or a view of memory someone may still change
            v = v.copy()
            v.setflags(write=False)
        return v  # a task's own: read-only, owning its numbers
    if (what := not_real(v)) is not None:
        raise ValueError(f"{name} must be 2 real numbers, got {what}")
    try:
        a = np.array(v, dtype=float).reshape(-1)  # a copy, never a view of the caller's
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 2 numbers, got {brief(v)}") from None
    if a.shape != (2,):
        raise ValueError(f"{name} must have shape (2,), got {np.shape(v)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {a}")
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class ReachingTask:
    """One reach to plan: the arm, where it starts (rad), where the bar is (m) and how long it takes (s)."""

    arm: ArmModel
    q0: np.ndarray
    target_x: float
    duration: float
    n_nodes: int = 100
    q_lower: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_Q_LOWER))
    q_upper: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_Q_UPPER))
    qd_max: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_QD_MAX))

    def __post_init__(self) -> None:
        if not isinstance(self.arm, ArmModel):
            raise TypeError(f"arm must be an ArmModel, got {type(self.arm).__name__}")
        for name in ("q0", "q_lower", "q_upper", "qd_max"):
            object.__setattr__(self, name, _vec2(name, getattr(self, name)))
        for name, unit in (("target_x", "m"), ("duration", "s")):
            try:
                object.__setattr__(self, name, number(getattr(self, name)))
            except (TypeError, ValueError):
                raise ValueError(f"{name} must be a number ({unit}), got {brief(getattr(self, name))}") from None
        if not math.isfinite(self.target_x):
            raise ValueError(f"target_x must be finite, got {self.target_x}")
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"duration must be a positive number of seconds, got {self.duration}")
        # physical and numerical ranges (InputError is a ValueError): a reach, a human-sized arm, a DOC that
        # builds and solves in seconds
        check_duration(self.duration, "ReachingTask")
        check_arm(self.arm, "ReachingTask")
        object.__setattr__(self, "n_nodes", check_n_nodes(self.n_nodes, "ReachingTask"))
        # on the two joints' numbers (a task is made for every prediction: numpy's calls cost more than the checks)
        (lo1, lo2), (hi1, hi2) = self.q_lower.tolist(), self.q_upper.tolist()
        for name, pair in (("q_lower", (lo1, lo2)), ("q_upper", (hi1, hi2))):
            if max(abs(pair[0]), abs(pair[1])) > 2 * np.pi:
                raise ValueError(f"{name} {getattr(self, name)} is beyond a full turn of a joint: radians are expected")
        if lo1 >= hi1 or lo2 >= hi2:
            raise ValueError(f"q_lower {self.q_lower} must be below q_upper {self.q_upper}")
        if min(self.qd_max.tolist()) <= 0:
            raise ValueError(f"qd_max must be > 0, got {self.qd_max}")
        a1, a2 = self.q0.tolist()
        if a1 < lo1 - 1e-9 or a2 < lo2 - 1e-9 or a1 > hi1 + 1e-9 or a2 > hi2 + 1e-9:
            lo, hi = np.rad2deg(self.q_lower), np.rad2deg(self.q_upper)
            # each joint's own range (the lower and the upper bounds were printed as two pairs, [[q1, q2], [q1,
            # q2]], which read as q1 in [-150, -5]), and what a start beyond a full turn most likely is
            hint = "; radians are expected (degrees?)" if np.any(np.abs(self.q0) > 2 * np.pi) else ""
            raise ValueError(
                f"q0 = ({np.rad2deg(self.q0[0]):.1f}°, {np.rad2deg(self.q0[1]):.1f}°) lies outside the joint limits "
                f"q1 in [{lo[0]:.1f}°, {hi[0]:.1f}°], q2 in [{lo[1]:.1f}°, {hi[1]:.1f}°]{hint}"
            )
        if abs(self.target_x) > self.arm.length:
            raise ValueError(f"target_x {self.target_x:.3f} m is out of reach of an arm {self.arm.length:.3f} m long")

    @classmethod
    def from_trial(cls, trial, n_nodes: int = 100, **bounds) -> ReachingTask:
        """The DOC task of a recorded reach (a :class:`~reachirl.data.trial.Trial`): its own arm, initial
        posture, target and duration."""
        return cls(trial.arm, trial.x0[:2], trial.target_x, trial.duration, n_nodes=n_nodes, **bounds)

    @property
    def dt(self) -> float:
        return self.duration / self.n_nodes

    @property
    def t(self) -> np.ndarray:
        return np.linspace(0.0, self.duration, self.n_nodes + 1)


@dataclass(frozen=True, eq=False)  # its own __eq__; unhashable (its arrays are mutable)
class DocSolution:
    """An optimal (or best-effort) reach: knots ``t (N+1,)``, ``q``/``qd (N+1, 2)``, torques ``tau (N, 2)``."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray
    cost: float
    converged: bool
    iterations: int
    solve_time: float
    status: str = ""
    backend: str = ""
    # solver runs behind this solution (a failed warm or fatrop start is retried; a Crocoddyl solve without the
    # running bounds that breaks one is solved again with them)
    attempts: int = 1
    # Solver state for warm starts (primal/dual vectors); opaque, not part of the public result.
    warm: dict | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if np.ndim(self.t) != 1 or np.shape(self.t)[0] < 2:  # a scalar t raised an IndexError below
            raise ValueError(f"DocSolution.t must have shape (N+1,) with N >= 1, got {np.shape(self.t)}")
        n = np.shape(self.t)[0] - 1
        for name, shape in (("q", (n + 1, 2)), ("qd", (n + 1, 2)), ("tau", (n, 2))):
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"DocSolution.{name} must have shape {shape}, got {np.shape(getattr(self, name))}")
        if not self.finite and self.converged:  # a solver's report is not taken over its own numbers
            object.__setattr__(self, "converged", False)
            object.__setattr__(self, "status", f"{self.status} (non-finite values)".strip())

    def __eq__(self, other: object) -> bool:
        """Field by field, the arrays by their values (dataclass equality compared them with ``==``, and two
        equal solutions, a solve repeated, raised numpy's "truth value of an array ... is ambiguous"); a NaN
        equals a NaN in the same place (a failed solve equals itself). ``warm``, the solver's opaque state, is not
        compared."""
        if other.__class__ is not self.__class__:
            return NotImplemented
        for f in fields(self):
            if not f.compare:
                continue
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray | float) or isinstance(b, np.ndarray | float):
                a, b = np.asarray(a), np.asarray(b)
                nan = a.dtype.kind in "fc" and b.dtype.kind in "fc"
                if a.shape != b.shape or not np.array_equal(a, b, equal_nan=nan):
                    return False
            elif a != b:
                return False
        return True

    @property
    def finite(self) -> bool:
        """Whether every knot of ``q``, ``q̇`` and ``τ`` is a finite number (a solution with none is never
        converged)."""
        return bool(np.isfinite(self.q).all() and np.isfinite(self.qd).all() and np.isfinite(self.tau).all())

    @property
    def state(self) -> np.ndarray:
        """Full state ``x = (q1, q2, q̇1, q̇2)`` at the knots, shape ``(N+1, 4)``."""
        return np.hstack([self.q, self.qd])


def rest_to_rest_knots(task: ReachingTask, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q, q̇, τ)`` of the semi-implicit Euler trajectory through a joint path ``q (N+1, 2)``, moved to start at
    ``task.q0`` and to end at rest (``q_{N−1} = q_N``, so ``q̇_0 = q̇_N = 0``): velocities by differences, torques
    by inverse dynamics. Both backends start from it."""
    q = np.array(q, dtype=float)
    q[0] = task.q0
    q[-2] = q[-1]
    return euler_knots(task.arm, q, task.dt)


def min_jerk(s: np.ndarray) -> np.ndarray:
    """The minimum-jerk profile ``10s³ − 15s⁴ + 6s⁵`` on ``s ∈ [0, 1]`` (0 to 1 with zero slope and curvature at
    both ends)."""
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def fingertip_x(task: ReachingTask, q: np.ndarray) -> tuple[float, np.ndarray]:
    """The fingertip's ``P_x`` at a posture ``q (2,)`` of ``task``'s arm and its gradient ``(2,)``: the operations of
    :meth:`~reachirl.arm.ArmModel.fk` and ``jacobian`` on scalars (the same numbers, without their arrays' cost)."""
    a = task.arm
    q1, q12 = float(q[0]), float(q[0] + q[1])
    c1, c12, s1, s12 = math.cos(q1), math.cos(q12), math.sin(q1), math.sin(q12)
    return a.l1 * c1 + a.l2 * c12, np.array([-a.l1 * s1 - a.l2 * s12, -a.l2 * s12])


def on_bar(task: ReachingTask, q: np.ndarray) -> np.ndarray:
    """The posture ``q (2,)`` moved onto the bar (fingertip ``P_x = task.target_x``) by minimum-norm Newton steps.

    The solvers meet the constraint to their feasibility tolerance (fatrop: ~1e-10 m); this makes it exact."""
    q = np.array(q, dtype=float).reshape(2)
    for _ in range(20):  # Newton: one or two steps from a solver's answer, a few from a posture centimetres away
        p, j = fingertip_x(task, q)
        r = task.target_x - p
        if abs(r) < 1e-15:
            break
        q += j * (r / float(j @ j))
    return q


def moved_path(task: ReachingTask, path: np.ndarray) -> np.ndarray:
    """A joint path ``(N+1, 2)`` of a similar reach (another task on the same knots, e.g. a fit's own rollout)
    moved to ``task``: the offset to ``task.q0`` fades out and the offset onto ``task``'s bar fades in, each
    along a minimum-jerk profile, so the path keeps its shape and its rest at both ends. A cold start for the
    solvers, which need fewer iterations from it than from the minimum-jerk path and reach the same optimum
    (``docs/method.md``)."""
    path = np.asarray(path, dtype=float)
    if path.shape != (task.n_nodes + 1, 2) or not np.all(np.isfinite(path)):
        raise ValueError(f"path must be a finite joint path of shape {(task.n_nodes + 1, 2)}, got {path.shape}")
    s = min_jerk(np.linspace(0.0, 1.0, task.n_nodes + 1))[:, None]
    return path + (task.q0 - path[0]) * (1.0 - s) + (on_bar(task, path[-1]) - path[-1]) * s


def check_warm_start_knots(task: ReachingTask, warm_start: DocSolution | None) -> None:
    """Raise a ``ValueError`` naming both knot counts when ``warm_start`` is a solution on another number of
    knots than ``task`` (``n_nodes + 1``): such a solution cannot start the task's solve, and a caller passing
    one has mixed up its tasks. ``None`` passes."""
    if warm_start is None:
        return
    have, want = np.shape(warm_start.q)[0], task.n_nodes + 1
    if have != want:
        raise ValueError(
            f"warm_start is a solution on {have} knots, but the task has {want} (n_nodes={task.n_nodes}): "
            "a warm start must be a solution of the same task; pass warm_start=None to solve cold"
        )


def warm_start_key(task: ReachingTask) -> tuple:
    """What must match for a warm start: everything in the task but the weights."""
    return (
        task.n_nodes,
        task.arm,
        tuple(task.q0),
        task.target_x,
        task.duration,
        tuple(task.q_lower),
        tuple(task.q_upper),
        tuple(task.qd_max),
    )
