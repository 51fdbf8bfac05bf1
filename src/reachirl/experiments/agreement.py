"""Virtual subjects: the true weights' own predictions of a unit's trials, to set the fit's beside.

For each unit of the main method whose section count equals the truth's windows, the trials of every set (at most
:data:`AGREEMENT_MAX_TRIALS`, evenly spaced) are predicted again under the nominal true weights (``truth.json``),
exactly as the unit predicted them (same knots, backend and ``observe``). :func:`true_predictions` records, per
trial, whether that DOC converged, its joint-angle RMSE against the recorded trial and against the unit's own
prediction. These solves depend on the unit's trials and not on its fit, so the worker that ran the unit makes them
right after it (:func:`run_unit_and_agreement`) and the unit's checkpoint keeps them as its ``agreement``: a
resumed run reuses them, and the report only sums them up (:func:`reachirl.experiments.analysis.prediction_agreement`,
which predicts again where a checkpoint holds none for these weights and trials).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np

from ..data.trial import Trial
from .protocol import SETS, Split, Unit, run_unit

__all__ = [
    "AGREEMENT_MAX_TRIALS",
    "agreement_units",
    "matches",
    "nominal_true_weights",
    "run_unit_and_agreement",
    "sampled_rows",
    "summary",
    "true_predictions",
]

AGREEMENT_MAX_TRIALS = 40
"""At most this many trials per set (evenly spaced in the set's order) are predicted again under the true
weights, so that a Berret-size run spends seconds, not minutes, on the comparison."""


def nominal_true_weights(truth: dict | None) -> tuple[np.ndarray, int] | None:
    """The nominal true weights of ``truth.json`` and its number of windows; ``None`` without them."""
    truth = truth or {}
    nominal = (truth.get("truth") or {}).get("nominal_weights")
    if nominal is None:
        return None
    return np.asarray(nominal, dtype=float), int(truth.get("n_windows", 0) or 0)


def agreement_units(units: Sequence[Unit], truth: dict | None, method: str) -> dict[str, np.ndarray]:
    """``{unit key: true weights}`` for the units whose trials the true weights predict again: the main table's
    units of ``method`` with the truth's number of sections (none without a truth)."""
    nominal = nominal_true_weights(truth)
    if nominal is None:
        return {}
    w_true, n_true = nominal
    return {u.key: w_true for u in units if u.is_main and u.method == method and u.sections == n_true}


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

    Returns ``{"weights", "sets": {set: {"ids", "true_converged", "true_vs_recorded_deg",
    "learned_vs_true_deg"}}, "time_s"}``: per sampled trial, in the set's order; an RMSE is ``None`` where the true
    weights' DOC did not converge."""
    from ..doc.evaluation import evaluate_trials, rmse_deg

    t0 = time.perf_counter()
    w_true = np.asarray(w_true, dtype=float)
    sets = {}
    for name in SETS:
        chosen = list(trials.get(name) or ())
        if not chosen:
            continue
        rows = sampled_rows(len(chosen))
        chosen = [chosen[k] for k in rows]
        learned = np.asarray(learned_q[name])[rows].astype(float)
        true = evaluate_trials(w_true, chosen, n_nodes, backend=backend, observe=observe)
        sets[name] = {
            "ids": [t.id for t in chosen],
            "true_converged": [bool(e.converged) for e in true],
            "true_vs_recorded_deg": [float(e.rmse_q) if e.converged else None for e in true],
            "learned_vs_true_deg": [
                rmse_deg(learned[k], e.prediction.q)[2] if e.converged else None for k, e in enumerate(true)
            ],
        }
    return {"weights": w_true.tolist(), "sets": sets, "time_s": time.perf_counter() - t0}


def matches(record: object, w_true: np.ndarray, result: dict) -> bool:
    """Whether a unit's stored ``agreement`` ``record`` holds the predictions under ``w_true`` of the trials it
    samples from the unit's sets (``result``, the unit's checkpoint)."""
    if not isinstance(record, dict) or not isinstance(record.get("sets"), dict):
        return False
    try:
        if not np.array_equal(np.asarray(record["weights"], dtype=float), np.asarray(w_true, dtype=float)):
            return False
    except (KeyError, TypeError, ValueError):
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


def run_unit_and_agreement(unit: Unit, split: Split, w_true: np.ndarray | None = None) -> dict:
    """:func:`~reachirl.experiments.protocol.run_unit`, then, with ``w_true``, the true weights' predictions of its
    trials (:func:`true_predictions`) as the result's ``agreement``."""
    payload = run_unit(unit, split)
    if w_true is not None:
        arrays = payload["arrays"]
        sets = {name: trials for name, trials in split.sets().items() if f"{name}/pred_q" in arrays}
        payload["result"]["agreement"] = true_predictions(
            w_true,
            sets,
            {name: arrays[f"{name}/pred_q"] for name in sets},
            unit.n_nodes,
            unit.backend,
            unit.observe,
        )
    return payload
