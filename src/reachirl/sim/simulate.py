"""Predict trials with the DOC and play the predictions back in MuJoCo: the library side of ``reachirl
simulate``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data.trial import Trial
from ..doc import DocSolution
from ..doc.observation import predict
from .playback import PlaybackResult, playback
from .render import RenderClip, render_frames, write_animation

__all__ = ["TrialSimulation", "render_simulations", "simulate_trial"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrialSimulation:
    """A trial's DOC prediction, its MuJoCo playback, and MuJoCo's joint angles at every simulation step."""

    trial: Trial
    solution: DocSolution
    result: PlaybackResult
    trace_t: np.ndarray
    trace_q: np.ndarray

    def summary(self) -> dict:
        s = self.solution
        return {
            "id": self.trial.id,
            "doc": {
                "backend": s.backend,
                "converged": bool(s.converged),
                "iterations": int(s.iterations),
                "solve_time_s": float(s.solve_time),
                "cost": float(s.cost),
            },
            "mujoco": self.result.summary(),
        }


def simulate_trial(
    trial: Trial,
    weights: np.ndarray,
    n_nodes: int = 100,
    backend: str = "casadi",
    mode: str = "open-loop",
    substeps: int = 10,
    kp: float = 50.0,
    kd: float = 5.0,
    observe: bool = False,
    path: np.ndarray | None = None,
) -> TrialSimulation:
    """Predict ``trial`` as :func:`reachirl.doc.evaluation.evaluate_trials` does (``observe`` and ``path`` as
    there; a model's are :attr:`~reachirl.irl.model.LearnedModel.observe` and ``rollout_q``) and play that
    prediction's torques in MuJoCo from its first state: with ``observe``, the DOC's part above the trial's onset
    threshold, the reach whose RMSE ``evaluate`` reports."""
    threshold = trial.onset_threshold if observe else None
    whole, sol = predict(trial, weights, n_nodes, threshold, backend, path=path)
    if not whole.converged:
        log.warning("trial %s: the DOC did not converge (%s)", trial.id, whole.status)
    result, trace = playback(
        trial.arm, sol, mode=mode, substeps=substeps, kp=kp, kd=kd, target_x=trial.target_x, record=True
    )
    trace_t = np.linspace(0.0, float(sol.t[-1]), trace.shape[0])
    return TrialSimulation(trial=trial, solution=sol, result=result, trace_t=trace_t, trace_q=trace)


def _demo_interpolant(trial: Trial, duration: float):
    """The trial's joint angles at a time of a ``duration``-long playback, on normalised time (as predictions are
    compared with it)."""
    t, q = trial.t / trial.duration * duration, trial.q

    def demo_q(s: float) -> np.ndarray:
        return np.array([np.interp(s, t, q[:, 0]), np.interp(s, t, q[:, 1])])

    return demo_q


def render_simulations(
    sims: Sequence[TrialSimulation],
    path: str | Path,
    fps: float = 30.0,
    width: int = 480,
    height: int = 480,
    ghost: bool = True,
) -> tuple[Path, int]:
    """Render the simulations one after another (demonstrations as ghosts) to ``path``; returns (path,
    frames).
    """
    clips = []
    for s in sims:
        ghost_q = _demo_interpolant(s.trial, float(s.trace_t[-1])) if ghost else None
        clips.append(RenderClip(s.trial.arm, s.trace_t, s.trace_q, s.trial.target_x, ghost_q))
    frames = render_frames(clips, fps=fps, width=width, height=height)
    return write_animation(path, frames, fps=fps)
