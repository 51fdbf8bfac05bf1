"""The uncertainty's checked samples as ``fit --uncertainty`` solves them: the interior point on the knots
(:mod:`reachirl.doc.interior`, where Newton cannot settle) against fatrop from the same start, in one run.

On the built-in virtual subjects, each posture's protocol fit (MO-IRL with weight samples, training split of
:func:`reachirl.experiments.protocol.split_trials`) re-solves its training rollouts under its first ``n_check``
weight samples (weights up to a factor of a few hundred from the fit's), warm from the fit's solutions, as
:func:`reachirl.irl.uncertainty.rollout_errors` does: by their path (exact Newton, then the interior point, then
fatrop; the ``default`` keys) and by fatrop alone (the path before the interior point; a cold retry where its warm
start fails), interleaved. Reported: CPU per re-solve of each path (median, mean, 90th percentile) and the ratio
of the totals, which solver answered, the re-solves that did not converge on each path, and how the answers
compare: the largest joint-angle difference, and their path's cost relative to fatrop's (fatrop stops at its
tolerance, 1e-6 of an order-one objective; a difference of several per cent is another local optimum).
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np


def run(postures=("P1", "P2", "P3", "P4", "P5"), sections: int = 8, n_check: int = 10, seed: int = 0) -> dict:
    from reachirl.doc import solve_doc
    from reachirl.experiments import datasets
    from reachirl.experiments.protocol import ProtocolConfig, split_trials
    from reachirl.irl.moirl import MOIRL

    dataset = datasets.load(None, seed=seed)
    config = ProtocolConfig()
    rows = []
    for posture in postures:
        split = split_trials(dataset.trials, posture, config)
        est = MOIRL(n_windows=sections, random_state=seed, uncertainty=20).fit(list(split.train))
        for w in np.asarray(est.uncertainty_["weight_samples"], dtype=float)[:n_check]:
            for task, before in zip(est.tasks_, est.train_solutions_, strict=True):
                out = {}
                for default in (True, False):
                    t0 = time.process_time()
                    sol = solve_doc(task, w, warm_start=before, newton=default, interior=default)
                    out[default] = (sol, time.process_time() - t0)
                (new, t_new), (old, t_old) = out[True], out[False]
                both = new.converged and old.converged
                rows.append(
                    {
                        "cpu_default": t_new,
                        "cpu_fatrop": t_old,
                        "solver": new.status.split(":")[0],
                        "converged": (new.converged, old.converged),
                        "diff_deg": float(np.rad2deg(np.max(np.abs(new.q - old.q)))) if both else np.nan,
                        "cost_rel": float(new.cost / old.cost - 1.0) if both else np.nan,
                    }
                )
    t_new = np.array([r["cpu_default"] for r in rows]) * 1e3
    t_old = np.array([r["cpu_fatrop"] for r in rows]) * 1e3
    diff = np.array([r["diff_deg"] for r in rows])
    rel = np.array([r["cost_rel"] for r in rows])

    def stats(t):
        return {"median": float(np.median(t)), "mean": float(np.mean(t)), "p90": float(np.percentile(t, 90))}

    return {
        "n_solves": len(rows),
        "postures": list(postures),
        "sections": sections,
        "cpu_ms_default": stats(t_new),
        "cpu_ms_fatrop": stats(t_old),
        "ratio_cpu_total": float(t_new.sum() / t_old.sum()),
        "answered_by": dict(Counter(r["solver"] for r in rows)),
        "not_converged": {
            "default_path": int(sum(not r["converged"][0] for r in rows)),
            "fatrop_path": int(sum(not r["converged"][1] for r in rows)),
        },
        "diff_deg": {"median": float(np.nanmedian(diff)), "p90": float(np.nanpercentile(diff, 90))},
        "cost_vs_fatrop": {
            "higher_by_more_than_1e-6": int(np.sum(rel > 1e-6)),
            "lower_by_more_than_1e-6": int(np.sum(rel < -1e-6)),
            "largest_rise": float(np.nanmax(rel)),
            "largest_fall": float(np.nanmin(rel)),
        },
    }


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
