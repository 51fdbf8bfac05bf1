"""The solves under the true weights (their predictions of a unit's trials, their own reach): made by the unit's
worker, kept in its checkpoint, and giving the report exactly what solving them again after the run gives."""

import json

import numpy as np
import pytest

from reachirl.experiments import datasets
from reachirl.experiments.analysis import _observes, prediction_agreement, truth_comparison
from reachirl.experiments.protocol import SETS, ProtocolConfig, make_units, split_trials
from reachirl.experiments.results import load_unit_arrays
from reachirl.experiments.runner import reproduce
from reachirl.experiments.truth_solves import (
    AGREEMENT_MAX_TRIALS,
    _truth_reach,
    matches,
    sampled_rows,
    true_weights,
    truth_jobs,
)


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
        first = next(name for name in SETS if f"{name}/pred_q" in arrays)
        reach = _truth_reach(
            [by_id[str(i)] for i in arrays[f"{first}/ids"]], w_true, u["n_nodes"], u["backend"], _observes(u)
        )[0]
        per_set = {}
        for name in SETS:
            if f"{name}/pred_q" not in arrays:
                continue
            ids = [str(i) for i in arrays[f"{name}/ids"]]
            rows = np.unique(np.linspace(0, len(ids) - 1, min(len(ids), AGREEMENT_MAX_TRIALS)).round().astype(int))
            ids = [ids[k] for k in rows]
            recs = {e["id"]: e for e in r["sets"][name]["trials"]}
            true = evaluate_trials(
                w_true, [by_id[i] for i in ids], u["n_nodes"], u["backend"], observe=_observes(u), path=reach.q
            )
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


def test_the_workers_solves_equal_solving_again(run, monkeypatch):
    (r,) = run.results.values()
    solves = r["truth_solves"]
    assert matches(solves["predictions"], np.asarray(run.dataset.truth["truth"]["nominal_weights"]), r)
    on_disk = json.loads((run.out_dir / "units" / f"{r['key']}.json").read_text())
    assert on_disk["truth_solves"] == solves  # in the checkpoint: a resumed run has them
    got = prediction_agreement(run, "moirl", ["P4"])
    assert set(got["P4"]) == set(SETS) and got == serial(run, "moirl", ["P4"])
    shares = truth_comparison(run.dataset, run.results, "moirl", ["P4"])
    assert shares[2]["P4"]["shares_on"] == "true_rollout"
    # the worker judged the truth against the fit (the fitted estimator is gone after the unit)
    assert shares[2]["P4"]["truth_versus_fit"] == solves["versus_fit"] and solves["versus_fit"]["converged"]
    monkeypatch.setitem(r, "truth_solves", {})  # as a checkpoint of an earlier version: solved here
    again = truth_comparison(run.dataset, run.results, "moirl", ["P4"])
    assert again[2]["P4"].pop("truth_versus_fit") is None  # that needs the fit: not solved again, not made up
    shares[2]["P4"].pop("truth_versus_fit")
    assert json.dumps(again, default=np.ndarray.tolist) == json.dumps(shares, default=np.ndarray.tolist)


def test_a_checkpoint_without_them_or_for_other_weights_is_solved_again(run, monkeypatch):
    (r,) = run.results.values()
    want = serial(run, "moirl", ["P4"])
    want_shares = json.dumps(truth_comparison(run.dataset, run.results, "moirl", ["P4"]), default=np.ndarray.tolist)
    monkeypatch.delitem(r, "truth_solves")  # a checkpoint of an earlier version
    assert prediction_agreement(run, "moirl", ["P4"]) == want
    monkeypatch.undo()
    other = json.loads(json.dumps(r["truth_solves"]))
    other["predictions"]["weights"][0][0] += 1.0  # made under other weights
    other["predictions"]["sets"]["iscv"]["true_vs_recorded_deg"] = [99.0] * len(
        other["predictions"]["sets"]["iscv"]["ids"]
    )
    other["reference"]["weights"][0][0] += 1.0
    other["reference"]["features"] = np.ones((8, 7)).tolist()
    monkeypatch.setitem(r, "truth_solves", other)
    assert prediction_agreement(run, "moirl", ["P4"]) == want
    got = truth_comparison(run.dataset, run.results, "moirl", ["P4"])
    # the checkpoint's judgement of the truth against the fit was of those other weights: not this truth's
    assert got[2]["P4"].pop("truth_versus_fit") is None
    expected = json.loads(want_shares)
    expected[2]["P4"].pop("truth_versus_fit")
    assert json.dumps(got, default=np.ndarray.tolist) == json.dumps(expected)


def test_a_resumed_run_reuses_the_agreement(run):
    again = reproduce(run.dataset, run.config, run.out_dir, workers=1)
    assert not again.summary.computed and again.summary.results == run.summary.results


def test_only_the_main_units_with_the_truths_sections_solve(run):
    truth = run.dataset.truth
    cfg = ProtocolConfig(sections=(1, 8), methods=("moirl", "maxent"), iscv="all-pairs", n_nodes=30)
    units = make_units(["P4"], cfg, ["S02"])
    splits = {u.split_key: split_trials(run.dataset.trials, u.posture, cfg) for u in units}
    jobs = truth_jobs(units, splits, truth, "moirl")
    assert sorted(jobs) == ["moirl-P4-s8"]
    np.testing.assert_array_equal(jobs["moirl-P4-s8"]["nominal"], truth["truth"]["nominal_weights"])
    train_ids = [t.trial_id for t in splits["P4"].train]
    np.testing.assert_array_equal(jobs["moirl-P4-s8"]["reference"], true_weights(truth, train_ids))
    assert truth_jobs(units, splits, None, "moirl") == {} and truth_jobs(units, splits, {"n_windows": 8}, "moirl") == {}


def test_the_sample_is_evenly_spaced_and_bounded():
    assert sampled_rows(3).tolist() == [0, 1, 2]
    rows = sampled_rows(400)
    assert len(rows) == AGREEMENT_MAX_TRIALS and rows[0] == 0 and rows[-1] == 399
