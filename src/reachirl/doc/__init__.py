"""Direct optimal control of a reach: :class:`ReachingTask` in, :class:`DocSolution` out, through a backend.

Backends: ``"casadi"`` (CasADi + IPOPT, the default) and ``"crocoddyl"`` (Pinocchio + Crocoddyl +
mim_solvers CSQP, the seed paper's own stack). Both solve the same problem; see :mod:`reachirl.doc.task`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..features import N_FEATURES
from ..validation import brief, not_real
from .task import DEFAULT_Q_LOWER, DEFAULT_Q_UPPER, DEFAULT_QD_MAX, DocSolution, ReachingTask, check_warm_start_knots

__all__ = [
    "BACKENDS",
    "DEFAULT_QD_MAX",
    "DEFAULT_Q_LOWER",
    "DEFAULT_Q_UPPER",
    "DocSolution",
    "ReachingTask",
    "check_weights",
    "solve_doc",
]

BACKENDS = ("casadi", "crocoddyl")


def check_weights(weights, n_nodes: int | None = None) -> np.ndarray:
    """Validate DOC weights: shape ``(n_windows, 7)``, finite, ``>= 0``. Returns a float copy."""
    if (what := not_real(weights)) is not None:
        raise ValueError(f"weights must be real numbers, got {what}")
    try:
        w = np.array(weights, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"weights must be numbers of shape (n_windows, {N_FEATURES}), got {brief(weights)}") from None
    if w.ndim == 1 and w.shape[0] == N_FEATURES:
        w = w[None, :]
    if w.ndim != 2 or w.shape[1] != N_FEATURES or w.shape[0] < 1:
        raise ValueError(f"weights must have shape (n_windows, {N_FEATURES}), got {np.shape(weights)}")
    if not np.all(np.isfinite(w)):
        raise ValueError("weights must be finite")
    if np.any(w < 0):
        raise ValueError(f"weights must be >= 0, got a minimum of {w.min():.3g}")
    if not np.any(w > 0):
        raise ValueError("weights are all zero: the DOC would have no cost to minimise")
    if n_nodes is not None and w.shape[0] > n_nodes:
        raise ValueError(f"{w.shape[0]} windows do not fit in {n_nodes} intervals")
    return w


def solve_doc(
    task: ReachingTask,
    weights,
    backend: str = "casadi",
    warm_start: DocSolution | None = None,
    *,
    retry_cold: bool = True,
    guess: np.ndarray | None = None,
    newton: bool = False,
    interior: bool = False,
) -> DocSolution:
    """Solve the reaching DOC of ``task`` under ``weights`` (shape ``(n_windows, 7)``, columns in FEATURES order).

    ``warm_start`` is a previous :class:`DocSolution` of the same task (other weights, as in MO-IRL's line
    search); the solve then starts from its solution. A solution of another task on the same knots is ignored
    (the solve is cold: another reach's solution costs more iterations than a cold start); one on another
    number of knots raises a ``ValueError`` naming both counts. When a warm start fails, the solve is retried
    cold unless ``retry_cold=False`` (MO-IRL's line search: a try the warm start cannot reach is rejected
    anyway).
    ``guess`` (a joint path ``(N+1, 2)`` on the task's knots, e.g. the demonstrations' mean) replaces the
    minimum-jerk path of the cold start; with ``newton`` (the CasADi backend; predictions, whose ``guess`` is a
    similar reach moved to the task), that start is first solved by exact Newton on the knots
    (:mod:`reachirl.doc.newton`), at the same optimum in a fraction of the time, with fatrop as its fallback;
    with ``newton`` and a ``warm_start`` of the same task, Newton starts from that solution instead, and with
    ``interior`` too (weights far from the warm start's: the uncertainty's checked samples), the interior point on
    the knots (:mod:`reachirl.doc.interior`) solves where Newton gives way, before fatrop.
    A solution that did not converge is returned with ``converged=False``, never raised.

    The problem is scale-free: ω and c·ω (any c > 0) have the same optimum. The backends solve it for
    ``ω / max(ω)`` and the cost is scaled back, so that weights of 1e-20 or 1e300 solve exactly the problem of
    their normalised version (before, tiny weights met CasADi's objective-scale floor and returned a
    "converged" non-optimum, and huge ones overflowed Crocoddyl's arithmetic and aborted the process).
    """
    if not isinstance(task, ReachingTask):
        raise TypeError(f"task must be a ReachingTask, got {type(task).__name__}")
    if warm_start is not None and not isinstance(warm_start, DocSolution):
        raise TypeError(f"warm_start must be a DocSolution (an earlier solve_doc's), got {type(warm_start).__name__}")
    check_warm_start_knots(task, warm_start)
    w = check_weights(weights, task.n_nodes)
    scale = float(w.max())
    # ω / max(ω), rounded to 40 significant bits: ω and c·ω then give the same numbers (not merely equal to
    # round-off) to the solvers, whose stopping tests would otherwise amplify the last bit
    mant, expo = np.frexp(w / scale)
    w = np.ldexp(np.round(mant * 2.0**40) / 2.0**40, expo)
    if backend == "casadi":
        from . import casadi as impl
    elif backend == "crocoddyl":
        from . import crocoddyl as impl
    else:
        raise ValueError(f"unknown DOC backend {backend!r}; choose one of {BACKENDS}")
    if guess is not None:
        guess = np.array(guess, dtype=float)
        if guess.shape != (task.n_nodes + 1, 2) or not np.all(np.isfinite(guess)):
            raise ValueError(f"guess must be a finite joint path of shape {(task.n_nodes + 1, 2)}, got {guess.shape}")
        guess = np.clip(guess, task.q_lower, task.q_upper)
    if backend == "casadi":
        sol = impl.solve(
            task, w, warm_start=warm_start, retry_cold=retry_cold, guess=guess, newton=newton, interior=interior
        )
    else:
        sol = impl.solve(task, w, warm_start=warm_start, guess=guess)
    return dataclasses.replace(sol, cost=sol.cost * scale) if scale != 1.0 else sol
