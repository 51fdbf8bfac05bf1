"""The true weights' predictions of a unit's trials: made by the unit's worker, kept in its checkpoint, and
summed up to exactly what predicting them again after the run gives."""

import json

import numpy as np
import pytest

from reachirl.experiments import datasets
from reachirl.experiments.agreement import AGREEMENT_MAX_TRIALS, agreement_units, matches, sampled_rows
from reachirl.experiments.analysis import _observes, prediction_agreement
from reachirl.experiments.protocol import SETS, ProtocolConfig, make_units
from reachirl.experiments.results import load_unit_arrays
from reachirl.experiments.runner import reproduce


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A finished run on toy virtual subjects whose one unit has the truth's 8 sections."""
    toy = datasets.toy(n_subjects=2, postures=("P4",), n_trials=3, n_nodes=30, seed=1)
    cfg = ProtocolConfig(sections=(8,), n_train=2, n_nodes=30, max_iter=1, uncertainty=0)
    return reproduce(toy, cfg, tmp_path_factory.mktemp("agree"), workers=1)


def serial(run, method, postures) -> dict:
    """The comparison as the report made it after the run, before the workers did: every true-weight prediction
    made again from the dataset's trials and the unit's NPZ."""
    from reachirl.doc.evaluation import evaluate_trials, rmse_deg

    truth = run.dataset.truth
    w_true = np.asarray(truth["truth"]["nominal_weights"], dtype=float)
    by_id = {t.id: t for t in run.dataset.trials}
    out = {}
    for r in run.results.values():
        u = r["unit"]
        if u["method"] != method or u["sections"] != truth["n_windows"] or u["posture"] not in postures:
            continue
        arrays = load_unit_arrays(run.out_dir, r["key"])
        per_set = {}
        for name in SETS:
            if f"{name}/pred_q" not in arrays:
                continue
            ids = [str(i) for i in arrays[f"{name}/ids"]]
            rows = np.unique(np.linspace(0, len(ids) - 1, min(len(ids), AGREEMENT_MAX_TRIALS)).round().astype(int))
            ids = [ids[k] for k in rows]
            recs = {e["id"]: e for e in r["sets"][name]["trials"]}
            true = evaluate_trials(w_true, [by_id[i] for i in ids], u["n_nodes"], u["backend"], observe=_observes(u))
            both = [k for k, i in enumerate(ids) if recs[i]["converged"] and true[k].converged]
            if not both:
                continue
            learned_q = arrays[f"{name}/pred_q"][rows].astype(float)
            per_set[name] = {
                "n": len(both),
                "learned_vs_true_deg": float(np.mean([rmse_deg(learned_q[k], true[k].prediction.q)[2] for k in both])),
                "true_vs_recorded_deg": float(np.mean([true[k].rmse_q for k in both])),
                "learned_vs_recorded_deg": float(np.mean([recs[ids[k]]["rmse_deg"]["q"] for k in both])),
            }
        if per_set:
            out[u["posture"]] = per_set
    return out


def test_the_workers_agreement_equals_predicting_again(run):
    (r,) = run.results.values()
    assert matches(r["agreement"], np.asarray(run.dataset.truth["truth"]["nominal_weights"]), r)
    on_disk = json.loads((run.out_dir / "units" / f"{r['key']}.json").read_text())
    assert on_disk["agreement"] == r["agreement"]  # in the checkpoint: a resumed run has it
    got = prediction_agreement(run, "moirl", ["P4"])
    assert set(got["P4"]) == set(SETS) and got == serial(run, "moirl", ["P4"])


def test_a_checkpoint_without_it_or_for_other_weights_is_predicted_again(run, monkeypatch):
    (key,) = run.results
    want = serial(run, "moirl", ["P4"])
    record = run.results[key]["agreement"]
    try:
        del run.results[key]["agreement"]  # a checkpoint of an earlier version
        assert prediction_agreement(run, "moirl", ["P4"]) == want
        other = json.loads(json.dumps(record))
        other["weights"][0][0] += 1.0  # made under other weights
        other["sets"]["iscv"]["true_vs_recorded_deg"] = [99.0] * len(other["sets"]["iscv"]["ids"])
        run.results[key]["agreement"] = other
        assert prediction_agreement(run, "moirl", ["P4"]) == want
    finally:
        run.results[key]["agreement"] = record


def test_a_resumed_run_reuses_the_agreement(run):
    again = reproduce(run.dataset, run.config, run.out_dir, workers=1)
    assert not again.summary.computed and again.summary.results == run.summary.results


def test_only_the_main_units_with_the_truths_sections_predict_again():
    truth = {"n_windows": 8, "truth": {"nominal_weights": np.ones((8, 7)).tolist()}}
    cfg = ProtocolConfig(sections=(1, 8), methods=("moirl", "maxent"), iscv="all-pairs", n_nodes=30)
    units = make_units(["P2", "P4"], cfg, ["S02"])
    assert sorted(agreement_units(units, truth, "moirl")) == ["moirl-P2-s8", "moirl-P4-s8"]
    assert agreement_units(units, None, "moirl") == {} and agreement_units(units, {"n_windows": 8}, "moirl") == {}


def test_the_sample_is_evenly_spaced_and_bounded():
    assert sampled_rows(3).tolist() == [0, 1, 2]
    rows = sampled_rows(400)
    assert len(rows) == AGREEMENT_MAX_TRIALS and rows[0] == 0 and rows[-1] == 399
