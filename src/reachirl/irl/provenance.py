"""What a MODEL.json records of how its weights were learned: every option, the versions, the trials."""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Sequence
from importlib import metadata

import numpy as np

from ..data.trial import Trial

__all__ = ["estimator_info", "fingerprint", "versions"]

_PACKAGES = ("reachirl", "numpy", "scipy", "casadi", "crocoddyl", "pin", "mim-solvers")


def fingerprint(trials: Sequence[Trial]) -> str:
    """A short hash of the trials' identities, arms and arrays (what a fit's result depends on)."""
    h = hashlib.sha256()
    for t in trials:
        h.update(json.dumps([t.id, t.target_x, t.arm.to_dict()], sort_keys=True).encode())
        for a in (t.t, t.q, t.qd, t.qdd, t.tau, t.x0):
            h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()[:16]


def versions() -> dict[str, str | None]:
    """The installed versions of reachirl and the solvers (``None`` where a package is missing)."""
    return dict(_installed())


@functools.lru_cache(maxsize=1)
def _installed() -> tuple[tuple[str, str | None], ...]:
    """What :func:`versions` reports, read once per process (each read scans the installed packages' metadata)."""
    out = []
    for name in _PACKAGES:
        try:
            out.append((name, metadata.version(name)))
        except metadata.PackageNotFoundError:
            out.append((name, None))
    return tuple(out)


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def _window_edges(est):
    edges = getattr(est, "window_edges", None)
    return None if edges is None else edges()


def estimator_info(est, method: str, trials: Sequence[Trial]) -> dict:
    """The provenance of a fitted estimator: ``method``, ``parameters`` (its constructor's, callback left out),
    for MO-IRL ``options`` (every :class:`~reachirl.irl.options.Options` field in force), ``tol`` and
    ``departures`` (each way the method departs from the seed paper's), ``observe`` (the option: how a trial cut
    at a threshold is fitted and predicted), ``observed_trial_ids`` (the training trials the fit did compare as
    recorded: ``observe`` and all of their rollout's trials cut at one threshold), ``backend``, ``versions``,
    ``trials_fingerprint``, the trial ids, counts, the history and the fit's warnings, and ``uncertainty``
    when it was computed."""
    from .options import departures

    params = {k: _jsonable(v) for k, v in est.get_params().items() if k != "callback"}
    if params.get("uncertainty") is True:  # the samples it stands for: the same record as `fit --uncertainty`'s
        from .uncertainty import DEFAULT_SAMPLES

        params["uncertainty"] = DEFAULT_SAMPLES
    seen = getattr(est, "observed_", None)  # MO-IRL's; the baselines compare whole rollouts
    if seen is None or len(seen) != len(trials):  # no record, or not told the trials it was fitted on
        seen = [False] * len(trials)
    info = {
        "method": method,
        "parameters": params,
        "observe": bool(getattr(est, "observe", False)),
        # what the fit did with it: the training trials compared with their rollout as recorded (the others, whole)
        "observed_trial_ids": [t.id for t, o in zip(trials, seen, strict=True) if bool(o)],
        "versions": versions(),
        "backend": est.backend,  # the DOC backend of the fit's solves, which its predictions use unless told
        "trials_fingerprint": fingerprint(trials),
        "trial_ids": [t.id for t in trials],
        "n_trials": len(trials),
        "postures": sorted({t.posture for t in trials}),
        "subjects": sorted({t.subject for t in trials}),
    }
    options = getattr(est, "options_", None)
    if options is not None:
        info["options"] = _jsonable(options.to_dict())
        info["tol"] = est.tol_
        # from one task (subject, posture), its one rollout is the paper's rollout from the demonstrations' mean
        one_task = est.rollout == "per_task" and len(getattr(est, "tasks_", ())) == 1
        info["departures"] = departures(
            options, "mean" if one_task else est.rollout, est.tol_, type(est)._option_defaults
        )
        info["seed_form"] = bool(est.seed_form)
    path, phi = est.rollout_path(), est.reach_features()
    info.update(
        {
            "rollout_q": None if path is None else path.tolist(),  # the fit's own reach: a prediction's cold start
            "reach_features": None if phi is None else phi.tolist(),  # Φ of that reach: the cost shares' base
            # where the weights' windows lie on the recorded reach (0 onset, 1 offset); None: k / n_windows
            "window_edges": None if (edges := _window_edges(est)) is None else edges.tolist(),
            "n_iter": getattr(est, "n_iter_", None),
            "n_doc_solves": getattr(est, "n_doc_solves_", None),
            "n_doc_failures": getattr(est, "n_doc_failures_", None),
            "fit_time_s": getattr(est, "fit_time_", None),
            "stop_reason": getattr(est, "stop_reason_", None),
            "flag": getattr(est, "flag_", None),
            "warnings": list(getattr(est, "warnings_", [])),
            "history": _jsonable(getattr(est, "history_", [])),
            # an observed MO-IRL fit's whole-rollout first stage (its own iterations and history), else None
            "first_stage": _jsonable(getattr(est, "plain_fit_", None)),
        }
    )
    if getattr(est, "uncertainty_", None) is not None:
        info["uncertainty"] = _jsonable(est.uncertainty_)
    return info
