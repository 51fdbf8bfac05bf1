"""Prediction error of learned weights on trials: joint-angle RMSE in degrees, as in the seed's Table II.

Each trial is predicted by the DOC from its own arm, initial posture, target and duration; the trial is
resampled onto the DOC's knots (normalised time) and compared there.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..data.trial import Trial
from . import DocSolution
from .observation import predict

__all__ = ["TrialError", "evaluate_trials", "rmse_deg", "summarise"]


@dataclass(frozen=True)
class TrialError:
    trial_id: str
    rmse_q1: float
    rmse_q2: float
    rmse_q: float
    converged: bool
    prediction: DocSolution

    def to_dict(self) -> dict:
        return {
            "id": self.trial_id,
            "rmse_deg": {"q1": self.rmse_q1, "q2": self.rmse_q2, "q": self.rmse_q},
            "converged": self.converged,
        }


def rmse_deg(q_pred: np.ndarray, q_true: np.ndarray) -> tuple[float, float, float]:
    """RMSE (degrees) of q1, q2 and of q = [q1, q2] (all samples of both joints)."""
    err = np.rad2deg(np.asarray(q_pred) - np.asarray(q_true))
    per_joint = np.sqrt(np.mean(err**2, axis=0))
    return float(per_joint[0]), float(per_joint[1]), float(np.sqrt(np.mean(err**2)))


def evaluate_trials(
    weights: np.ndarray,
    trials: Sequence[Trial],
    n_nodes: int = 100,
    backend: str = "casadi",
    on_trial: Callable[[TrialError], None] | None = None,
    observe: bool = False,
    path: np.ndarray | None = None,
) -> list[TrialError]:
    """Predict every trial from its own initial state and measure the RMSE against it. With ``observe``, a trial
    cut from its recording at a speed threshold (``Trial.onset_threshold``) is predicted as it was recorded
    (:mod:`reachirl.doc.observation`): the rest-to-rest DOC's own onset-to-offset part.

    Each DOC starts cold: from the minimum-jerk path, or from ``path`` (``(n_nodes + 1, 2)``, a reach under
    these weights on the same knots, such as the fit's own rollout) moved to the trial's start and bar
    (:func:`reachirl.doc.task.moved_path`), which takes fewer iterations to the same optimum."""
    if isinstance(trials, Trial | str) or not isinstance(trials, Iterable):
        raise TypeError(f"evaluate takes a sequence of Trial, got a {type(trials).__name__}")
    trials = list(trials)
    for i, trial in enumerate(trials):
        if not isinstance(trial, Trial):
            raise TypeError(f"evaluate takes a sequence of Trial, got a {type(trial).__name__} at index {i}")
    out = []
    for trial in trials:  # each from a cold start: another reach's solution is a poor warm start
        _, sol = predict(trial, weights, n_nodes, trial.onset_threshold if observe else None, backend, path=path)
        e = TrialError(trial.id, *rmse_deg(sol.q, trial.q_at(n_nodes + 1)), converged=sol.converged, prediction=sol)
        out.append(e)
        if on_trial is not None:
            on_trial(e)
    return out


def summarise(errors: Sequence[TrialError], include_failed: bool = False) -> dict:
    """``{"n_trials", "n_included", "doc_failures", "failures_included", "rmse_deg": {"q1"|"q2"|"q": {"mean",
    "std"}}}`` (population SD).

    A prediction whose DOC did not converge is not an answer of the model: it is counted in ``doc_failures`` and
    left out of the RMSE statistics unless ``include_failed``. With no prediction left, mean and SD are None.
    """
    kept = [e for e in errors if include_failed or e.converged]

    def stats(key: str) -> dict:
        if not kept:
            return {"mean": None, "std": None}
        v = np.array([getattr(e, f"rmse_{key}") for e in kept])
        return {"mean": float(np.mean(v)), "std": float(np.std(v))}

    return {
        "n_trials": len(errors),
        "n_included": len(kept),
        "doc_failures": int(sum(not e.converged for e in errors)),
        "failures_included": bool(include_failed),
        "rmse_deg": {k: stats(k) for k in ("q1", "q2", "q")},
    }
