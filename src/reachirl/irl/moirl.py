"""MO-IRL with time-varying weights (the seed paper's extended form, §II-C), as a scikit-learn-style estimator.

One iteration:

1. Features ``Φ_i`` of the generated trajectories in ``x̄`` (the latest rollouts) and ``Φ*_d`` of the
   demonstrations, per window (:func:`reachirl.features.windowed_features`).
2. ``Δω*`` from the subproblem, seed Eq. 4 (:func:`reachirl.irl.objective.solve_step`, or
   :func:`~reachirl.irl.objective.solve_delta` in the seed's raw coordinates).
3. Line search ``ω_α = ω + αΔω*``, ``α = 1, 0.25, 0.25², …``: each try solves the DOC of every rollout and is
   accepted when the merit ``m(x) = (1/D) Σ_d (1/N) ‖x*_d − x_d‖²`` over ``(q1, q2, q̇1, q̇2)`` falls by more
   than ``tol``. The accepted rollouts replace ``x̄``; no accepted try ends the fit.

The method's other choices are :class:`reachirl.irl.options.Options`: reachirl's defaults (observed rollouts, the
normalised merit, scale-free steps with a trust region, the merit fallback), or the seed's form exactly as written
(``seed_form=True``). ``docs/method.md`` states each departure from the paper with its evidence.

**Rollouts** (``rollout``): each demonstration is compared with the rollout of its task. ``"per_task"`` (the
default) solves one DOC per (subject, posture) of the demonstrations, from their mean arm, start, target and
duration, so that demonstrations of several postures (and subjects) learn one cost shared by all of them;
``"per_demo"`` solves one per demonstration, from its own start; ``"mean"`` one from the mean of all
demonstrations (the seed's, identical to ``"per_task"`` on one task).

**Observed rollouts** (``Options.observe``): for demonstrations cut at a fingertip-speed threshold
(``Trial.onset_threshold``), a rollout is the rest-to-rest DOC over ``duration / MOVING_FRACTION`` and enters the
merit and the features through its own onset-to-offset part (:mod:`reachirl.doc.observation`). The fit first runs on
whole rollouts (same options) and goes on from those weights; both stages' solves are counted.
"""

from __future__ import annotations

import copy
import logging
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import fields, replace
from typing import ClassVar, NamedTuple

import numpy as np

from ..arm import ArmModel
from ..data.trial import Trial, trial_from_solution
from ..doc import DocSolution, ReachingTask, solve_doc
from ..doc.observation import (
    common_threshold,
    observe,
    observed_knots,
    observed_state_jacobian,
    observed_task,
    rest_to_rest,
)
from ..doc.sensitivity import weight_jacobian
from ..features import N_FEATURES, feature_rates, window_index, windowed_features
from .base import WeightEstimator, caller_shows_fit_warnings, log_fit_warning
from .objective import channel_scale, feature_scale, gauss_newton_step, merit, merit_model_step, solve_delta, solve_step
from .options import FIELDS as _OPTION_FIELDS
from .options import ROLLOUTS, Options, check_windows, resolve_options

__all__ = [
    "MOIRL",
    "SMOOTHNESS_GRID",
    "demonstration_states",
    "fit_flag",
    "fit_warnings",
    "mean_task",
    "mixed_postures_warning",
    "multimodal_accept",
    "rollout_groups",
]

DEFAULT_TOL = 1e-4
"""The acceptance threshold: well above the DOC's own repeatability (warm and cold solves of the same weights give
merits ~2e-5 apart), so that solver noise is not taken for progress."""

SMOOTHNESS_GRID = (0.0, 0.03, 0.3, 3.0)
"""Candidate ``λ`` of ``smoothness="cv"`` (per demonstration; ``λ → ∞`` would tie the windows into one)."""

ONE_DEMO_SAMPLES = (
    "weight samples from one demonstration: with no second one to measure the trial-to-trial spread, the merit "
    "rise the data can tell from noise is taken as the fit's merit itself, so the determined directions and the "
    "intervals rest on that stand-in, not on measured noise"
)
"""The warning of a fit with weight samples from a single demonstration (:func:`reachirl.irl.uncertainty.merit_noise`
has no spread to measure then)."""


def one_demo_tasks_warning(tasks: Sequence[str]) -> str:
    """The warning of a pooled fit with weight samples whose ``uncertainty.pooling.per_task`` intervals of ``tasks``
    (``subject/posture``) come from one demonstration each: :data:`ONE_DEMO_SAMPLES`' stand-in noise, task by task
    (the pooled intervals, from several demonstrations, measure theirs)."""
    named = ", ".join(tasks[:5]) + (f" and {len(tasks) - 5} more" if len(tasks) > 5 else "")
    return (
        f"uncertainty.pooling.per_task from one demonstration for {len(tasks)} task(s) ({named}): with no second "
        "one to measure the task's trial-to-trial spread, the merit rise it can tell from noise is taken as its "
        "merit itself, so those tasks' widths rest on that stand-in, not on measured noise"
    )


log = logging.getLogger(__name__)


def mean_task(trials: Sequence[Trial], n_nodes: int) -> ReachingTask:
    """The DOC task at the demonstrations' mean arm, initial posture, target and duration."""
    arms = [t.arm for t in trials]
    arm = ArmModel(**{f.name: float(np.mean([getattr(a, f.name) for a in arms])) for f in fields(ArmModel)})
    q0 = np.mean([t.x0[:2] for t in trials], axis=0)
    return ReachingTask(
        arm,
        q0,
        float(np.mean([t.target_x for t in trials])),
        float(np.mean([t.duration for t in trials])),
        n_nodes=n_nodes,
    )


def demonstration_states(trials: Sequence[Trial], n_nodes: int) -> np.ndarray:
    """Demonstrations on the DOC's normalised knots, ``(D, N+1, 4)`` of ``(q1, q2, q̇1, q̇2)``."""
    return np.stack([t.knot_state(n_nodes) for t in trials])


def _suffix_features(rates: np.ndarray, dt: float, n_windows: int, starts: np.ndarray) -> np.ndarray:
    """Φ of the suffixes starting at each interval in ``starts``, ``(len(starts), n_windows, 7)``."""
    idx = window_index(rates.shape[0], n_windows)
    out = np.zeros((len(starts), n_windows, N_FEATURES))
    for k, start in enumerate(starts):
        np.add.at(out[k], idx[start:], rates[start:] * dt)
    return out


class _Step(NamedTuple):
    """The line search's outcome: the accepted try, or ``accepted=False`` with the current point."""

    accepted: bool
    alpha: float
    tries: int
    weights: np.ndarray
    solutions: list
    merit: float
    solves: int
    failures: int
    recovered: int


def rollout_groups(trials: Sequence[Trial], rollout: str) -> np.ndarray:
    """Each trial's rollout index, ``(D,)``, under ``rollout``: one for all (``"mean"``), one per trial
    (``"per_demo"``) or one per subject and posture (``"per_task"``)."""
    if rollout == "mean":
        return np.zeros(len(trials), dtype=int)
    if rollout == "per_demo":
        return np.arange(len(trials))
    keys = list(dict.fromkeys((t.subject, t.posture) for t in trials))
    return np.array([keys.index((t.subject, t.posture)) for t in trials])


class MOIRL(WeightEstimator):
    """Minimal Observation IRL with ``n_windows`` time windows of weights.

    Parameters:

    * ``n_windows``: windows of weights over the reach (interval ``k`` of ``N`` is in window ``⌊k N_w / N⌋``).
    * ``rollout``: ``"per_task"``, ``"per_demo"`` or ``"mean"`` (module docstring).
    * ``max_iter``, ``tol``: iterations at most; a step must lower the merit by more than ``tol`` (relative;
      ``None``: 1e-4, or 0 with ``seed_form``).
    * ``n_nodes``, ``backend``: the DOC's knots and solver stack (``"casadi"`` or ``"crocoddyl"``).
    * ``seed_form``: the paper's method exactly as written (:data:`reachirl.irl.options.SEED_FORM`).
    * ``uncertainty``: a number ``20 ≤ K ≤ 1000`` of weight samples from the weights' posterior given the training data
      and the share intervals (:func:`reachirl.irl.uncertainty.weight_uncertainty`), or ``None``; ``True`` is
      :data:`~reachirl.irl.uncertainty.DEFAULT_SAMPLES` (40, as ``reachirl fit --uncertainty``), ``False`` and ``0``
      none (as ``uncertainty = 0`` in a ``reproduce`` run file).
    * ``random_state``: the seed of every random choice (the uncertainty's samples).
    * ``feature_mask``: ``(7,)`` or ``(n_windows, 7)`` booleans; a ``False`` feature is left out of the cost
      (weight 0, never learned). ``None``: every feature.
    * ``experimental``: a mapping of :class:`~reachirl.irl.options.Options` fields that override the method's.
    * ``callback(iteration_record)``: called after every iteration (progress); of an observed fit, after each of
      its second stage's only: its whole-rollout first stage (``plain_fit_``, up to ``max_iter`` iterations of
      its own) calls it for none.

    The fit makes no random choice: the same demonstrations give the same weights.

    Fitted attributes: ``weights_ (n_windows, 7)`` (those of the best merit seen), ``options_`` (the
    :class:`~reachirl.irl.options.Options` used), ``tol_`` (the acceptance threshold used: ``tol`` or the method's
    default), ``history_`` (one dict per iteration: merit, step kind, alpha, tries, weights, DOC solves, failures
    (tries whose DOC failed after every retry), recovered (tries a retry rescued), wall time), ``merit_``,
    ``initial_merit_``, ``best_iteration_``, ``n_doc_solves_``, ``n_doc_failures_``, ``n_iter_``, ``stop_reason_``,
    ``smoothness_``, ``cv_scores_``, ``plain_fit_`` (the whole-rollout first stage of an observed fit, else
    ``None``), ``tasks_`` (the rollouts' tasks), ``train_solutions_``, ``task_of_demo_`` (each demonstration's
    rollout), ``observed_`` (``(D,)`` booleans: which demonstrations were compared with their rollout as recorded,
    cut at their threshold; with ``observe``, those whose rollout's demonstrations were all cut at one),
    ``uncertainty_`` (with ``uncertainty``) and ``warnings_`` (a fit that never left ``ω₀``, or made a single step,
    says so).
    """

    _option_defaults: ClassVar[dict] = {}  # subclasses' own Options defaults (MaxEnt keeps every trajectory)

    def __init__(
        self,
        n_windows: int = 8,
        *,
        rollout: str = "per_task",
        max_iter: int = 30,
        tol: float | None = None,
        n_nodes: int = 100,
        backend: str = "casadi",
        seed_form: bool = False,
        uncertainty: int | None = None,
        random_state: int = 0,
        feature_mask: np.ndarray | None = None,
        experimental: dict | None = None,
        callback: Callable[[dict], None] | None = None,
    ):
        self.n_windows = n_windows
        self.rollout = rollout
        self.max_iter = max_iter
        self.tol = tol
        self.n_nodes = n_nodes
        self.backend = backend
        self.seed_form = seed_form
        self.uncertainty = uncertainty
        self.random_state = random_state
        self.feature_mask = feature_mask
        self.experimental = experimental
        self.callback = callback

    @property
    def _o(self) -> Options:
        """The resolved method options (checked)."""
        opts = self.__dict__.get("_options")
        if opts is None:
            opts = resolve_options(self.seed_form, self.experimental, self._option_defaults)
            self.__dict__["_options"] = opts
        return opts

    def __getattr__(self, name: str):
        """An :class:`~reachirl.irl.options.Options` field reads as the option in force (``est.merit``)."""
        if name in _OPTION_FIELDS:
            return getattr(self._o, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def observe(self) -> bool:
        """Whether trials cut at a speed threshold are fitted and predicted as they were recorded."""
        return bool(self._o.observe)

    @property
    def _tol(self) -> float:
        """The acceptance threshold ``tol`` asks for: itself, or the method's default (the fit's is ``tol_``)."""
        if self.tol is not None:
            return float(self.tol)
        return 0.0 if self.seed_form else DEFAULT_TOL

    def set_params(self, **params) -> MOIRL:
        """Set constructor parameters (scikit-learn style); the resolved options follow."""
        super().set_params(**params)
        self.__dict__.pop("_options", None)
        return self

    def _as_fitted(self) -> MOIRL:
        """As :meth:`WeightEstimator._as_fitted`, with the options the fit ran with (``options_``)."""
        view = super()._as_fitted()
        if view is not self:
            view.__dict__["_options"] = self.options_
        return view

    # ------------------------------------------------------------------ helpers
    def _check_params(self, trials: Sequence[Trial]) -> list[Trial]:
        self.__dict__.pop("_options", None)
        if self.experimental is not None and not isinstance(self.experimental, Mapping):
            raise ValueError(f"experimental must be a mapping of option names to values, got {self.experimental!r}")
        try:
            self.options_ = self._o
        except TypeError as e:
            raise ValueError(f"experimental: {e}") from None
        trials = self._check_trials(trials)
        if self.rollout not in ROLLOUTS:
            raise ValueError(f"rollout must be one of {', '.join(ROLLOUTS)}, got {self.rollout!r}")
        if not (
            isinstance(self.max_iter, int | np.integer) and not isinstance(self.max_iter, bool) and self.max_iter >= 1
        ):
            raise ValueError(f"max_iter must be an integer >= 1, got {self.max_iter!r}")
        if self.tol is not None and (not isinstance(self.tol, int | float | np.number) or isinstance(self.tol, bool)):
            raise ValueError(f"tol must be a number >= 0 and < 1, or None, got {self.tol!r}")
        if not (np.isfinite(self._tol) and 0 <= self._tol < 1):
            raise ValueError(f"tol must be a number >= 0 and < 1, got {self.tol}")
        self.tol_ = self._tol
        if not isinstance(self.random_state, int | np.integer) or isinstance(self.random_state, bool):
            raise ValueError(
                f"random_state must be an integer >= 0 (the seed of every random choice), got {self.random_state!r}"
            )
        if self.random_state < 0:
            raise ValueError(f"random_state must be an integer >= 0, got {self.random_state}")
        self._n_samples()  # checked before any solve
        check_windows(self._o, self.n_windows)
        if self.callback is not None and not callable(self.callback):
            raise ValueError(f"callback must be a function of an iteration's record, or None, got {self.callback!r}")
        self._mask = self._feature_mask()
        return trials

    def _n_samples(self) -> int | None:
        """The weight samples ``uncertainty`` asks for: its number, :data:`~reachirl.irl.uncertainty.DEFAULT_SAMPLES`
        for ``True`` (the bare ``reachirl fit --uncertainty``), ``None`` for ``None``, ``False`` or ``0`` (none, as
        the run-file key ``uncertainty = 0`` of ``reachirl reproduce``)."""
        from .uncertainty import DEFAULT_SAMPLES

        u = self.uncertainty
        if isinstance(u, np.bool_):  # a numpy boolean means what Python's does
            u = bool(u)
        if u is None or u is False or (isinstance(u, int | np.integer) and not isinstance(u, bool) and u == 0):
            return None
        if u is True:
            return DEFAULT_SAMPLES
        if not (isinstance(u, int | np.integer) and 20 <= u <= 1000):
            raise ValueError(
                f"uncertainty must be a number of samples from 20 to 1000, True ({DEFAULT_SAMPLES}), or 0, False or "
                f"None for none, got {u!r}"
            )
        return int(u)

    def _feature_mask(self) -> np.ndarray:
        """``(n_windows, 7)`` booleans: the features in the cost."""
        if self.feature_mask is None:
            return np.ones((self.n_windows, N_FEATURES), dtype=bool)
        m = np.asarray(self.feature_mask)
        if m.dtype != bool or m.shape not in ((N_FEATURES,), (self.n_windows, N_FEATURES)):
            raise ValueError(
                f"feature_mask must be booleans of shape ({N_FEATURES},) or ({self.n_windows}, "
                f"{N_FEATURES}), got {m.dtype} {m.shape}"
            )
        m = np.broadcast_to(m, (self.n_windows, N_FEATURES)).copy()
        if not m.any(axis=1).all():
            raise ValueError("feature_mask leaves a window without any feature")
        return m

    def _effective(self, w: np.ndarray) -> np.ndarray:
        """The weights the DOC sees: removed features at 0."""
        return np.where(self._mask, w, 0.0)

    def _groups(self, trials: Sequence[Trial]) -> np.ndarray:
        """Each demonstration's rollout index, ``(D,)``."""
        return rollout_groups(trials, self.rollout)

    def _tasks(self, trials: Sequence[Trial]) -> list[ReachingTask]:
        """The rollouts' tasks; sets ``self._thresholds`` (each rollout's onset threshold, or ``None``) and
        ``self._of`` (each demonstration's rollout)."""
        self._of = self._groups(trials)
        if self.rollout == "per_demo":
            self._thresholds = [t.onset_threshold if self._o.observe else None for t in trials]
            return [observed_task(t, self.n_nodes, th) for t, th in zip(trials, self._thresholds, strict=True)]
        tasks, self._thresholds = [], []
        for r in range(int(self._of.max()) + 1):
            group = [t for t, g in zip(trials, self._of, strict=True) if g == r]
            task = mean_task(group, self.n_nodes)
            th = common_threshold(group) if self._o.observe else None
            if th is not None:  # rest to rest, seen from onset to offset (reachirl.doc.observation)
                task = rest_to_rest(task)
            tasks.append(task)
            self._thresholds.append(th)
        return tasks

    def _seen(self, i: int, task: ReachingTask, sol: DocSolution) -> Trial:
        """Rollout ``i`` as a trial, seen as the demonstrations were recorded: its onset-to-offset part when
        they were cut at a threshold (:func:`reachirl.doc.observation.observe`), all of it otherwise."""
        if self._thresholds[i] is None:
            return trial_from_solution(sol, task.arm, task.target_x)
        return observe(sol, task, self._thresholds[i])

    def _rollout(
        self, task, w, warm: DocSolution | None, guess: np.ndarray, far: bool = False
    ) -> tuple[DocSolution, int]:
        """One DOC: warm from ``warm`` (same task), then cold, then from ``guess`` (the demonstrations' path).
        ``far``: weights far from ``warm``'s (the uncertainty's samples, not the line search's tries), solved by the
        interior point on the knots where Newton gives way. Returns the solution and the number of solver runs
        behind it."""
        w = self._effective(w)
        sol = solve_doc(task, w, backend=self.backend, warm_start=warm, newton=self._o.warm_newton, interior=far)
        runs = sol.attempts
        if not sol.converged:
            sol = solve_doc(task, w, backend=self.backend, guess=guess)
            runs += sol.attempts
        return sol, runs

    def _rollouts(self, tasks, w, warm, guesses, far: bool = False) -> tuple[list[DocSolution], int, int]:
        """Rollouts of every task (``far``: see :meth:`_rollout`); returns them, the solver runs, and how many
        needed more than one run."""
        sols, runs, rescued = [], 0, 0
        for i, task in enumerate(tasks):
            sol, n = self._rollout(task, w, None if warm is None else warm[i], guesses[i], far)
            sols.append(sol)
            runs += n
            rescued += int(sol.converged and n > 1 and warm is not None)
        return sols, runs, rescued

    def _trajectory_features(self, trial: Trial, starts: np.ndarray) -> np.ndarray:
        """Φ of one trajectory, demonstration or rollout alike: ``(n_windows, 7)``, or with suffixes
        ``(1 + n_suffixes, n_windows, 7)``. With ``feature_cutoff`` both sides are seen through the same
        low-pass filter, so the filter's own distortions cancel in ``Φ_i − Φ*``."""
        if self._o.feature_cutoff is not None:
            trial = trial.lowpass(self._o.feature_cutoff)
        q, qd, tau = trial.knots(self.n_nodes)
        return self._knot_features(trial.arm, q, qd, tau, trial.duration / self.n_nodes, starts)

    def _knot_features(self, arm: ArmModel, q, qd, tau, dt: float, starts: np.ndarray) -> np.ndarray:
        if not self._o.n_suffixes:
            return windowed_features(arm, q, qd, tau, dt, self.n_windows)
        return _suffix_features(feature_rates(arm, q, qd, tau, dt), dt, self.n_windows, starts)

    def _features(self, tasks, sols: list[DocSolution], starts: np.ndarray) -> np.ndarray:
        """Features of each rollout: ``(R, n_windows, 7)``, or with suffixes ``(R, 1 + n_suffixes, S, 7)``."""
        if self._o.feature_cutoff is not None:  # the filter needs the rollout as a recording
            return np.stack(
                [
                    self._trajectory_features(self._seen(i, task, sol), starts)
                    for i, (task, sol) in enumerate(zip(tasks, sols, strict=True))
                ]
            )
        return np.stack(
            [
                self._knot_features(task.arm, *observed_knots(sol, task, self._thresholds[i]), starts)
                for i, (task, sol) in enumerate(zip(tasks, sols, strict=True))
            ]
        )

    def reach_features(self) -> np.ndarray | None:
        """Φ ``(n_windows, 7)`` of the fit's training rollouts (their mean), each the whole DOC on the windows the
        weights act on: ``ω·Φ`` are the terms of the cost each rollout minimised (its ``trajectory_cost``), so the
        cost shares are each window's own. A rollout seen as recorded (cut at a speed threshold) is the middle of a
        rest-to-rest DOC whose windows begin before its onset and end after its offset; the windows of the part
        seen are not those the weights act on. ``None`` if a rollout did not converge."""
        est = self._as_fitted()
        sols = getattr(est, "train_solutions_", None)
        if not sols or not all(s.converged for s in sols):
            return None
        return np.mean(
            [
                windowed_features(task.arm, s.q, s.qd, s.tau, task.dt, est.n_windows)
                for task, s in zip(est.tasks_, sols, strict=True)
            ],
            axis=0,
        )

    def window_edges(self) -> np.ndarray | None:
        """Where the weights' windows begin and end on the recorded reach, ``(n_windows + 1,)``: 0 at its onset, 1 at
        its offset (the mean over the training rollouts seen as recorded, each between its own crossings of the
        onset threshold). The windows split the rest-to-rest DOC evenly, so the first begins before the onset and
        the last ends after the offset. ``None`` when no rollout is seen as recorded (each is then the DOC over the
        trial's own duration, and the edges are ``k / n_windows``) or one did not converge."""
        from ..doc.observation import cut_times

        est = self._as_fitted()
        sols = getattr(est, "train_solutions_", None)
        if not sols or not all(s.converged for s in sols) or all(th is None for th in est._thresholds):
            return None
        edges = []
        for task, sol, th in zip(est.tasks_, sols, est._thresholds, strict=True):
            a, b = cut_times(sol, task, th)
            edges.append((np.linspace(0.0, task.duration, est.n_windows + 1) - a) / (b - a))
        return np.mean(edges, axis=0)

    def _demo_features(self, trials: Sequence[Trial], starts: np.ndarray) -> np.ndarray:
        return np.stack([self._trajectory_features(t, starts) for t in trials])

    def _state(self, i: int, task: ReachingTask, sol: DocSolution) -> np.ndarray:
        """Rollout ``i``'s state on the knots as the merit compares it, ``(N+1, 4)``: seen as the demonstrations
        were recorded (:func:`reachirl.doc.observation.observed_knots`), or the DOC's own knots."""
        q, qd, _, _ = observed_knots(sol, task, self._thresholds[i])
        return np.hstack([q, qd])

    def _merit(
        self, x_demos: np.ndarray, sols: list[DocSolution], channels: np.ndarray | None, tasks: Sequence[ReachingTask]
    ) -> float:
        if any(not s.converged for s in sols):
            return np.inf
        states = [self._state(i, task, s) for i, (task, s) in enumerate(zip(tasks, sols, strict=True))]
        x = states[0] if len(states) == 1 else np.stack([states[r] for r in self._of])
        return merit(x_demos, x, channels)

    def _subproblem_terms(self, phi_star: np.ndarray, bank: list[np.ndarray], starts: np.ndarray):
        """Stack (demonstration, trajectory) pairs into the arrays the subproblem takes: each demonstration with
        the trajectories of its own rollout.

        Returns a list of ``(phi_i (I,S,7), phi_star (D',S,7), term_weights (D',))`` groups.
        """
        suffix_w = None
        if self._o.n_suffixes:
            T = self.n_nodes
            suffix_w = (T - starts + 1) / (T + 1)
        groups = []
        for r in range(bank[0].shape[0]):
            demos = np.flatnonzero(self._of == r)
            phi_i = np.stack([b[r] for b in bank])  # (I, [K,] S, 7)
            if self._o.n_suffixes:
                for k in range(len(starts)):
                    groups.append((phi_i[:, k], phi_star[demos, k], np.full(demos.size, suffix_w[k])))
            else:
                groups.append((phi_i, phi_star[demos], np.ones(demos.size)))
        return groups

    def _step(self, w, sigma, phi_star, bank, starts, smoothness, ratio) -> tuple[np.ndarray, dict]:
        """``Δω*`` of seed Eq. 4: scale-free (``scaling="demo"``) or in the seed's raw coordinates. Weights that
        may not move (:meth:`_movable`) keep their value; removed features are absent from the likelihood."""
        free = self._movable(w.shape)
        if self._o.scaling is None:
            dw, info = solve_delta(
                w, self._subproblem_terms(phi_star, bank, starts), self._o.beta, self._o.use_gamma, self._o.l1
            )
            return np.where(free, dw, 0.0), info
        groups = self._subproblem_terms(phi_star / sigma, [b / sigma for b in bank], starts)
        n_demo = phi_star.shape[0]
        return solve_step(w, sigma, groups, self._o.beta, ratio, smoothness * n_demo, free=free, present=self._mask)

    # ------------------------------------------------------------------ fit / predict
    def fit(self, trials: Sequence[Trial], y=None) -> MOIRL:
        """Learn ``weights_`` from the demonstrations ``trials``; returns the estimator. ``y`` is ignored
        (scikit-learn's signature: the demonstrations are their own targets)."""
        trials = self._check_params(trials)
        t_start = time.perf_counter()
        smoothness = self._o.smoothness
        self.cv_scores_ = None
        cv_msg = None
        if smoothness == "cv":
            smoothness, cv_msg = self._choose_smoothness(trials) if self.n_windows > 1 else (0.0, None)
        self.smoothness_ = float(smoothness)
        self._fit(trials, float(smoothness))
        msgs = [
            cv_msg,
            mixed_postures_warning(trials) if self.rollout == "mean" else None,
            uncut_trials_warning(trials, self._of, self._thresholds) if self._o.observe else None,
        ]
        self.uncertainty_ = None
        n_samples = self._n_samples()
        if n_samples is not None:
            from .uncertainty import weight_uncertainty

            try:
                self.uncertainty_ = weight_uncertainty(self, trials, n_samples, self.random_state)
            except ValueError as e:  # an unconverged or degenerate rollout has no sensitivity
                msgs.append(f"no weight samples: {e}")
            if self.uncertainty_ is not None and len(trials) < 2:
                msgs.append(ONE_DEMO_SAMPLES)
            elif self.uncertainty_ is not None and self.uncertainty_.get("pooling"):  # each task's data alone
                from .uncertainty import one_demo_tasks

                if lone := one_demo_tasks(trials):
                    msgs.append(one_demo_tasks_warning(lone))
        for msg in filter(None, msgs):
            self.warnings_ = [*self.warnings_, msg]
            log_fit_warning(log, msg)
        self.fit_time_ = time.perf_counter() - t_start
        self._keep_fit_params()
        return self

    def _choose_smoothness(self, trials: list[Trial]) -> tuple[float, str | None]:
        """``λ`` of :data:`SMOOTHNESS_GRID` with the lowest mean joint-angle RMSE over ``cv_folds`` folds of the
        training demonstrations (each fold predicted by the DOC from its own start, as a test trial would be).
        Ties go to the smoother model. The folds interleave the trials in their given order. With it, the one
        warning that sums up the fold fits' own (:func:`cv_fold_warning`), or ``None``: the fold fits log none."""
        from ..doc.evaluation import rmse_deg

        k = min(int(self._o.cv_folds), len(trials))
        if k < 2:
            return 0.0, None
        folds = [list(range(i, len(trials), k)) for i in range(k)]
        scores = {}
        warned: list[str] = []  # the fold fits' warnings, said once by this fit
        for lam in SMOOTHNESS_GRID:
            errs = []
            for held in folds:
                train = [t for i, t in enumerate(trials) if i not in held]
                est = type(self)(
                    **{
                        **self.get_params(),
                        "callback": None,
                        "uncertainty": None,
                        "experimental": {**dict(self.experimental or {}), "smoothness": lam},
                    }
                )
                est._check_params(train)
                with caller_shows_fit_warnings():
                    est._fit(train, lam)
                warned += est.warnings_
                for i in held:
                    sol = est.predict(trials[i])
                    q = trials[i].knot_state(self.n_nodes)[:, :2]
                    errs.append(rmse_deg(sol.q, q)[2] if sol.converged else np.inf)
            scores[lam] = float(np.mean(errs))
        self.cv_scores_ = scores
        best = min(scores.values())
        # the smoothest λ within 1 % of the best score (prefer the simpler model)
        lam = max(lam for lam, v in scores.items() if v <= best * 1.01)
        return lam, cv_fold_warning(warned, len(SMOOTHNESS_GRID) * k, lam)

    def _fit(self, trials: list[Trial], smoothness: float) -> None:
        t_start = time.perf_counter()
        tasks = self._tasks(trials)
        plain = None
        if any(th is not None for th in self._thresholds):
            # seen as recorded, the merit has a flatter, more winding landscape far from the optimum (measured:
            # from ω₀ the fits stopped above the true weights' merit): start from the rest-to-rest fit's weights
            plain = copy.copy(self)  # the same estimator (a subclass keeps its own state, e.g. held weights)
            plain.__dict__["_options"] = replace(self._o, observe=False)
            plain.callback, plain._first_stage = None, True
            # it only brings the weights near: one rollout per task, not one per demonstration
            plain.rollout = "mean" if self.rollout == "mean" else "per_task"
            plain._fit(trials, smoothness)
        x_demos = demonstration_states(trials, self.n_nodes)
        self._tau_demos = (
            np.stack([t.knots(self.n_nodes)[2] for t in trials]) if self._o.acceptance == "multimodal" else None
        )
        channels = channel_scale(x_demos) if self._o.merit == "normalised" else None
        guesses = [x_demos[self._of == r, :, :2].mean(axis=0) for r in range(len(tasks))]
        starts = (
            np.array([0])
            if not self._o.n_suffixes
            else np.unique(np.linspace(0, self.n_nodes * 0.9, self._o.n_suffixes + 1).astype(int))
        )
        phi_star = self._demo_features(trials, starts)
        sigma = None
        if self._o.scaling == "demo":
            sigma = feature_scale(phi_star[:, 0] if self._o.n_suffixes else phi_star)
            w = float(self._o.w0) / sigma  # every feature starts with the same share of each window's cost
        else:
            w = np.full((self.n_windows, N_FEATURES), float(self._o.w0))
        # the uncertainty's prior centre: every feature with the same share of each window's demonstrated cost
        self._w_start = float(self._o.w0) / feature_scale(phi_star[:, 0] if self._o.n_suffixes else phi_star)
        if plain is not None:
            w = plain._w_fit
        sols, n_solves, _ = self._rollouts(tasks, w, None, guesses)
        n_fail = sum(not s.converged for s in sols)
        n_rescued = 0
        if plain is not None:  # its solves count, its steps too (its weights are learned ones)
            n_solves += plain.n_doc_solves_
            n_fail += plain.n_doc_failures_
            n_rescued += plain.n_doc_recovered_
        m = self._merit(x_demos, sols, channels, tasks)
        best = (m, w, sols, 0)  # the fit returns the best merit seen ("either" acceptance can raise it)
        bank = [self._features(tasks, sols, starts)]
        self.history_ = [
            {
                "iteration": 0,
                "merit": m,
                "alpha": 0.0,
                "tries": 0,
                "accepted": True,
                "weights": w.tolist(),
                "doc_solves": n_solves,
                "doc_failures": n_fail,
                "doc_recovered": 0,
                "wall_time": time.perf_counter() - t_start,
            }
        ]
        if not np.isfinite(m):
            log.warning("the DOC at the initial weights did not converge")
        self.stop_reason_ = "max_iter"
        n_accepted = 0
        ratio = float(self._o.max_ratio)
        for it in range(1, self.max_iter + 1):
            # Δω* from the subproblem (seed Eq. 4), then ω ← ω + αΔω* with α from the line search on the merit
            dw, info = self._step(w, sigma, phi_star, bank, starts, smoothness, ratio)
            # every weight scaled by one factor changes no DOC, so no α can lower the merit (the demonstrations
            # cost more than the rollout on every feature: the likelihood has nothing left to say)
            rescale = _is_rescale(w, dw)
            step = (
                _Step(False, 0.0, 0, w, sols, m, 0, 0, 0)
                if rescale
                else self._line_search(w, dw, m, sols, tasks, x_demos, phi_star, starts, guesses, channels)
            )
            kind = "likelihood"
            # the Gauss-Newton model costs no solve: it is also tried when the likelihood's step gains little
            small = not step.accepted or (
                self._o.merit_model == "gauss-newton" and step.merit > m * (1.0 - self._o.fallback_tol)
            )
            if self._o.fallback == "merit" and np.isfinite(m) and small:
                # the likelihood's step lowers the merit by less than a merit step must (or not at all): a step
                # from a local model of the merit itself, taken when it is accepted (it then lowers the merit by
                # at least fallback_tol, more than the likelihood's step did)
                alt = self._merit_step(w, m, sols, tasks, x_demos, phi_star, starts, guesses, channels, ratio)
                if alt.accepted or not step.accepted:
                    step, kind = (
                        alt._replace(
                            solves=alt.solves + step.solves,
                            failures=alt.failures + step.failures,
                            recovered=alt.recovered + step.recovered,
                        ),
                        "merit",
                    )
                else:  # the likelihood's smaller gain stands; the merit step's solves count all the same
                    step = step._replace(
                        solves=step.solves + alt.solves,
                        failures=step.failures + alt.failures,
                        recovered=step.recovered + alt.recovered,
                    )
            n_solves += step.solves
            n_fail += step.failures
            n_rescued += step.recovered
            record = {
                "iteration": it,
                "step": kind,
                "alpha": step.alpha,
                "tries": step.tries,
                "accepted": step.accepted,
                "subproblem_iterations": info["nit"],
                "doc_solves": n_solves,
                "doc_failures": n_fail,
                "doc_recovered": n_rescued,
            }
            if not step.accepted:
                record.update(merit=m, weights=w.tolist(), wall_time=time.perf_counter() - t_start)
                self.history_.append(record)
                self._notify(record)
                self.stop_reason_ = "step_only_rescales" if rescale else "no_improving_step"
                break
            n_accepted += 1
            # trust region: the next step may go 4× as far (in log-weights) as this accepted one, up to max_ratio
            ratio = float(
                np.clip(
                    np.exp(4.0 * np.max(np.abs(np.log(step.weights / w)))), 1.0 + self._o.min_step, self._o.max_ratio
                )
            )
            w, sols, m = step.weights, step.solutions, step.merit
            if m < best[0]:
                best = (m, w, sols, it)
            bank.append(self._features(tasks, sols, starts))
            if self._o.memory is not None:
                bank = bank[-self._o.memory :]
            record.update(merit=m, weights=w.tolist(), wall_time=time.perf_counter() - t_start)
            self.history_.append(record)
            self._notify(record)
        m, w, sols, self.best_iteration_ = best
        self._w_fit = w  # removed features keep a weight > 0 here, for the multiplicative step
        self.weights_ = self._effective(w)
        self.tasks_, self.task_of_demo_, self._channels = tasks, self._of.copy(), channels
        # which demonstrations were compared with their rollout as recorded (a rollout whose demonstrations were all
        # cut at one threshold); the others with the whole rollout, whatever `observe` says
        self.observed_ = np.array([self._thresholds[r] is not None for r in self._of], dtype=bool)
        self._x_demos, self._guesses = x_demos, guesses
        self.merit_ = m
        self.initial_merit_ = self.history_[0]["merit"]
        self.n_accepted_ = n_accepted
        self.n_doc_solves_ = n_solves
        self.n_doc_failures_ = n_fail
        self.n_doc_recovered_ = n_rescued
        self.n_iter_ = len(self.history_) - 1
        self.train_solutions_ = sols
        self.plain_fit_ = None
        best_iteration, initial_merit = self.best_iteration_, self.initial_merit_
        if plain is not None:
            self.plain_fit_ = {
                "merit": plain.merit_,
                "initial_merit": plain.initial_merit_,
                "n_iter": plain.n_iter_,
                "n_accepted": plain.n_accepted_,
                "stop_reason": plain.stop_reason_,
                "weights": plain.weights_.tolist(),
                "history": plain.history_,  # its iteration 0 is ω₀; the observed stage's starts where it ended
            }
            # the flag judges both stages: ω₀ only if neither moved, one step only if they made one between them
            n_accepted += plain.n_accepted_
            self.n_accepted_ = n_accepted
            best_iteration = self.best_iteration_ + plain.best_iteration_
            initial_merit = plain.initial_merit_ if best_iteration == plain.best_iteration_ else initial_merit
        self.flag_ = fit_flag(best_iteration, n_accepted)
        self.warnings_ = fit_warnings(best_iteration, n_accepted, initial_merit, m)
        if not getattr(self, "_first_stage", False):  # the first stage of an observed fit is judged with it
            for msg in self.warnings_:
                log_fit_warning(log, msg)

    def _line_search(
        self, w, dw, m, sols, tasks, x_demos, phi_star, starts, guesses, channels, tol: float | None = None
    ) -> _Step:
        """``α = α0, α0·shrink, …`` (at most ``max_tries``): the first ``ω + αΔω`` whose DOC rollout lowers the
        merit by more than ``tol`` (relative; or passes the "either" test) is accepted. A try whose DOC fails
        even after the cold and demonstration-path retries counts as a failure and is rejected.
        ``ω + αΔω > 0`` since ``Δω > −ω``. The search ends when a try would move no weight by ``min_step``, and
        (merit acceptance) when a try's merit is no lower than the longer try's before it: along a unimodal
        merit no shorter step can then pass (a failed try, whose merit is unknown, does not end it)."""
        alpha, solves, failures, recovered = self._o.alpha0, 0, 0, 0
        tol = self._tol if tol is None else tol
        rel = float(np.max(np.abs(dw / w)))
        m_prev = np.inf  # the previous (longer) try's merit
        for tries in range(1, self._o.max_tries + 1):
            if alpha * rel < self._o.min_step:  # no weight moves by min_step: the merit cannot move beyond noise
                return _Step(False, 0.0, tries - 1, w, sols, m, solves, failures, recovered)
            w_try = w + alpha * dw
            cand, runs, rescued = self._rollouts(tasks, w_try, sols, guesses)
            solves += runs
            recovered += rescued
            failed = sum(not s.converged for s in cand)
            failures += failed
            m_try = self._merit(x_demos, cand, channels, tasks)
            if m_try < m * (1.0 - tol) or (
                failed == 0
                and (
                    self._accept_either(w, dw, alpha, tasks, sols, cand, phi_star, starts)
                    or self._accept_multimodal(m, m_try, sols, cand)
                )
            ):
                return _Step(True, alpha, tries, w_try, cand, m_try, solves, failures, recovered)
            if self._o.line_search_stop and self._o.acceptance == "merit" and np.isfinite(m_try) and m_try >= m_prev:
                # this shorter try did no better than the longer one: along a unimodal merit the best step is
                # longer than this one, so no shorter try can pass where these two did not
                return _Step(False, 0.0, tries, w, sols, m, solves, failures, recovered)
            m_prev = m_try
            alpha *= self._o.shrink
        return _Step(False, 0.0, self._o.max_tries, w, sols, m, solves, failures, recovered)

    def _merit_step(self, w, m, sols, tasks, x_demos, phi_star, starts, guesses, channels, ratio) -> _Step:
        """The step when the likelihood's lowers no merit (or, with the Gauss-Newton model, less than
        ``fallback_tol``): a step from a local model of the merit,
        bounded by ``log ρ`` in log-weights (``ρ`` the trust region's ratio, at least 1.1), line-searched as a
        likelihood step would be. The model (``merit_model``):

        * ``"gauss-newton"``: each rollout's derivative along every log-weight (:func:`reachirl.doc.sensitivity
          .weight_jacobian`, seen as the demonstrations were recorded: :func:`reachirl.doc.observation
          .observed_state_jacobian`) gives the Gauss-Newton model of the merit in all ``S × 7`` log-weights
          (:func:`reachirl.irl.objective.gauss_newton_step`); no DOC is solved for it.
        * ``"probes"``: rollouts with each feature's weight (in every window) scaled by ``ρ^{±1}`` give a
          per-feature quadratic model (:func:`reachirl.irl.objective.merit_model_step`): ``2 × 7`` DOC solves
          per rollout. Also the Gauss-Newton model's fallback where a sensitivity cannot be had.

        Returns the line search's outcome, with the model's solves counted."""
        h = max(float(np.log(ratio)), float(np.log(1.1)))  # probes well above the DOC's repeatability
        free = self._movable(w.shape)
        eta = (
            self._gauss_newton(w, sols, tasks, x_demos, channels, h, free)
            if self._o.merit_model == "gauss-newton"
            else None
        )
        solves = failures = 0
        if eta is None:
            mp, mm = np.full(N_FEATURES, np.inf), np.full(N_FEATURES, np.inf)
            for j in np.flatnonzero(free.any(axis=0)):
                for sign, out in ((1.0, mp), (-1.0, mm)):
                    wj = w.copy()
                    wj[free[:, j], j] *= np.exp(sign * h)
                    cand, runs, _ = self._rollouts(tasks, wj, sols, guesses)
                    solves += runs
                    failures += sum(not c.converged for c in cand)
                    out[j] = self._merit(x_demos, cand, channels, tasks)
            eta = np.broadcast_to(merit_model_step(m, mp, mm, h), w.shape)  # no probe (nothing free): η = 0
        dw = np.where(free, w * np.expm1(eta), 0.0)
        if _is_rescale(w, dw):
            return _Step(False, 0.0, 0, w, sols, m, solves, failures, 0)
        step = self._line_search(
            w,
            dw,
            m,
            sols,
            tasks,
            x_demos,
            phi_star,
            starts,
            guesses,
            channels,
            tol=max(self._tol, self._o.fallback_tol),
        )
        return step._replace(solves=step.solves + solves, failures=step.failures + failures)

    def _gauss_newton(self, w, sols, tasks, x_demos, channels, h, free) -> np.ndarray | None:
        """The Gauss-Newton log-step ``(S, 7)`` of the merit at ``ω`` (zero where ``free`` is False), or ``None``
        when a rollout's sensitivity cannot be had (a degenerate optimum)."""
        cols = np.flatnonzero(free.reshape(-1))
        if cols.size == 0:
            return None
        n1 = self.n_nodes + 1
        scale = np.sqrt(np.ones(4) if channels is None else np.asarray(channels, dtype=float)) / np.sqrt(n1)
        states, jacs = [], []
        for i, (task, sol) in enumerate(zip(tasks, sols, strict=True)):
            try:
                dq = weight_jacobian(task, w, sol).reshape(n1, 2, -1)[:, :, cols]
            except ValueError as e:
                log.info("no Gauss-Newton model (%s): probing the merit instead", e)
                return None
            states.append(self._state(i, task, sol))
            jacs.append(
                (observed_state_jacobian(sol, task, self._thresholds[i], dq) * scale[None, :, None]).reshape(
                    -1, cols.size
                )
            )
        states, jacs = [states[r] for r in self._of], [jacs[r] for r in self._of]  # each demonstration's rollout
        residuals = np.stack([((x - xd) * scale).reshape(-1) for x, xd in zip(states, x_demos, strict=True)])
        eta = np.zeros(w.size)
        eta[cols] = gauss_newton_step(residuals, np.stack(jacs), h)
        return eta.reshape(w.shape)

    def _movable(self, shape: tuple[int, int]) -> np.ndarray:
        """Which weights a step may change: those of the features in the cost, outside the frozen windows."""
        free = self._mask.copy()
        free[list(self._o.frozen_windows), :] = False
        return free

    def _notify(self, record: dict) -> None:
        log.info(
            "iteration %d: merit %.5g alpha %.3g tries %d",
            record["iteration"],
            record["merit"],
            record["alpha"],
            record["tries"],
        )
        if self.callback is not None:
            self.callback(record)

    def _accept_either(self, w, dw, alpha, tasks, old, new, phi_star, starts) -> bool:
        """``acceptance="either"``: feature mismatch decreased, or cost mismatch under Armijo + curvature."""
        if self._o.acceptance != "either":
            return False
        f_old = self._features(tasks, old, starts)
        f_new = self._features(tasks, new, starts)
        if self._o.n_suffixes:
            f_old, f_new, ps = f_old[:, 0], f_new[:, 0], phi_star[:, 0]
        else:
            ps = phi_star
        target = ps.mean(axis=0)
        if np.sum((target - f_new.mean(axis=0)) ** 2) < np.sum((target - f_old.mean(axis=0)) ** 2):
            return True
        w_new = w + alpha * dw
        d_old = np.sum(w * (target - f_old.mean(axis=0)))
        d_new = np.sum(w_new * (target - f_new.mean(axis=0)))
        g0 = d_old * np.sum(dw * (target - f_old.mean(axis=0)))  # d/dα of ½(ωᵀ(Φ*−Φ̃))² at α = 0, Φ̃ held
        g1 = d_new * np.sum(dw * (target - f_new.mean(axis=0)))
        armijo = 0.5 * d_new**2 <= 0.5 * d_old**2 + self._o.armijo_c1 * alpha * g0
        curvature = abs(g1) <= self._o.curvature_c2 * abs(g0)
        return bool(g0 < 0 and armijo and curvature)

    def _accept_multimodal(self, m: float, m_try: float, old, new) -> bool:
        """``acceptance="multimodal"``: :func:`multimodal_accept` on the state and torque merits."""
        if self._o.acceptance != "multimodal" or self._tau_demos is None:
            return False

        def tau_merit(sols):
            tau = sols[0].tau if len(sols) == 1 else np.stack([sols[r].tau for r in self._of])
            return merit(self._tau_demos, tau)

        return multimodal_accept(m, m_try, tau_merit(old), tau_merit(new), self._tol)


def multimodal_accept(m: float, m_try: float, t: float, t_try: float, tol: float = 0.0) -> bool:
    """Multimodal step acceptance: the mean relative change of the state merit (``m → m_try``) and of a second
    channel's merit (``t → t_try``, e.g. torque) is a fall by more than ``tol``:
    ``½ (m_try/m + t_try/t) < 1 − tol``. False when a merit is not finite and positive."""
    vals = np.array([m, m_try, t, t_try], dtype=float)
    if not np.all(np.isfinite(vals)) or m <= 0 or t <= 0:
        return False
    return bool(0.5 * (m_try / m + t_try / t) < 1.0 - tol)


def _is_rescale(w: np.ndarray, dw: np.ndarray, rtol: float = 1e-9) -> bool:
    """Whether ``ω + Δω`` is ``ω`` times one common factor (a step the DOC cannot see)."""
    ratio = (w + dw) / w
    return bool(np.ptp(ratio) <= rtol * np.max(np.abs(ratio)))


def mixed_postures_warning(trials: Sequence[Trial], other_rollouts: bool = True) -> str | None:
    """The warning for demonstrations of several postures fitted through one mean-task rollout, or ``None``.
    ``other_rollouts``: the method can roll out otherwise (MO-IRL, MaxEnt), so the warning names it; bilevel
    cannot (it has no ``--rollout``), and is pointed to a method that can."""
    postures = sorted({t.posture for t in trials})
    if len(postures) < 2:
        return None
    other = (
        "or use one rollout per posture or per demonstration (--rollout per_task, per_demo)"
        if other_rollouts
        else "or learn one cost shared by them with moirl or maxent (one rollout per posture; bilevel has only the one)"
    )
    return (
        f"the demonstrations span {len(postures)} postures ({', '.join(postures)}): the one training rollout "
        f"starts from their mean posture, which none of them has; fit each posture apart (reachirl fit "
        f"--posture), {other}"
    )


def uncut_trials_warning(trials: Sequence[Trial], groups: np.ndarray, thresholds: Sequence) -> str | None:
    """The warning for a rollout that cannot be observed because some of its demonstrations were not cut at a
    speed threshold (a record without rest before or after the reach) while others were: the rollout is then
    compared whole with all of them (:func:`~reachirl.doc.observation.common_threshold`), or ``None``."""
    uncut, cut = [], 0
    for r, th in enumerate(thresholds):
        members = [t for t, g in zip(trials, groups, strict=True) if g == r]
        if th is None and any(t.onset_threshold is not None for t in members):
            uncut += [t.id for t in members if t.onset_threshold is None]
            cut += sum(t.onset_threshold is not None for t in members)
    if not uncut:
        return None
    shown = ", ".join(uncut[:5]) + (f" and {len(uncut) - 5} more" if len(uncut) > 5 else "")
    return (
        f"{len(uncut)} trial(s) not cut at a speed threshold (no rest before or after the reach: {shown}) share "
        f"a training rollout with {cut} that were: that rollout is compared whole with all of them, not as they "
        "were recorded (observed rollouts); leave those trials out, or fit one rollout per trial (--rollout per_demo)"
    )


def fit_flag(best_iteration: int, n_accepted: int) -> str | None:
    """``"w0"`` for a fit whose weights are still the initial ones, ``"one_step"`` for a fit that made a single
    step, ``None`` otherwise (the marker the tables and figures show)."""
    if best_iteration == 0:
        return "w0"
    if n_accepted == 1:
        return "one_step"
    return None


def cv_fold_warning(warned: Sequence[str], n_fits: int, smoothness: float) -> str | None:
    """The one warning of a ``smoothness="cv"`` fit about its fold fits' own warnings (``warned``, each fold fit's
    :func:`fit_warnings`), counted by kind, or ``None`` when no fold fit warned: ``smoothness`` was chosen on
    their predictions."""
    if not warned:
        return None
    kinds = Counter(msg.split(":")[0].split(" (")[0] for msg in warned)
    counts = ", ".join(f"{n} {kind}" for kind, n in kinds.items())
    return (
        f"smoothness cross-validation: {len(warned)} of {n_fits} fold fits were not fully learned ({counts}), so "
        f"smoothness {smoothness:g} was chosen partly on weights that were not learned"
    )


def fit_warnings(best_iteration: int, n_accepted: int, initial_merit: float, final_merit: float) -> list[str]:
    """What a reader of a fit must be told: weights that are still ``ω₀`` (no step improved the merit) are not
    learned; a fit that made one step only was not refined (no second step lowered the merit)."""
    if best_iteration == 0:
        return ["never left the initial weights: no step lowered the merit, so these weights are w0, not learned"]
    if n_accepted == 1:
        gain = 100.0 * (1.0 - final_merit / initial_merit) if np.isfinite(initial_merit) and initial_merit else 0.0
        return [
            f"stopped after one step (merit {gain:.1f} % below w0's): no second step lowered the merit, so "
            "these weights were not refined"
        ]
    return []
