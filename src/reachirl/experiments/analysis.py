"""What a finished run's results say, computed and never written (:mod:`reachirl.experiments.report` writes it):

* :func:`truth_comparison` and :func:`prediction_agreement` — virtual subjects: the learned weights against the
  true ones, as cost shares on the true weights' own reach and as predictions (these solve DOCs);
* :func:`paired_comparison` and :func:`section_comparisons` — the most against the fewest sections, paired by
  posture (:func:`signed_rank_p`: Wilcoxon's exact test);
* :func:`methods_run` — what each method's units ran (:func:`reachirl.experiments.method.unit_method`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..features import FEATURES, cost_shares
from .datasets import Dataset
from .method import unit_method
from .protocol import SETS
from .results import RunResult, load_unit_arrays
from .tables import natural_key
from .truth_solves import reference_features, reference_from, true_weights

__all__ = [
    "methods_run",
    "paired_comparison",
    "prediction_agreement",
    "reference_features",
    "section_comparisons",
    "signed_rank_p",
    "true_weights",
    "truth_comparison",
]


def _observes(unit: dict) -> bool:
    """Whether a unit (its ``results.json`` record) saw its trials as they were recorded (``observe``)."""
    from .protocol import unit_observes

    return unit_observes(unit["method"], unit.get("estimator_options", ()))


def truth_comparison(dataset: Dataset, results: dict, method: str, postures) -> tuple[dict, dict, dict]:
    """Learned vs true cost shares for the units whose section count equals the truth's windows, both on the
    true weights' own noise-free reach, seen as the unit sees its trials
    (:func:`~reachirl.experiments.truth_solves.reference_features`, as the unit's worker stored it in its
    ``truth_solves``, else solved here; the demonstrations' Φ* if that DOC fails)."""
    learned, true, metrics = {}, {}, {}
    if dataset.truth is None:
        return learned, true, metrics
    n_true = int(dataset.truth.get("n_windows", 0) or 0)
    by_id = {t.id: t for t in dataset.trials}
    for r in sorted(results.values(), key=lambda r: natural_key(r["unit"]["posture"])):
        u = r["unit"]
        if u["method"] != method or u["sections"] != n_true or u["posture"] not in postures:
            continue
        train = [by_id[t["id"]] for t in r["sets"]["train"]["trials"] if t["id"] in by_id]
        if not train:
            continue
        w_true = true_weights(dataset.truth, [t.trial_id for t in train])
        if w_true is None or w_true.shape != (n_true, len(FEATURES)):
            continue
        found, phi = reference_from((r.get("truth_solves") or {}).get("reference"), w_true)  # the worker's
        if not found:
            phi = reference_features(train, w_true, u["n_nodes"], u["backend"], _observes(u))
        on = "true_rollout"
        if phi is None:
            phi, on = np.asarray(r["demo_features"]), "demonstrations"
        s_true = cost_shares(w_true, phi)
        s_learned = cost_shares(np.asarray(r["weights"], dtype=float), phi)
        p = u["posture"]
        learned[p], true[p] = s_learned, s_true
        tv = 0.5 * np.abs(s_learned - s_true).sum(axis=1)  # total variation per window, in [0, 1]
        a, b = s_learned.ravel() - s_learned.mean(), s_true.ravel() - s_true.mean()
        corr = float(a @ b / np.sqrt((a @ a) * (b @ b))) if (a @ a) > 0 and (b @ b) > 0 else None
        dom_l, dom_t = s_learned.argmax(axis=1), s_true.argmax(axis=1)
        metrics[p] = {
            "sections": n_true,
            "shares_on": on,
            "mean_total_variation": float(tv.mean()),
            "share_correlation": corr,
            "dominant_feature_agreement": float(np.mean(dom_l == dom_t)),
            "learned_dominant": [FEATURES[i] for i in dom_l],
            "true_dominant": [FEATURES[i] for i in dom_t],
            # the shares themselves (windows × FEATURES), on the reach above: the truth's against each interval
            "true_shares": s_true.tolist(),
            "learned_shares": s_learned.tolist(),
            # whether the training reaches tell the truth's cost from the fit's: the unit's worker solved it, for these
            # weights (its reference's); none in a checkpoint of an earlier version, and none can be solved here
            # without the fitted estimator
            "truth_versus_fit": (r.get("truth_solves") or {}).get("versus_fit") if found else None,
        }
    return learned, true, metrics


def prediction_agreement(run: RunResult, method: str, postures) -> dict:
    """Virtual subjects: how far the fits' predictions lie from the true weights' own, per posture and set.

    For each unit of ``method`` whose section count equals the truth's windows, the trials of every set (at most
    :data:`~reachirl.experiments.truth_solves.AGREEMENT_MAX_TRIALS`, evenly spaced) predicted again under the nominal
    true weights (``truth.json``), exactly as the unit predicted them (same knots, backend and ``observe``): the
    unit's worker made those predictions (its checkpoint's ``truth_solves``,
    :mod:`reachirl.experiments.truth_solves`); they are made here for a checkpoint that holds none for these
    weights and trials. Returns
    ``{posture: {set: {"n", "learned_vs_true_deg", "true_vs_recorded_deg", "learned_vs_recorded_deg"}}}``
    (joint-angle RMSE in degrees, means over those trials where both predictions converged); empty without a
    truth."""
    from .truth_solves import matches, nominal_true_weights, summary, true_predictions

    nominal = nominal_true_weights(run.dataset.truth)
    if nominal is None:
        return {}
    w_true, n_true = nominal
    by_id = {t.id: t for t in run.dataset.trials}
    out: dict = {}
    for r in run.results.values():
        u = r["unit"]
        if u["method"] != method or u["sections"] != n_true or u["posture"] not in postures:
            continue
        record = (r.get("truth_solves") or {}).get("predictions")
        if not matches(record, w_true, r):
            arrays = load_unit_arrays(run.out_dir, r["key"])
            sets = [name for name in SETS if f"{name}/pred_q" in arrays]
            record = true_predictions(
                w_true,
                {name: [by_id[str(i)] for i in arrays[f"{name}/ids"]] for name in sets},
                {name: arrays[f"{name}/pred_q"] for name in sets},
                u["n_nodes"],
                u["backend"],
                _observes(u),
            )
        per_set = summary(record, r)
        if per_set:
            out[u["posture"]] = per_set
    return out


def signed_rank_p(d) -> float:
    """Exact two-sided p-value of Wilcoxon's signed-rank test on the differences ``d``, as
    ``scipy.stats.wilcoxon(d, method="exact")`` gives it (tested against it): zeros dropped, tied ``|d|`` given
    their mean rank, the positive differences' rank sum ``T`` set against its null distribution (each of the
    ``2ⁿ`` sign patterns of the ranks ``1 … n`` equally likely, the patterns of each sum counted), a non-integral
    ``T`` (ties) rounded away from the centre; ``p = min(1, 2 min(P(T' ≤ ⌈T⌉), P(T' ≥ ⌊T⌋)))``. 1 without a
    non-zero difference. Without scipy.stats, whose import and teardown take half a second."""
    d = np.asarray(d, dtype=float).reshape(-1)
    d = d[d != 0]
    n = d.size
    if n == 0:
        return 1.0
    _, tie, size = np.unique(np.abs(d), return_inverse=True, return_counts=True)
    ranks = (np.cumsum(size) - (size - 1) / 2.0)[tie]  # the mean rank of each group of equal |d|
    t = float(np.sum((d > 0) * ranks))
    counts = [1] + [0] * (n * (n + 1) // 2)  # counts[s]: the sign patterns whose positive ranks sum to s
    for r in range(1, n + 1):
        for s in range(r * (r + 1) // 2, r - 1, -1):
            counts[s] += counts[s - r]
    below, above = sum(counts[: math.ceil(t) + 1]), sum(counts[math.floor(t) :])
    return min(1.0, 2 * min(below, above) / 2**n)


def paired_comparison(
    results: dict[str, dict], method: str, set_name: str, lo: int, hi: int, postures: Sequence[str]
) -> dict | None:
    """``hi`` against ``lo`` sections, paired by posture. Each posture has one fit per section count, and the
    trials a fit predicts share its weights, so they are not independent samples: the unit compared is the
    posture, through its mean RMSE of q over the trials both fits predicted (a failed prediction is not compared).

    Returns ``{"n"`` (postures), ``"per_posture"`` (the differences, deg; negative: ``hi`` is lower),
    ``"mean_diff_deg"``, ``"n_lower"`` (postures where ``hi`` is lower), ``"wilcoxon_p"`` (exact two-sided
    signed-rank p over the postures; with ``n`` postures it is never below ``2 / 2ⁿ``), ``"min_p"``, ``"test"}``;
    ``None`` with fewer than 2 postures that both fits predicted."""

    def per_posture(n):
        out: dict = {}
        for r in results.values():
            u = r["unit"]
            if u["method"] == method and u["sections"] == n and u["posture"] in postures:
                out[u["posture"]] = {  # a prediction whose DOC failed is counted in the tables, not compared here
                    t["id"]: t["rmse_deg"]["q"]
                    for t in r["sets"][set_name]["trials"]
                    if t["rmse_deg"]["q"] is not None and t.get("converged", True)
                }
        return out

    a, b = per_posture(lo), per_posture(hi)
    diffs = {}
    for p in sorted(set(a) & set(b), key=natural_key):
        ids = sorted(set(a[p]) & set(b[p]))
        if ids:
            diffs[p] = float(np.mean([b[p][i] for i in ids]) - np.mean([a[p][i] for i in ids]))
    if len(diffs) < 2:
        return None
    d = np.array(list(diffs.values()))
    p_value = signed_rank_p(d)
    return {
        "n": len(d),
        "per_posture": diffs,
        "mean_diff_deg": float(d.mean()),
        "n_lower": int(np.sum(d < 0)),
        "wilcoxon_p": p_value,
        "min_p": 2.0 / 2 ** len(d),
        "test": "exact two-sided Wilcoxon signed-rank over postures (one fit each), on each posture's mean "
        "RMSE of q over the trials both fits predicted",
    }


def section_comparisons(run: RunResult) -> dict:
    """Paired comparisons of the most against the fewest sections, per set, for every method."""
    sections = list(run.config.sections)
    lo, hi = min(sections), max(sections)
    if lo == hi:
        return {}
    out = {}
    for m in run.config.methods:
        for s in SETS:
            c = paired_comparison(run.results, m, s, lo, hi, run.postures)
            if c is not None:
                out.setdefault(m, {})[s] = {"sections": [lo, hi], **c}
    return out


def methods_run(run: RunResult) -> dict:
    """Per method, what its units ran (:func:`reachirl.experiments.method.unit_method`; None for a baseline)."""
    out: dict = {}
    for r in sorted(run.results.values(), key=lambda r: r["key"]):
        u = r["unit"]
        if u["method"] not in out:
            out[u["method"]] = unit_method(u["method"], u.get("estimator_options"), u.get("tol"), tasks=1)
    return out
