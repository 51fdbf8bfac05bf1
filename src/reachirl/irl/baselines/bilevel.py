"""Bilevel inverse optimal control (Mombaur et al. 2010; Berret et al. 2011): a derivative-free outer search
over the weights, with a full DOC solved at every evaluation.

The outer problem minimises MO-IRL's own merit (:func:`reachirl.irl.objective.merit`): the mean squared state
error ``(1/D) Σ_d (1/N) ‖x*_d − x(ω)‖²`` between the demonstrations and the DOC rollout on the demonstrations'
mean task (:func:`reachirl.irl.moirl.mean_task`), the same rollout MO-IRL uses by default. The search runs on
log-weights around MO-IRL's start, ``ω = w0 · exp(θ)`` with ``θ₀ = 0``, so the weights stay positive and each
coordinate moves in relative terms; ``θ`` is bounded to ``±log_bound`` (default ``log 1e4``: four decades
either way), which keeps the DOC away from weights it cannot solve. Berret used CONDOR; here scipy's Powell
(default) or Nelder-Mead, capped at ``max_evals`` DOC solves and, when given, at ``max_iter`` outer iterations of
the direct search (default None: the DOC-solve budget alone stops it). Each DOC is warm-started from the previous
converged one and retried cold if that fails (both count as solves); a DOC that still fails scores
``failure_merit`` times the initial merit (finite, so the direct-search line searches stay well defined).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence

import numpy as np

from ...data.trial import Trial
from ...doc import DocSolution, solve_doc
from ...doc.observation import observed_knots
from ...features import N_FEATURES, windowed_features
from ..base import WeightEstimator, log_fit_warning
from ..moirl import demonstration_states, mean_task, mixed_postures_warning
from ..objective import merit

__all__ = ["BilevelIOC"]

log = logging.getLogger(__name__)

METHODS = ("powell", "nelder-mead")


class _BudgetError(Exception):
    """Raised inside the objective when the DOC budget is spent."""


class BilevelIOC(WeightEstimator):
    """Derivative-free bilevel IOC with ``n_windows`` time windows of weights.

    Fitted attributes: ``weights_`` (the best evaluated), ``merit_``, ``history_`` (one record per evaluation:
    merit, converged, weights, cumulative DOC solves, wall time), ``n_doc_solves_``, ``n_doc_failures_``,
    ``n_iter_`` (outer iterations of the direct search), ``fit_time_``, ``stop_reason_``, ``warnings_`` (demonstrations
    of several postures behind the one mean-task rollout: :func:`reachirl.irl.moirl.mixed_postures_warning`; a
    search stopped by ``max_evals`` or ``max_iter`` rather than converged).
    """

    def __init__(
        self,
        n_windows: int = 8,
        *,
        n_nodes: int = 100,
        max_evals: int = 400,
        max_iter: int | None = None,
        method: str = "powell",
        w0: float = 0.05,
        log_bound: float = float(np.log(1e4)),
        xtol: float = 1e-3,
        ftol: float = 1e-6,
        failure_merit: float = 10.0,
        backend: str = "casadi",
    ):
        self.n_windows = n_windows
        self.n_nodes = n_nodes
        self.max_evals = max_evals
        self.max_iter = max_iter
        self.method = method
        self.w0 = w0
        self.log_bound = log_bound
        self.xtol = xtol
        self.ftol = ftol
        self.failure_merit = failure_merit
        self.backend = backend

    def _check_params(self, trials: Sequence[Trial]) -> list[Trial]:
        trials = self._check_trials(trials)
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not isinstance(self.max_evals, int | np.integer) or isinstance(self.max_evals, bool) or self.max_evals < 2:
            raise ValueError(f"max_evals must be an integer >= 2, got {self.max_evals!r}")
        it = self.max_iter
        if it is not None and (not isinstance(it, int | np.integer) or isinstance(it, bool) or it < 1):
            raise ValueError(f"max_iter must be None or an integer >= 1, got {it!r}")
        for name, least in (("xtol", 0.0), ("ftol", 0.0), ("failure_merit", 1.0)):
            v = getattr(self, name)  # a failure merit under 1 would score a failed DOC better than the start
            ok = isinstance(v, int | float | np.number) and not isinstance(v, bool) and np.isfinite(v)
            if not (ok and (v >= least if least else v > 0)):
                raise ValueError(f"{name} must be a number {'>= 1' if least else '> 0'}, got {v!r}")
        for name, why in (("log_bound", ""), ("w0", " (the search is on log-weights)")):
            v = getattr(self, name)
            ok = isinstance(v, int | float | np.number) and not isinstance(v, bool) and bool(np.isfinite(v))
            if not (ok and v > 0):
                raise ValueError(f"{name} must be > 0{why} and finite, got {v!r}")
        return trials

    def reach_features(self) -> np.ndarray | None:
        """Φ ``(n_windows, 7)`` of the fit's own reach: the mean task's DOC under the learned weights."""
        self._check_fitted()
        return getattr(self, "_reach_phi", None)

    def fit(self, trials: Sequence[Trial], y=None) -> BilevelIOC:
        """Learn ``weights_`` from the demonstrations ``trials``; returns the estimator. ``y`` is ignored
        (scikit-learn's signature: the demonstrations are their own targets)."""
        trials = self._check_params(trials)
        t_start = time.perf_counter()
        task = mean_task(trials, self.n_nodes)
        x_demos = demonstration_states(trials, self.n_nodes)
        shape = (self.n_windows, N_FEATURES)
        self.history_ = []
        state: dict = {"warm": None, "best": (np.inf, None, None), "m0": None, "solves": 0}

        def evaluate(theta: np.ndarray) -> float:
            if state["solves"] >= self.max_evals:
                raise _BudgetError
            w = self.w0 * np.exp(np.clip(theta, -self.log_bound, self.log_bound)).reshape(shape)
            sol: DocSolution = solve_doc(task, w, backend=self.backend, warm_start=state["warm"], retry_cold=False)
            state["solves"] += 1
            if not sol.converged and state["warm"] is not None and state["solves"] < self.max_evals:
                sol = solve_doc(task, w, backend=self.backend)  # a distant warm start can mislead IPOPT
                state["solves"] += 1
            m = merit(x_demos, sol.state) if sol.converged else np.inf
            if sol.converged:
                state["warm"] = sol
            if state["m0"] is None:
                state["m0"] = m if np.isfinite(m) else 1.0
            if m < state["best"][0]:
                state["best"] = (m, w, sol)
            self.history_.append(
                {
                    "evaluation": len(self.history_) + 1,
                    "merit": m,
                    "converged": sol.converged,
                    "weights": w.tolist(),
                    "doc_solves": state["solves"],
                    "wall_time": time.perf_counter() - t_start,
                }
            )
            return m if np.isfinite(m) else self.failure_merit * state["m0"]

        theta0 = np.zeros(self.n_windows * N_FEATURES)
        if self.method == "powell":
            opts = {"maxfev": int(self.max_evals), "xtol": self.xtol, "ftol": self.ftol}
        else:
            opts = {"maxfev": int(self.max_evals), "xatol": self.xtol, "fatol": self.ftol, "adaptive": True}
        if self.max_iter is not None:  # else scipy's own bound (1000 per coordinate), which the budget reaches first
            opts["maxiter"] = int(self.max_iter)
        n_iter = 0

        def count(_xk) -> None:
            nonlocal n_iter
            n_iter += 1

        from scipy.optimize import minimize  # here: the command's own process never needs scipy.optimize

        try:
            bounds = [(-self.log_bound, self.log_bound)] * theta0.size
            res = minimize(
                evaluate,
                theta0,
                method="Powell" if self.method == "powell" else "Nelder-Mead",
                bounds=bounds,
                options=opts,
                callback=count,
            )
            self.stop_reason_ = "max_evals" if state["solves"] >= self.max_evals else str(res.message)
            if self.max_iter is not None and res.status == 2 and self.stop_reason_ != "max_evals":
                self.stop_reason_ = "max_iter"  # scipy's status 2 (Powell and Nelder-Mead): maxiter reached
            n_iter = int(getattr(res, "nit", n_iter))
        except _BudgetError:
            self.stop_reason_ = "max_evals"
        m_best, w_best, sol_best = state["best"]
        if w_best is None:  # no DOC converged: keep the start
            w_best = np.full(shape, float(self.w0))
        self.weights_ = w_best
        self.merit_ = m_best
        self.n_doc_solves_ = state["solves"]
        self.n_doc_failures_ = sum(not h["converged"] for h in self.history_)  # evaluations without a converged DOC
        self.n_iter_ = n_iter
        self.fit_time_ = time.perf_counter() - t_start
        self.train_solutions_ = [sol_best] if sol_best is not None else []
        # Φ of its reach (the mean task's DOC under the learned weights, whole: bilevel does not observe)
        self._reach_phi = (
            None
            if sol_best is None
            else windowed_features(task.arm, *observed_knots(sol_best, task, None), self.n_windows)
        )
        self.warnings_ = [msg] if (msg := mixed_postures_warning(trials, other_rollouts=False)) is not None else []
        if self.stop_reason_ == "max_evals":
            self.warnings_.append(
                f"stopped at its budget of {self.max_evals} DOC solves (max_evals) after {n_iter} complete "
                f"direct-search iteration(s): the weights are the best of {len(self.history_)} evaluated, not a "
                "converged optimum"
            )
        elif self.stop_reason_ == "max_iter":
            self.warnings_.append(
                f"stopped at its limit of {self.max_iter} direct-search iteration(s) (max_iter) after "
                f"{state['solves']} DOC solves: the weights are the best of {len(self.history_)} evaluated, not a "
                "converged optimum"
            )
        for msg in self.warnings_:  # as MO-IRL's: logged, unless the caller says them (reachirl fit, reproduce)
            log_fit_warning(log, msg)
        self._keep_fit_params()
        return self
