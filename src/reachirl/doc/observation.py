"""A DOC solution seen the way the recording saw the reach: cut at the same fingertip-speed threshold.

A recorded trial runs from onset to offset, where the fingertip speed crosses a fraction of its peak (5 % in
Berret et al. 2011 and in ``reachirl preprocess``; ``Trial.onset_threshold``), so it starts and ends *moving*.
The seed's DOC starts and ends at rest. Solved over the trial's own duration, it must squeeze a rest-to-rest
reach into the moving part of one.

With an onset threshold, the task and the comparison change, the DOC does not:

* :func:`observed_task`: the rest-to-rest DOC from the trial's onset posture to its target, over
  ``duration / MOVING_FRACTION`` (a bell-shaped reach spends about 90 % of its rest-to-rest time above 5 % of its
  peak speed; a minimum-jerk one 88 %). Its constraints are the seed's, zero velocity at both ends included.
* :func:`observe`: the solution's own onset-to-offset part, where its fingertip speed is above the same threshold
  times its peak, as a :class:`~reachirl.data.trial.Trial`. It is compared with the trial on normalised time, and
  its features are computed exactly as a demonstration's.

Both sides are compared on normalised time, so the result hardly depends on the fraction. ``reproduce`` and
``fit`` use it by default (``--seed-form`` for the seed's DOC over the trial's own duration);
``docs/method.md`` gives the held-out measurements and what it costs.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from scipy import sparse

from ..data.trial import Trial
from ..errors import InputError
from ..features import euler_knots
from . import DocSolution, ReachingTask, solve_doc
from .task import moved_path

if TYPE_CHECKING:
    from scipy.interpolate import BSpline

__all__ = [
    "MOVING_FRACTION",
    "check_threshold",
    "common_threshold",
    "cut_times",
    "observe",
    "observed_knots",
    "observed_solution",
    "observed_state_jacobian",
    "observed_task",
    "predict",
    "predict_reach",
    "rest_to_rest",
]

MOVING_FRACTION = 0.9
"""Share of a rest-to-rest reach's time above its onset threshold (the DOC horizon is the trial's duration over it)."""

_FINE = 20  # speed samples per DOC interval when looking for the crossings


def check_threshold(threshold: float | None) -> float | None:
    """``threshold`` as a float in (0, 1), or ``None``; anything else raises ``ValueError``."""
    if threshold is None:
        return None
    if (
        isinstance(threshold, bool)
        or not isinstance(threshold, int | float | np.floating)
        or not 0.0 < float(threshold) < 1.0
    ):
        raise ValueError(f"the onset threshold must be a fraction of the peak speed in (0, 1), got {threshold!r}")
    return float(threshold)


def common_threshold(trials: Sequence[Trial]) -> float | None:
    """The onset threshold all ``trials`` were cut at (``None`` if any was not cut); trials cut at different
    thresholds raise :class:`~reachirl.errors.InputError`, a ``ValueError`` (one rollout cannot be seen two ways:
    a trials file merged from two ``preprocess --threshold`` runs)."""
    found = {t.onset_threshold for t in trials}
    if None in found:
        return None
    if len(found) > 1:
        raise InputError(
            f"the trials of one rollout were cut at different onset thresholds {sorted(found)} (preprocess "
            "--threshold); preprocess them at one threshold, fit them apart, or fit one rollout per trial "
            "(--rollout per_demo)"
        )
    return found.pop() if found else None


def rest_to_rest(task: ReachingTask) -> ReachingTask:
    """``task`` over ``duration / MOVING_FRACTION``: the whole rest-to-rest reach whose part above the onset
    threshold lasts about ``task.duration``."""
    return replace(task, duration=task.duration / MOVING_FRACTION)


def observed_task(trial: Trial, n_nodes: int, threshold: float | None) -> ReachingTask:
    """The DOC task that predicts ``trial``: :meth:`ReachingTask.from_trial` without a threshold; with one, the
    rest-to-rest reach from the trial's onset posture to its target (:func:`rest_to_rest`)."""
    task = ReachingTask.from_trial(trial, n_nodes)
    return task if check_threshold(threshold) is None else rest_to_rest(task)


def predict(
    trial: Trial,
    weights: np.ndarray,
    n_nodes: int,
    threshold: float | None,
    backend: str = "casadi",
    warm_start: DocSolution | None = None,
    path: np.ndarray | None = None,
) -> tuple[DocSolution, DocSolution]:
    """``(solution, seen)``: the DOC of :func:`observed_task` under ``weights`` (``warm_start``: a solution of
    that same task; ``path``: a cold start, a similar reach's joint path on the same knots, moved to this task
    by :func:`reachirl.doc.task.moved_path`) and its :func:`observed_solution`; both are the same solution
    without a threshold."""
    task = observed_task(trial, n_nodes, threshold)
    guess = None if path is None else moved_path(task, path)
    # Newton from the moved path; a warm start (the same task under other weights) is fatrop's
    sol = solve_doc(task, weights, backend=backend, warm_start=warm_start, guess=guess, newton=warm_start is None)
    return sol, observed_solution(sol, task, threshold)


def predict_reach(
    trial_or_task: Trial | ReachingTask,
    weights: np.ndarray,
    n_nodes: int,
    observe: bool,
    backend: str = "casadi",
    warm_start: DocSolution | None = None,
    path: np.ndarray | None = None,
) -> DocSolution:
    """A fitted model's prediction (an estimator's ``predict``, a saved model's
    :meth:`~reachirl.irl.model.LearnedModel.predict`): for a :class:`~reachirl.data.trial.Trial`, the DOC from its
    own arm, start, target and duration, seen as it was recorded when ``observe`` (:func:`predict`'s ``seen``); for a
    :class:`ReachingTask`, its DOC on ``n_nodes`` knots (the task's own are replaced: the weights' windows and
    ``path`` are on the model's knots, and so must ``warm_start`` be). Without ``warm_start`` the solve starts
    from ``path`` moved to the task, when given."""
    path = path if warm_start is None else None
    if isinstance(trial_or_task, Trial):
        threshold = trial_or_task.onset_threshold if observe else None
        return predict(trial_or_task, weights, n_nodes, threshold, backend, warm_start, path)[1]
    if not isinstance(trial_or_task, ReachingTask):
        raise TypeError(f"predict takes a Trial or a ReachingTask, got {type(trial_or_task).__name__}")
    task = trial_or_task if trial_or_task.n_nodes == n_nodes else replace(trial_or_task, n_nodes=n_nodes)
    guess = None if path is None else moved_path(task, path)
    return solve_doc(task, weights, backend=backend, warm_start=warm_start, guess=guess)


class _Cut(NamedTuple):
    """Where :func:`observe` cuts a solution: the crossings ``a``, ``b`` (s) and the speed samples they lie
    between (``ia``/``ib``: the sample before each crossing, ``None`` where the solution is kept whole on that
    side), the peak's sample ``peak``, the fine times ``tf`` and the knots' spline."""

    spline: BSpline
    tf: np.ndarray
    speed: np.ndarray
    peak: int
    ia: int | None
    ib: int | None
    a: float
    b: float


@functools.lru_cache(maxsize=8)
def _unit_knots(n: int) -> tuple[np.ndarray, np.ndarray, sparse.csr_matrix, sparse.csr_matrix]:
    """For ``n + 1`` equally spaced knots on [0, 1]: the not-a-knot cubic's B-spline knots, the matrix that takes the
    knot values to its coefficients, and the (sparse) matrices that take the coefficients to its values and slopes
    at the :data:`_FINE` samples per interval. A B-spline on knots scaled by ``T`` has the same coefficients and
    values, and its slopes divided by ``T``: every DOC solution of ``n`` intervals shares them."""
    from scipy.interpolate import BSpline, make_interp_spline  # here: it imports scipy.optimize (see _knot_spline)

    u = np.linspace(0.0, 1.0, n + 1)
    unit = make_interp_spline(u, np.eye(n + 1), k=3)
    slope = BSpline(unit.t, np.eye(n + 1), 3).derivative()
    uf = np.linspace(0.0, 1.0, _FINE * n + 1)
    values = BSpline.design_matrix(uf, unit.t, 3).tocsr()
    slopes = sparse.csr_matrix(BSpline.design_matrix(uf, slope.t, 2) @ slope.c[: len(slope.t) - 3])
    return unit.t, np.ascontiguousarray(unit.c), values, slopes


def _equally_spaced(t: np.ndarray) -> bool:
    """Whether the knots ``t`` are ``linspace(0, t[-1], len(t))`` (a DOC solution's), to rounding."""
    return t[0] == 0.0 and bool(np.all(np.abs(np.diff(t) - t[-1] / (len(t) - 1)) <= 1e-12 * t[-1]))


def _knot_spline(t: np.ndarray, y: np.ndarray, shared: bool = False) -> BSpline:
    """The not-a-knot cubic interpolant of the knot values ``y (N+1, ...)`` (``CubicSpline``'s default; as a
    B-spline, which scipy builds three times faster). ``shared``: on equally spaced knots, from the matrices of
    :func:`_unit_knots`, seven times faster again and equal to rounding (not bit for bit)."""
    # imported here: scipy.interpolate imports scipy.optimize, which the command's own process never needs
    from scipy.interpolate import BSpline, make_interp_spline

    if not (shared and _equally_spaced(t)):
        return make_interp_spline(t, y, k=3)
    knots, coef, _, _ = _unit_knots(len(t) - 1)
    y = np.asarray(y, dtype=float)
    c = (coef @ y.reshape(len(t), -1)).reshape(y.shape)
    return BSpline.construct_fast(knots * float(t[-1]), c, 3)


def _fine_samples(sol: DocSolution, spline: BSpline, tf: np.ndarray, shared: bool) -> tuple[np.ndarray, np.ndarray]:
    """``q`` and ``q̇`` of ``spline`` (``sol``'s knots' spline, ``shared`` as :func:`_knot_spline` made it) at the
    fine times ``tf``."""
    if not (shared and _equally_spaced(sol.t)):
        return spline(tf), spline(tf, 1)
    _, _, values, slopes = _unit_knots(len(sol.t) - 1)
    return values @ spline.c, (slopes @ spline.c) / float(sol.t[-1])


def _cut(sol: DocSolution, task: ReachingTask, threshold: float | None, shared: bool = False) -> _Cut:
    arm, n = task.arm, task.n_nodes
    spline = _knot_spline(sol.t, sol.q, shared)
    end = float(sol.t[-1])
    if check_threshold(threshold) is None:
        return _Cut(spline, np.array([0.0, end]), np.zeros(2), 0, None, None, 0.0, end)
    tf = np.linspace(0.0, end, _FINE * n + 1)
    speed = arm.fingertip_speed(*_fine_samples(sol, spline, tf, shared))
    p = int(np.argmax(speed))
    thr = threshold * speed[p]
    below_before = np.flatnonzero(speed[:p] < thr)
    below_after = np.flatnonzero(speed[p:] < thr)

    def crossing(i: int) -> float:  # where the speed, linear between samples i and i + 1, equals thr
        return float(tf[i] + (thr - speed[i]) / (speed[i + 1] - speed[i]) * (tf[i + 1] - tf[i]))

    # the crossings found on the samples, refined linearly between them, so that the cut moves continuously
    # with the solution (a merit that jumped with the sampling would mislead MO-IRL's line search)
    ia = int(below_before[-1]) if below_before.size else None
    ib = p + int(below_after[0]) - 1 if below_after.size else None
    a = crossing(ia) if ia is not None else 0.0
    b = crossing(ib) if ib is not None else end
    if b - a < 0.1 * end:  # no movement to speak of: keep the whole solution
        return _Cut(spline, tf, speed, p, None, None, 0.0, end)
    return _Cut(spline, tf, speed, p, ia, ib, a, b)


def cut_times(sol: DocSolution, task: ReachingTask, threshold: float | None) -> tuple[float, float]:
    """``(a, b)``: where :func:`observe` cuts ``sol`` (s from its start), the whole solution without a threshold."""
    cut = _cut(sol, task, threshold)
    return cut.a, cut.b


def observe(sol: DocSolution, task: ReachingTask, threshold: float | None, name: str = "prediction") -> Trial:
    """The part of ``sol`` (a solution of ``task``) where the fingertip speed is above ``threshold`` × its peak,
    as a trial sampled on ``4 N + 1`` points from the knots' cubic spline (``q̇``, ``q̈`` its derivatives, ``τ``
    by inverse dynamics); the whole solution without a threshold. The onset and offset are the first samples
    around the peak where the speed crosses the threshold (as :func:`reachirl.data.segmentation.detect_onset_offset`
    finds them in a recording), refined linearly between the speed's samples."""
    arm, n = task.arm, task.n_nodes
    cut = _cut(sol, task, threshold)
    t = np.linspace(cut.a, cut.b, 4 * n + 1)
    q, qd, qdd = cut.spline(t), cut.spline(t, 1), cut.spline(t, 2)
    return Trial(
        "model", "", name, t, q, qd, qdd, arm.inverse_dynamics(q, qd, qdd), float(arm.fk(q[-1])[0]), arm, source=name
    )


def observed_state_jacobian(
    sol: DocSolution, task: ReachingTask, threshold: float | None, dq: np.ndarray
) -> np.ndarray:
    """The derivative of the observed state (``q`` and ``q̇`` of :func:`observed_knots`, ``sol.state`` without a
    threshold) along changes ``dq (N+1, 2, P)`` of the solution's knots: ``(N+1, 4, P)``.

    The observed knots are the spline at ``t_k = a + k (b − a)/N``, their velocities Euler differences over
    ``(b − a)/N`` (the first one the spline's slope at ``a``), so a change moves them directly and through the
    crossings ``a`` and ``b``: ``s(a) = θ s(t_peak)`` with ``s`` the fingertip speed, linear between its samples
    (the peak's sample held, as the envelope theorem allows). Tested against finite differences of
    :func:`observe`."""
    n = task.n_nodes
    dq = np.asarray(dq, dtype=float)
    if dq.ndim != 3 or dq.shape[:2] != (n + 1, 2):
        raise ValueError(f"dq must have shape ({n + 1}, 2, P), got {dq.shape}")
    n_dir = dq.shape[2]
    if check_threshold(threshold) is None:
        dqd = np.concatenate([np.zeros((1, 2, n_dir)), np.diff(dq, axis=0) / task.dt])
        return np.concatenate([dq, dqd], axis=1)
    cut = _cut(sol, task, threshold)
    arm = task.arm
    dspline = _knot_spline(sol.t, dq.reshape(n + 1, -1))

    def dspeed(i: int) -> np.ndarray:  # d s(tf[i]) along every direction, (P,)
        t = cut.tf[i]
        q, qd = cut.spline(t), cut.spline(t, 1)
        d, dd = dspline(t).reshape(2, n_dir), dspline(t, 1).reshape(2, n_dir)
        eps = 1e-7  # the speed's directional derivative, central differences (exact to ~1e-9; the speed is > 0 here)
        return (
            arm.fingertip_speed(q + eps * d.T, qd + eps * dd.T) - arm.fingertip_speed(q - eps * d.T, qd - eps * dd.T)
        ) / (2 * eps)

    def dcrossing(i: int | None) -> np.ndarray:
        if i is None:
            return np.zeros(n_dir)
        s0, s1, thr = cut.speed[i], cut.speed[i + 1], threshold * cut.speed[cut.peak]
        d0, d1, dthr = dspeed(i), dspeed(i + 1), threshold * dspeed(cut.peak)
        dt = cut.tf[i + 1] - cut.tf[i]
        return ((dthr - d0) * (s1 - s0) - (thr - s0) * (d1 - d0)) / (s1 - s0) ** 2 * dt

    da, db = dcrossing(cut.ia), dcrossing(cut.ib)
    k = np.arange(n + 1)[:, None] / n
    t = cut.a + k[:, 0] * (cut.b - cut.a)
    h, dh = (cut.b - cut.a) / n, (db - da) / n
    dtk = da[None, :] + k * (db - da)[None, :]  # (N+1, P)
    q = cut.spline(t)
    dqk = dspline(t).reshape(n + 1, 2, n_dir) + cut.spline(t, 1)[:, :, None] * dtk[:, None, :]
    dqd0 = dspline(cut.a, 1).reshape(2, n_dir) + cut.spline(cut.a, 2)[:, None] * da[None, :]
    dqd = np.diff(dqk, axis=0) / h - (np.diff(q, axis=0) / h**2)[:, :, None] * dh[None, None, :]
    return np.concatenate([dqk, np.concatenate([dqd0[None], dqd])], axis=1)


def observed_knots(
    sol: DocSolution, task: ReachingTask, threshold: float | None, *, shared: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``(q (N+1, 2), q̇ (N+1, 2), τ (N, 2), dt)``: the observed part of ``sol`` on the DOC's ``N`` intervals, as
    :meth:`Trial.knots` computes a demonstration's (``observe(sol, task, threshold).knots(N)``), read straight
    off the solution's spline: ``q_k`` at ``t_k = a + k (b − a)/N``, ``q̇_0`` its slope at ``a``, Euler
    differences, inverse-dynamics torques, ``dt = (b − a)/N``. (The trial of :func:`observe` is sampled on a grid
    that contains the ``t_k``, so its own spline passes through the same values: equal to rounding, tested.)
    The solution's own knots without a threshold. MO-IRL reads every rollout this way, with scipy's own spline
    (a fit's line search amplifies rounding: its rollouts are read bit for bit as they always were); ``shared``:
    with the shared matrices of :func:`_knot_spline`, as :func:`observed_solution` reads a prediction."""
    n = task.n_nodes
    if check_threshold(threshold) is None:
        return sol.q, sol.qd, sol.tau, task.dt
    cut = _cut(sol, task, threshold, shared)
    dt = (cut.b - cut.a) / n
    return (*euler_knots(task.arm, cut.spline(np.linspace(cut.a, cut.b, n + 1)), dt, cut.spline(cut.a, 1)), dt)


def observed_solution(sol: DocSolution, task: ReachingTask, threshold: float | None) -> DocSolution:
    """``sol`` replaced by its observed part (:func:`observe`) on ``N + 1`` equally spaced knots (time from 0,
    ``q̇`` and ``τ`` as :meth:`Trial.knots` computes a demonstration's: :func:`observed_knots`), so that it is
    compared with a trial resampled on the same knots; ``sol`` itself without a threshold. Its ``cost``,
    ``converged`` and solver fields stay the whole rest-to-rest DOC's: the cost is that DOC's optimum, not the
    cost of the part returned. Read with the shared spline matrices (:func:`observed_knots`' ``shared``)."""
    if check_threshold(threshold) is None or not sol.finite:  # non-finite: a failure, counted, with nothing to cut
        return sol
    q, qd, tau, dt = observed_knots(sol, task, threshold, shared=True)
    return DocSolution(
        np.linspace(0.0, dt * task.n_nodes, task.n_nodes + 1),
        q,
        qd,
        tau,
        sol.cost,
        sol.converged,
        sol.iterations,
        sol.solve_time,
        sol.status,
        sol.backend,
        sol.attempts,
        warm=None,
    )
