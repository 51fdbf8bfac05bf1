"""How well the weight samples cover the true cost shares on virtual subjects (reachirl.irl.uncertainty).

For each built-in virtual population (``--seeds``) and posture, the protocol's fit (10 training reaches of the first
subject, 8 windows, the default method) with 40 weight samples; the fraction of the 56 true cost shares (the true
weights on their own noise-free reach, seen as recorded) inside the 95 % intervals (within 0.005, the shares'
printed precision), the intervals' mean width, the determined directions and shares, the claim's fraction of
samples, and the samples' CPU time against the fit's; beside them the same coverage and width of intervals drawn
from the prior alone (no data), which says how much of the coverage the data earns. One JSON line per fit, then the
means.
Run: ``.venv/bin/python benchmarks/coverage.py --seeds 0 1 2 3 4 5 6``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from reachirl import MOIRL
from reachirl.experiments import datasets
from reachirl.experiments.analysis import reference_features, true_weights
from reachirl.experiments.protocol import ProtocolConfig, split_trials
from reachirl.features import cost_shares
from reachirl.irl.uncertainty import PRIOR_LOG_SD, share_intervals, weight_uncertainty


def prior_intervals(est, n: int = 4000, seed: int = 1) -> dict:
    """95 % share intervals on the fit's own reach from the prior alone: every free log-weight drawn around the
    equal-share start ``ω₀`` with the prior's standard deviation (an overall scale does not change a share)."""
    free = est._movable(est._w_fit.shape).reshape(-1)
    eta = np.tile(np.log(est._w_fit).reshape(-1), (n, 1))
    eta0 = np.log(est._w_start).reshape(-1)[free]
    eta[:, free] = eta0 + PRIOR_LOG_SD * np.random.default_rng(seed).standard_normal((n, int(free.sum())))
    w = est._effective(np.exp(eta).reshape(n, *est._w_fit.shape))
    return share_intervals(cost_shares(w, est.reach_features()))


def one_fit(ds, posture: str, n_windows: int = 8, rollout: str = "per_task") -> dict:
    train = list(split_trials(ds.trials, posture, ProtocolConfig()).train)
    c0 = time.process_time()
    est = MOIRL(n_windows, rollout=rollout).fit(train)
    fit_cpu = time.process_time() - c0
    c0 = time.process_time()
    unc = weight_uncertainty(est, train, 40, 0)
    unc_cpu = time.process_time() - c0
    w_true = true_weights(ds.truth, [t.trial_id for t in train])
    phi = reference_features(train, w_true, est.n_nodes, "casadi", True)
    true = w_true * phi / (w_true * phi).sum(axis=1, keepdims=True)
    lo, hi = np.array(unc["share_intervals"]["low"]), np.array(unc["share_intervals"]["high"])
    prior = prior_intervals(est)
    lo0, hi0 = np.array(prior["low"]), np.array(prior["high"])
    return {
        "posture": posture,
        "coverage": float(np.mean((true >= lo - 0.005) & (true <= hi + 0.005))),
        "mean_width": float(np.mean(hi - lo)),
        "n_determined": unc["determination"]["n_determined"],
        "n_shares_determined": int(np.sum(unc["share_intervals"]["determined"])),
        "claim_fraction": unc["claim"]["fraction"],
        "prior_coverage": float(np.mean((true >= lo0 - 0.005) & (true <= hi0 + 0.005))),
        "prior_mean_width": float(np.mean(hi0 - lo0)),
        "prior_claim_fraction": unc["prior"]["claim_fraction"],
        "checked_indistinguishable": unc["checked"]["indistinguishable"],
        "uncertainty_over_fit_cpu": unc_cpu / fit_cpu,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="built-in data seeds (default 0)")
    parser.add_argument("--postures", nargs="+", default=["P1", "P2", "P3", "P4", "P5"])
    parser.add_argument("--rollout", default="per_task", help="MOIRL's rollout (default per_task)")
    args = parser.parse_args(argv)
    rows = []
    for seed in args.seeds:
        ds = datasets.load(None, seed=seed)
        for posture in args.postures:
            rows.append({"seed": seed, **one_fit(ds, posture, rollout=args.rollout)})
            print(json.dumps(rows[-1]), flush=True)
    cov = [r["coverage"] for r in rows]
    print(
        json.dumps(
            {
                "fits": len(rows),
                "mean_coverage": float(np.mean(cov)),
                "min_coverage": float(min(cov)),
                "fits_at_least_0.9": sum(c >= 0.9 for c in cov),
                "mean_width": float(np.mean([r["mean_width"] for r in rows])),
                "prior_mean_coverage": float(np.mean([r["prior_coverage"] for r in rows])),
                "prior_min_coverage": float(min(r["prior_coverage"] for r in rows)),
                "prior_mean_width": float(np.mean([r["prior_mean_width"] for r in rows])),
                "claim_fraction_range": [
                    float(min(r["claim_fraction"] for r in rows)),
                    float(max(r["claim_fraction"] for r in rows)),
                ],
                "prior_claim_fraction_range": [
                    float(min(r["prior_claim_fraction"] for r in rows)),
                    float(max(r["prior_claim_fraction"] for r in rows)),
                ],
                "max_cpu_ratio": float(max(r["uncertainty_over_fit_cpu"] for r in rows)),
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
