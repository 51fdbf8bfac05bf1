"""MO-IRL with time-varying weights (the seed paper's extended form), as a scikit-learn-style estimator.

One iteration (seed §II-C):

1. Features ``Φ_i`` of the generated trajectories in ``x̄`` (only the latest one, by default) and ``Φ*_d`` of the
   demonstrations, per window.
2. ``Δω*`` from the subproblem (:func:`reachirl.irl.objective.solve_delta`).
3. Line search: ``ω_α = ω + αΔω*`` with ``α = 1, 0.25, 0.25², …`` (at most ``max_tries``); each try solves the
   DOC and is accepted when the merit ``m(x) = (1/D) Σ_d (1/N) ‖x*_d − x‖²`` over ``(q1, q2, q̇1, q̇2)``
   decreases. The accepted rollout replaces ``x̄``. No accepted try ends the fit.

Choices the seed leaves open, fixed here (each an option):

* **The training rollout** (``rollout="mean"``): one DOC from the demonstrations' mean initial posture, mean
  target and mean duration, on their mean arm. ``rollout="per_demo"`` solves one DOC per demonstration from its
  own start, target and duration; each demonstration is then compared with its own rollout, in the subproblem and
  in the merit.
* **Time normalisation**: every demonstration is resampled to the DOC's ``N + 1`` knots over its own duration, so
  trials of different durations are compared at the same normalised times.
* **Feature scaling**: none. Features are raw SI quantities and the subproblem is solved on the raw weights;
  a rescaling of the features with the inverse rescaling of the weights would leave every DOC unchanged.
* **Tolerance**: the fit also stops when an accepted step improves the merit by less than ``tol`` (relative).

Options from the original MO-IRL (Mehrdad et al. 2025), all off by default so the seed's form is the default:
``l1`` (elastic-net λ), ``n_suffixes`` (suffix sub-sampling), ``acceptance="either"`` (also accept a step that
decreases the feature mismatch, or the cost mismatch under Armijo and curvature conditions) and ``memory``
(``x̄`` keeps the last ``memory`` trajectories; ``None`` keeps them all).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import fields
from typing import NamedTuple

import numpy as np

from ..arm import ArmModel
from ..data.trial import Trial
from ..doc import DocSolution, ReachingTask, solve_doc
from ..features import N_FEATURES, feature_rates, window_index, windowed_features
from .base import WeightEstimator
from .objective import merit, solve_delta

__all__ = ["MOIRL", "demonstration_states", "mean_task"]

log = logging.getLogger(__name__)


def mean_task(trials: Sequence[Trial], n_nodes: int) -> ReachingTask:
    """The DOC task at the demonstrations' mean arm, initial posture, target and duration."""
    arms = [t.arm for t in trials]
    arm = ArmModel(**{f.name: float(np.mean([getattr(a, f.name) for a in arms])) for f in fields(ArmModel)})
    q0 = np.mean([t.x0[:2] for t in trials], axis=0)
    return ReachingTask(
        arm, q0, float(np.mean([t.target_x for t in trials])), float(np.mean([t.duration for t in trials])),
        n_nodes=n_nodes,
    )


def demonstration_states(trials: Sequence[Trial], n_nodes: int) -> np.ndarray:
    """Demonstrations on the DOC's normalised knots, ``(D, N+1, 4)`` of ``(q1, q2, q̇1, q̇2)``."""
    return np.stack([t.resample(n_nodes + 1).state for t in trials])


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


class MOIRL(WeightEstimator):
    """Minimal Observation IRL with ``n_windows`` time windows of weights.

    Parameters follow the seed: ``beta=1e-10``, ``w0=0.05``, ``alpha0=1``, ``shrink=0.25``, ``max_tries=10``.
    ``callback(iteration_record)`` is called after every iteration (for progress bars). The fit makes no
    random choice: the same demonstrations give the same weights (the protocol's trial split takes a seed).

    Fitted attributes: ``weights_ (n_windows, 7)`` (those of the best merit seen), ``history_`` (one dict per
    iteration: merit, alpha, tries, weights, DOC solves (every solver run), failures, wall time), ``merit_``,
    ``best_iteration_``, ``n_doc_solves_``, ``n_iter_``, ``stop_reason_``.
    """

    def __init__(
        self,
        n_windows: int = 8,
        *,
        n_nodes: int = 100,
        max_iter: int = 30,
        tol: float = 1e-5,
        beta: float = 1e-10,
        w0: float = 0.05,
        alpha0: float = 1.0,
        shrink: float = 0.25,
        max_tries: int = 10,
        rollout: str = "mean",
        memory: int | None = 1,
        use_gamma: bool = True,
        l1: float = 0.0,
        n_suffixes: int = 0,
        acceptance: str = "merit",
        armijo_c1: float = 1e-4,
        curvature_c2: float = 0.9,
        backend: str = "casadi",
        callback: Callable[[dict], None] | None = None,
    ):
        self.n_windows = n_windows
        self.n_nodes = n_nodes
        self.max_iter = max_iter
        self.tol = tol
        self.beta = beta
        self.w0 = w0
        self.alpha0 = alpha0
        self.shrink = shrink
        self.max_tries = max_tries
        self.rollout = rollout
        self.memory = memory
        self.use_gamma = use_gamma
        self.l1 = l1
        self.n_suffixes = n_suffixes
        self.acceptance = acceptance
        self.armijo_c1 = armijo_c1
        self.curvature_c2 = curvature_c2
        self.backend = backend
        self.callback = callback

    # ------------------------------------------------------------------ helpers
    def _check_params(self, trials: Sequence[Trial]) -> list[Trial]:
        trials = self._check_trials(trials)
        if self.rollout not in ("mean", "per_demo"):
            raise ValueError(f"rollout must be 'mean' or 'per_demo', got {self.rollout!r}")
        if self.acceptance not in ("merit", "either"):
            raise ValueError(f"acceptance must be 'merit' or 'either', got {self.acceptance!r}")
        if self.memory is not None and self.memory < 1:
            raise ValueError(f"memory must be >= 1 or None, got {self.memory}")
        if not 0 < self.shrink < 1 or self.max_tries < 1:
            raise ValueError(f"need 0 < shrink < 1 and max_tries >= 1, got {self.shrink} and {self.max_tries}")
        if not self.w0 > 0 or not 0 < self.alpha0 <= 1:
            raise ValueError(f"need w0 > 0 and 0 < alpha0 <= 1 (weights stay > 0), got {self.w0} and {self.alpha0}")
        return trials

    def _tasks(self, trials: Sequence[Trial]) -> list[ReachingTask]:
        if self.rollout == "mean":
            return [mean_task(trials, self.n_nodes)]
        return [ReachingTask.from_trial(t, self.n_nodes) for t in trials]

    def _rollouts(self, tasks, w, warm: list[DocSolution] | None) -> list[DocSolution]:
        """DOC rollouts; line-search tries (``warm`` given) are not retried cold: a failed try is rejected."""
        return [
            solve_doc(task, w, backend=self.backend, warm_start=None if warm is None else warm[i],
                      retry_cold=warm is None)
            for i, task in enumerate(tasks)
        ]

    def _features(self, tasks, sols: list[DocSolution], starts: np.ndarray) -> np.ndarray:
        """Features of each rollout: ``(R, n_windows, 7)``, or with suffixes ``(R, 1 + n_suffixes, S, 7)``."""
        out = []
        for task, sol in zip(tasks, sols, strict=True):
            if self.n_suffixes:
                rates = feature_rates(task.arm, sol.q, sol.qd, sol.tau, task.dt)
                out.append(_suffix_features(rates, task.dt, self.n_windows, starts))
            else:
                out.append(windowed_features(task.arm, sol.q, sol.qd, sol.tau, task.dt, self.n_windows))
        return np.stack(out)

    def _demo_features(self, trials: Sequence[Trial], starts: np.ndarray) -> np.ndarray:
        out = []
        for t in trials:
            if self.n_suffixes:
                q, qd, tau = t.knots(self.n_nodes)
                dt = t.duration / self.n_nodes
                out.append(_suffix_features(feature_rates(t.arm, q, qd, tau, dt), dt, self.n_windows, starts))
            else:
                out.append(t.features(self.n_nodes, self.n_windows))
        return np.stack(out)

    def _merit(self, x_demos: np.ndarray, sols: list[DocSolution]) -> float:
        if any(not s.converged for s in sols):
            return np.inf
        x = sols[0].state if self.rollout == "mean" else np.stack([s.state for s in sols])
        return merit(x_demos, x)

    def _subproblem_terms(self, phi_star: np.ndarray, bank: list[np.ndarray], starts: np.ndarray):
        """Stack (demonstration, trajectory) pairs into the arrays the subproblem takes.

        Returns a list of ``(phi_i (I,S,7), phi_star (D',S,7), term_weights (D',))`` groups.
        """
        n_demo = phi_star.shape[0]
        suffix_w = None
        if self.n_suffixes:
            T = self.n_nodes
            suffix_w = (T - starts + 1) / (T + 1)
        groups = []
        if self.rollout == "mean":
            phi_i = np.stack([b[0] for b in bank])  # (I, [K,] S, 7)
            if self.n_suffixes:
                for k in range(len(starts)):
                    groups.append((phi_i[:, k], phi_star[:, k], np.full(n_demo, suffix_w[k])))
            else:
                groups.append((phi_i, phi_star, np.ones(n_demo)))
        else:
            for d in range(n_demo):
                phi_i = np.stack([b[d] for b in bank])
                if self.n_suffixes:
                    for k in range(len(starts)):
                        groups.append((phi_i[:, k], phi_star[d : d + 1, k], np.array([suffix_w[k]])))
                else:
                    groups.append((phi_i, phi_star[d : d + 1], np.ones(1)))
        return groups

    # ------------------------------------------------------------------ fit / predict
    def fit(self, trials: Sequence[Trial]) -> MOIRL:
        trials = self._check_params(trials)
        t_start = time.perf_counter()
        tasks = self._tasks(trials)
        x_demos = demonstration_states(trials, self.n_nodes)
        starts = np.array([0]) if not self.n_suffixes else np.unique(
            np.linspace(0, self.n_nodes * 0.9, self.n_suffixes + 1).astype(int)
        )
        phi_star = self._demo_features(trials, starts)

        w = np.full((self.n_windows, N_FEATURES), float(self.w0))
        sols = self._rollouts(tasks, w, None)
        n_solves, n_fail = sum(s.attempts for s in sols), sum(not s.converged for s in sols)
        m = self._merit(x_demos, sols)
        best = (m, w, sols, 0)  # the fit returns the best merit seen ("either" acceptance can raise it)
        bank = [self._features(tasks, sols, starts)]
        self.history_ = [
            {"iteration": 0, "merit": m, "alpha": 0.0, "tries": 0, "accepted": True, "weights": w.tolist(),
             "doc_solves": n_solves, "doc_failures": n_fail, "wall_time": time.perf_counter() - t_start}
        ]
        if not np.isfinite(m):
            log.warning("the DOC at the initial weights did not converge")
        self.stop_reason_ = "max_iter"
        for it in range(1, self.max_iter + 1):
            # Δω* from the subproblem (seed Eq. 4), then ω ← ω + αΔω* with α from the line search on the merit
            dw, info = solve_delta(w, self._subproblem_terms(phi_star, bank, starts), self.beta, self.use_gamma,
                                   self.l1)
            step = self._line_search(w, dw, m, sols, tasks, x_demos, phi_star, starts)
            n_solves += step.solves
            n_fail += step.failures
            accepted, alpha, tries = step.accepted, step.alpha, step.tries
            w_try, cand, m_try = step.weights, step.solutions, step.merit
            record = {"iteration": it, "alpha": alpha if accepted else 0.0, "tries": tries, "accepted": accepted,
                      "subproblem_iterations": info["nit"], "doc_solves": n_solves, "doc_failures": n_fail}
            if not accepted:
                record.update(merit=m, weights=w.tolist(), wall_time=time.perf_counter() - t_start)
                self.history_.append(record)
                self._notify(record)
                self.stop_reason_ = "no_improving_step"
                break
            improvement = (m - m_try) / m if np.isfinite(m) and m > 0 else np.inf
            w, sols, m = w_try, cand, m_try
            if m < best[0]:
                best = (m, w, sols, it)
            bank.append(self._features(tasks, sols, starts))
            if self.memory is not None:
                bank = bank[-self.memory :]
            record.update(merit=m, weights=w.tolist(), wall_time=time.perf_counter() - t_start)
            self.history_.append(record)
            self._notify(record)
            if 0 <= improvement < self.tol:  # a step accepted on another criterion (worse merit) goes on
                self.stop_reason_ = "tol"
                break
        m, w, sols, self.best_iteration_ = best
        self.weights_ = w
        self.merit_ = m
        self.n_doc_solves_ = n_solves
        self.n_doc_failures_ = n_fail
        self.n_iter_ = len(self.history_) - 1
        self.fit_time_ = time.perf_counter() - t_start
        self.train_solutions_ = sols
        return self

    def _line_search(self, w, dw, m, sols, tasks, x_demos, phi_star, starts) -> _Step:
        """``α = α0, α0·shrink, …`` (at most ``max_tries``): the first ``ω + αΔω`` whose DOC rollout lowers the
        merit (or passes the "either" test) is accepted. ``ω + αΔω > 0`` since ``Δω ≥ −(1 − min_ratio) ω``."""
        alpha, solves, failures = self.alpha0, 0, 0
        for tries in range(1, self.max_tries + 1):
            w_try = w + alpha * dw
            cand = self._rollouts(tasks, w_try, sols)
            solves += sum(s.attempts for s in cand)
            failed = sum(not s.converged for s in cand)
            failures += failed
            m_try = self._merit(x_demos, cand)
            if m_try < m or (failed == 0 and self._accept_either(w, dw, alpha, tasks, sols, cand, phi_star, starts)):
                return _Step(True, alpha, tries, w_try, cand, m_try, solves, failures)
            alpha *= self.shrink
        return _Step(False, 0.0, self.max_tries, w, sols, m, solves, failures)

    def _notify(self, record: dict) -> None:
        log.info("iteration %d: merit %.5g alpha %.3g tries %d", record["iteration"], record["merit"],
                 record["alpha"], record["tries"])
        if self.callback is not None:
            self.callback(record)

    def _accept_either(self, w, dw, alpha, tasks, old, new, phi_star, starts) -> bool:
        """``acceptance="either"``: feature mismatch decreased, or cost mismatch under Armijo + curvature."""
        if self.acceptance != "either":
            return False
        f_old = self._features(tasks, old, starts)
        f_new = self._features(tasks, new, starts)
        if self.n_suffixes:
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
        armijo = 0.5 * d_new**2 <= 0.5 * d_old**2 + self.armijo_c1 * alpha * g0
        curvature = abs(g1) <= self.curvature_c2 * abs(g0)
        return bool(g0 < 0 and armijo and curvature)
