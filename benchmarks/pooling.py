"""One cost learned from a virtual subject's five postures at once, against each posture's true cost.

Evidence for docs/method.md#uncertainty ("Pooling"). For each built-in virtual population (``--seeds``): MO-IRL with
8 windows and 40 weight samples on the first subject's training trials of every posture (the protocol's split), one
rollout per posture unless ``--rollout`` says otherwise. One JSON line per population: the directions the pooled
data determines, the intervals' mean width pooled and from each posture's demonstrations alone
(``uncertainty.pooling``), and per posture the coverage of its true shares (on its truth's own reach, the whole DOC
on the weights' windows) by the pooled intervals and the total variation between the learned and the true shares
(mean over windows), with the fit's CPU time; and whether the pooled training reaches can tell the truth's cost (the
mean true weights of all the pooled trials) from the fit's (``truth_versus_fit``:
:func:`reachirl.irl.uncertainty.versus_fit`).
Run: ``.venv/bin/python benchmarks/pooling.py --seeds 0 1``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from reachirl import MOIRL
from reachirl.experiments import datasets
from reachirl.experiments.protocol import ProtocolConfig, split_trials
from reachirl.experiments.truth_solves import reference_features, true_weights
from reachirl.features import cost_shares
from reachirl.irl.uncertainty import versus_fit

POSTURES = ("P1", "P2", "P3", "P4", "P5")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="built-in data seeds (default 0)")
    parser.add_argument("--rollout", default="per_task", help="MOIRL's rollout (default per_task: one per posture)")
    parser.add_argument("--merit-model", default="probes", help="probes (default) or gauss-newton")
    parser.add_argument("--max-iter", type=int, default=30, help="MO-IRL iterations per stage (default 30)")
    args = parser.parse_args(argv)
    for seed in args.seeds:
        ds = datasets.load(None, seed=seed)
        per = {p: list(split_trials(ds.trials, p, ProtocolConfig()).train) for p in POSTURES}
        c0 = time.process_time()
        est = MOIRL(
            8,
            rollout=args.rollout,
            max_iter=args.max_iter,
            uncertainty=40,
            experimental={"merit_model": args.merit_model},
        ).fit([t for p in POSTURES for t in per[p]])
        cpu = time.process_time() - c0
        u = est.uncertainty_
        lo, hi = np.array(u["share_intervals"]["low"]), np.array(u["share_intervals"]["high"])
        coverage, tv = {}, {}
        for p, trials in per.items():
            w_true = true_weights(ds.truth, [t.trial_id for t in trials])
            phi = reference_features(trials, w_true, est.n_nodes, "casadi", True)
            true, learned = cost_shares(w_true, phi), cost_shares(est.weights_, phi)
            coverage[p] = round(float(np.mean((true >= lo - 0.005) & (true <= hi + 0.005))), 3)
            tv[p] = round(float(np.mean(0.5 * np.abs(learned - true).sum(axis=1))), 3)
        pooling = u["pooling"]
        pooled_truth = true_weights(ds.truth, [t.trial_id for p in POSTURES for t in per[p]])
        versus = versus_fit(est, pooled_truth)
        row = {
            "seed": seed,
            "n_determined": u["determination"]["n_determined"],
            "mean_width": round(pooling["pooled"]["mean_width"], 3),
            "per_posture_mean_width": {k: round(v["mean_width"], 3) for k, v in pooling["per_task"].items()},
            "per_posture_determined": {k: v["n_determined"] for k, v in pooling["per_task"].items()},
            "coverage": coverage,
            "total_variation": tv,
            "mean_total_variation": round(float(np.mean(list(tv.values()))), 3),
            "truth_versus_fit": {k: v if not isinstance(v, float) else round(v, 3) for k, v in versus.items()},
            "stop_reason": str(est.stop_reason_),
            "fit_cpu_s": round(cpu, 1),
        }
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
