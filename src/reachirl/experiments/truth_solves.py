"""Virtual subjects: what the true weights themselves do, to set the fits beside.

* :func:`reference_features` — the features of the true weights' own noise-free reach (the DOC over a unit's
  training trials' mean task), on which :func:`reachirl.experiments.analysis.truth_comparison` weighs learned
  and true cost shares;
* :func:`true_predictions` — the true weights' predictions of a unit's trials (at most
  :data:`AGREEMENT_MAX_TRIALS` per set, evenly spaced), exactly as the unit predicted them (same knots, backend
  and ``observe``): per trial, whether the DOC converged, its joint-angle RMSE against the recorded trial and
  against the unit's own prediction, which :func:`reachirl.experiments.analysis.prediction_agreement` sums up.

These solves depend on a unit's trials and not on its fit, so the worker that ran the unit makes them right after
it (:func:`run_unit_and_truth`, for the units :func:`truth_jobs` names: the main method's, with the truth's
number of sections) and the unit's checkpoint keeps them as ``truth_solves``: a resumed run reuses them, and the
report only reads them (it solves again where a checkpoint holds none for these weights and trials).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..data.trial import Trial
from ..features import FEATURES
from .protocol import SETS, Split, Unit, fit_unit, run_unit, unit_payload

__all__ = [
    "AGREEMENT_MAX_TRIALS",
    "matches",
    "nominal_true_weights",
    "reference_features",
    "reference_from",
    "run_unit_and_truth",
    "sampled_rows",
    "summary",
    "true_predictions",
    "true_weights",
    "truth_jobs",
]

AGREEMENT_MAX_TRIALS = 40
"""At most this many trials per set (evenly spaced in the set's order) are predicted again under the true
weights, so that a Berret-size run spends seconds, not minutes, on the comparison."""


def true_weights(truth: dict | None, trial_ids: Sequence[str]) -> np.ndarray | None:
    """Mean true weights ``(n_windows, 7)`` of the given trials (``truth.json`` of virtual subjects), matched
    on the trial file's stem; the nominal weights when none match; ``None`` without truth."""
    if not truth:
        return None
    by_stem = {}
    for subj in (truth.get("subjects") or {}).values():
        for recs in (subj.get("trials") or {}).values():
            for r in recs:
                by_stem[Path(str(r.get("file", ""))).stem] = r.get("weights")
    ws = [by_stem[i] for i in trial_ids if by_stem.get(i) is not None]
    if ws:
        return np.mean(np.asarray(ws, dtype=float), axis=0)
    nominal = (truth.get("truth") or {}).get("nominal_weights")
    return None if nominal is None else np.asarray(nominal, dtype=float)


def _truth_reach(trials, weights: np.ndarray, n_nodes: int, backend: str, observe: bool):
    """The DOC under ``weights`` over the trials' mean task, as an observed unit sees its rollout: ``(solution,
    task, threshold)``; with ``observe`` and trials cut at one onset threshold the task is rest to rest and
    ``threshold`` that threshold, otherwise ``None``."""
    from ..doc import solve_doc
    from ..doc.observation import common_threshold, rest_to_rest
    from ..irl.moirl import mean_task

    task = mean_task(trials, n_nodes)
    try:
        threshold = common_threshold(trials) if observe else None
    except ValueError:  # cut at different thresholds: no one way to see the reach
        threshold = None
    if threshold is not None:
        task = rest_to_rest(task)
    return solve_doc(task, weights, backend=backend), task, threshold


def reference_features(
    trials, weights: np.ndarray, n_nodes: int, backend: str = "casadi", observe: bool = False
) -> np.ndarray | None:
    """Φ ``(n_windows, 7)`` of the DOC under ``weights`` over the trials' mean task (noise-free), on which learned
    and true cost shares are compared; ``None`` if that DOC does not converge. With ``observe`` and trials cut
    at one onset threshold, the DOC is the rest-to-rest one an observed unit predicts its trials by, and Φ is the
    whole DOC's on its own windows, the ones the weights act on (as a fit's
    :meth:`~reachirl.irl.moirl.MOIRL.reach_features`); otherwise the DOC over the mean duration.

    Not the demonstrations' Φ*: the position noise a recording keeps (after its filter) inflates the features
    of second and third derivatives (joint acceleration, torque change) by up to two orders of magnitude, so
    shares on Φ* credit the true weights with costs that hardly shape their own reach."""
    from ..data.trial import trial_from_solution
    from ..features import windowed_features

    sol, task, threshold = _truth_reach(trials, weights, n_nodes, backend, observe)
    if not sol.converged:
        return None
    if threshold is not None:
        return windowed_features(task.arm, sol.q, sol.qd, sol.tau, task.dt, weights.shape[0])
    return trial_from_solution(sol, task.arm, task.target_x).features(n_nodes, weights.shape[0])


def nominal_true_weights(truth: dict | None) -> tuple[np.ndarray, int] | None:
    """The nominal true weights of ``truth.json`` and its number of windows; ``None`` without them."""
    truth = truth or {}
    nominal = (truth.get("truth") or {}).get("nominal_weights")
    if nominal is None:
        return None
    return np.asarray(nominal, dtype=float), int(truth.get("n_windows", 0) or 0)


def truth_jobs(units: Sequence[Unit], splits: Mapping, truth: dict | None, method: str) -> dict[str, dict]:
    """``{unit key: {"nominal", "reference"}}`` for the units whose workers solve under the true weights: the main
    table's units of ``method`` with the truth's number of sections (none without nominal true weights).
    ``nominal``: the weights their trials are predicted again under; ``reference``: the mean true weights of
    their training trials (:func:`true_weights`), whose own reach :func:`reference_features` gives (``None`` if
    those are not ``(n_windows, 7)``)."""
    nominal = nominal_true_weights(truth)
    if nominal is None:
        return {}
    w_nominal, n_true = nominal
    jobs = {}
    for u in units:
        if u.is_main and u.method == method and u.sections == n_true:
            ref = true_weights(truth, [t.trial_id for t in splits[u.split_key].train])
            ok = ref is not None and ref.shape == (n_true, len(FEATURES))
            jobs[u.key] = {"nominal": w_nominal, "reference": ref if ok else None}
    return jobs


def sampled_rows(n: int) -> np.ndarray:
    """The rows of a set of ``n`` trials that are predicted again: at most :data:`AGREEMENT_MAX_TRIALS`, evenly
    spaced."""
    return np.unique(np.linspace(0, n - 1, min(n, AGREEMENT_MAX_TRIALS)).round().astype(int))


def true_predictions(
    w_true: np.ndarray,
    trials: Mapping[str, Sequence[Trial]],
    learned_q: Mapping[str, np.ndarray],
    n_nodes: int,
    backend: str,
    observe: bool,
) -> dict:
    """The true weights' predictions of the sampled trials of every set that has trials (``trials[set]``, in the
    set's order, and ``learned_q[set]``, the unit's predicted q of those trials, ``(n, n_nodes + 1, 2)``).

    Like the unit's, each prediction starts from a reach under the same weights moved to the trial: the true
    weights' own reach over the first set's mean task (:func:`_truth_reach`), when it converges.

    Returns ``{"weights", "sets": {set: {"ids", "true_converged", "true_vs_recorded_deg",
    "learned_vs_true_deg"}}}``: per sampled trial, in the set's order; an RMSE is ``None`` where the true weights'
    DOC did not converge."""
    from ..doc.evaluation import evaluate_trials, rmse_deg

    w_true = np.asarray(w_true, dtype=float)
    first = next((list(trials[name]) for name in SETS if trials.get(name)), None)
    path = None
    if first is not None:
        reach = _truth_reach(first, w_true, n_nodes, backend, observe)[0]
        path = reach.q if reach.converged else None
    sets = {}
    for name in SETS:
        chosen = list(trials.get(name) or ())
        if not chosen:
            continue
        rows = sampled_rows(len(chosen))
        chosen = [chosen[k] for k in rows]
        learned = np.asarray(learned_q[name])[rows].astype(float)
        true = evaluate_trials(w_true, chosen, n_nodes, backend=backend, observe=observe, path=path)
        sets[name] = {
            "ids": [t.id for t in chosen],
            "true_converged": [bool(e.converged) for e in true],
            "true_vs_recorded_deg": [float(e.rmse_q) if e.converged else None for e in true],
            "learned_vs_true_deg": [
                rmse_deg(learned[k], e.prediction.q)[2] if e.converged else None for k, e in enumerate(true)
            ],
        }
    return {"weights": w_true.tolist(), "sets": sets}


def _same_weights(stored, w: np.ndarray) -> bool:
    try:
        return np.array_equal(np.asarray(stored, dtype=float), np.asarray(w, dtype=float))
    except (TypeError, ValueError):
        return False


def matches(record: object, w_true: np.ndarray, result: dict) -> bool:
    """Whether a unit's stored predictions ``record`` (its ``truth_solves["predictions"]``) are those under
    ``w_true`` of the trials it samples from the unit's sets (``result``, the unit's checkpoint)."""
    if not isinstance(record, dict) or not isinstance(record.get("sets"), dict):
        return False
    if not _same_weights(record.get("weights"), w_true):
        return False
    for name in SETS:
        ids = [e["id"] for e in result["sets"][name]["trials"]]
        stored = record["sets"].get(name)
        if not ids:
            if stored is not None:
                return False
            continue
        want = [ids[k] for k in sampled_rows(len(ids))]
        if not isinstance(stored, dict) or stored.get("ids") != want:
            return False
        keys = ("true_converged", "true_vs_recorded_deg", "learned_vs_true_deg")
        if any(not isinstance(stored.get(k), list) or len(stored[k]) != len(want) for k in keys):
            return False
    return True


def summary(record: dict, result: dict) -> dict:
    """``{set: {"n", "learned_vs_true_deg", "true_vs_recorded_deg", "learned_vs_recorded_deg"}}``: joint-angle RMSE
    in degrees, means over the sampled trials where both the unit's prediction and the true weights' converged (a
    set with none is left out)."""

    def mean(values, keep):
        return float(np.mean([np.nan if values[k] is None else values[k] for k in keep]))

    out = {}
    for name in SETS:
        stored = record["sets"].get(name)
        if stored is None:
            continue
        recs = {e["id"]: e for e in result["sets"][name]["trials"]}
        ids = stored["ids"]
        both = [k for k, i in enumerate(ids) if recs[i]["converged"] and stored["true_converged"][k]]
        if not both:
            continue
        out[name] = {
            "n": len(both),
            "learned_vs_true_deg": mean(stored["learned_vs_true_deg"], both),
            "true_vs_recorded_deg": mean(stored["true_vs_recorded_deg"], both),
            "learned_vs_recorded_deg": mean([recs[i]["rmse_deg"]["q"] for i in ids], both),
        }
    return out


def reference_from(record: object, w_true: np.ndarray) -> tuple[bool, np.ndarray | None]:
    """``(found, Φ)``: the reference features a unit's worker stored (its ``truth_solves["reference"]``) for
    ``w_true``; ``Φ`` is ``None`` where that DOC did not converge. ``found`` is false without a record for these
    weights."""
    if not isinstance(record, dict) or not _same_weights(record.get("weights"), w_true):
        return False, None
    phi = record.get("features")
    return True, None if phi is None else np.asarray(phi, dtype=float)


def run_unit_and_truth(unit: Unit, split: Split, job: Mapping | None = None) -> dict:
    """:func:`~reachirl.experiments.protocol.run_unit`, then, with a :func:`truth_jobs` ``job``, the solves under
    the true weights as the result's ``truth_solves``: ``{"predictions"`` (:func:`true_predictions` under
    ``job["nominal"]``), ``"reference"`` (``{"weights", "features"}``: :func:`reference_features` of the training
    trials under ``job["reference"]``, when given), ``"versus_fit"`` (with ``"reference"``, for a fit that keeps
    its training rollouts: :func:`reachirl.irl.uncertainty.versus_fit` of those weights, whether the training
    demonstrations can tell them from the fit's), ``"time_s"}``."""
    if not job:
        return run_unit(unit, split)
    est, fit_time = fit_unit(unit, split)
    payload = unit_payload(unit, split, est, fit_time)
    t0 = time.perf_counter()
    solves: dict = {}
    if job.get("nominal") is not None:
        arrays = payload["arrays"]
        sets = {name: trials for name, trials in split.sets().items() if f"{name}/pred_q" in arrays}
        solves["predictions"] = true_predictions(
            job["nominal"],
            sets,
            {name: arrays[f"{name}/pred_q"] for name in sets},
            unit.n_nodes,
            unit.backend,
            unit.observe,
        )
    if job.get("reference") is not None:
        w_ref = np.asarray(job["reference"], dtype=float)
        phi = reference_features(list(split.train), w_ref, unit.n_nodes, unit.backend, unit.observe)
        solves["reference"] = {"weights": w_ref.tolist(), "features": None if phi is None else phi.tolist()}
        from ..irl.methods import builds_on_moirl

        if builds_on_moirl(unit.method):  # MO-IRL's and MaxEnt's fits keep their training rollouts
            from ..irl.uncertainty import versus_fit

            # whether the training reaches can tell the truth's cost from the fit's (the report's evidence)
            solves["versus_fit"] = versus_fit(est, w_ref)
    solves["time_s"] = time.perf_counter() - t0
    payload["result"]["truth_solves"] = solves
    return payload
