"""The weight samples where the data is informative: noise-free DOC reaches of a known one-window cost.

Evidence for docs/method.md#uncertainty. Each population: ``--postures`` start postures, ``--reaches`` reaches from
each (start jittered by 3°, bar 25 cm in front of the start's fingertip, at most 0.85 of the arm's length, duration
0.8 s ± 5 %), all under one cost whose shares on the first reaches are drawn from a flat Dirichlet (seeded); the
reaches are the DOC's own solutions, whole (not cut at a speed threshold) and without recording noise. MO-IRL fits
one window with 40 weight samples, with the given rollout and merit model. One JSON line per population: how many
of the 7 true shares (on the fit's own reach) lie inside their 95 % intervals (within 0.005), the intervals' mean
width, the total variation from the fit's shares to the truth's, the determined directions, the fit's merit and the
true weights' own (the same rollouts, solved at the true weights), and the shares missed; then the means.
Run: ``.venv/bin/python benchmarks/informative.py --seeds 0 1 2 3 4 5 6 7`` (default options) and with
``--rollout per_demo --merit-model gauss-newton``.

``--truth paper`` fits the paper's 8-window cost instead (the virtual population's nominal weights), on reaches of
one virtual subject (the population of the seed's first) from Berret's five postures (start jittered by 3°, bar at
0.95 of the arm's length, Berret's mean durations); ``--jitter`` draws each reach's weights around it as the
virtual population does (a log-normal factor of SD 0.2, the truth being their mean), and ``--cut`` cuts each reach
where its fingertip speed crosses 5 % of its peak, as a recording is: what each of the recorded data's departures
from one cost seen whole does to the fit and its intervals. The line also gives the total variation per window
and joint acceleration's learned and true shares per window (the paper's pattern).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import numpy as np

from reachirl import FEATURES, MOIRL, ArmModel, ReachingTask, solve_doc
from reachirl.doc.observation import observe
from reachirl.features import cost_shares, windowed_features
from reachirl.irl.uncertainty import versus_fit
from reachirl.virtual import one_cost_trials

POSTURES_DEG = [(-60.0, 90.0), (0.0, 90.0), (30.0, 120.0), (-30.0, 110.0), (50.0, 80.0)]
FEATURE_SCALE = np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])  # typical feature sizes of a reach


def population(seed: int, n_postures: int, n_reaches: int):
    """``(trials, true weights (1, 7))``, or None when a reach's DOC failed."""
    rng = np.random.default_rng(seed)
    arm = ArmModel.from_anthropometrics(1.76, 69.9, "M")
    tasks = []
    for posture in POSTURES_DEG[:n_postures]:
        for _ in range(n_reaches):
            q0 = np.deg2rad(np.array(posture) + rng.normal(0.0, 3.0, 2))
            bar = min(float(arm.fk(q0)[0]) + 0.25, 0.85 * arm.length) * (1.0 + 0.02 * rng.normal())
            tasks.append(ReachingTask(arm, q0, bar, 0.8 * (1.0 + 0.05 * rng.normal())))
    shares = rng.dirichlet(np.ones(len(FEATURES)))
    w_start = (1.0 / FEATURE_SCALE)[None, :]
    starts = [solve_doc(t, w_start) for t in tasks[:3]]
    phi = np.mean(
        [windowed_features(arm, s.q, s.qd, s.tau, t.dt, 1) for s, t in zip(starts, tasks[:3], strict=True)], axis=0
    )
    w = (shares / phi[0])[None, :]  # those shares on the first reaches
    trials = []
    for i, task in enumerate(tasks):
        sol = solve_doc(task, w)
        if not sol.converged:
            return None
        trial = observe(sol, task, None, name=f"T{i}")
        trials.append(replace(trial, subject="V", posture=f"P{i // n_reaches + 1}", trial_id=f"T{i}"))
    return trials, w


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--postures", type=int, default=5, help="start postures, 1 to 5 (default 5)")
    parser.add_argument("--reaches", type=int, default=4, help="reaches per posture (default 4)")
    parser.add_argument("--rollout", default="per_task", help="MO-IRL's rollout (default per_task, the default)")
    parser.add_argument("--merit-model", default="probes", help="probes (default) or gauss-newton")
    parser.add_argument("--truth", choices=["random", "paper"], default="random", help="the cost (default random)")
    parser.add_argument("--jitter", action="store_true", help="--truth paper: each reach's weights jittered")
    parser.add_argument("--cut", action="store_true", help="--truth paper: reaches cut at 5 %% of peak speed")
    args = parser.parse_args(argv)
    rows = []
    n_windows = 8 if args.truth == "paper" else 1
    for seed in args.seeds:
        if args.truth == "paper":
            try:
                made = one_cost_trials(
                    args.reaches, seed, jitter=0.2 if args.jitter else 0.0, threshold=0.05 if args.cut else None
                )
            except RuntimeError:
                made = None
        else:
            made = population(seed, args.postures, args.reaches)
        if made is None:
            print(json.dumps({"seed": seed, "skipped": "a true reach's DOC did not converge"}), flush=True)
            continue
        trials, w = made
        est = MOIRL(n_windows, rollout=args.rollout, uncertainty=40, experimental={"merit_model": args.merit_model})
        est.fit(trials)
        u, reach = est.uncertainty_, est.reach_features()
        true, fit = cost_shares(w, reach), cost_shares(est.weights_, reach)
        lo, hi = (np.array(u["share_intervals"][k]) for k in ("low", "high"))
        inside = (true >= lo - 0.005) & (true <= hi + 0.005)
        tv = 0.5 * np.abs(true - fit).sum(axis=1)
        truth_rollouts = [solve_doc(t, w) for t in est.tasks_]
        row = {
            "seed": seed,
            "coverage": float(inside.mean()),
            "mean_width": float(np.mean(hi - lo)),
            "total_variation": float(tv.mean()),
            "n_determined": u["determination"]["n_determined"],
            "merit": float(est.merit_),
            "true_merit": float(est._merit(est._x_demos, truth_rollouts, est._channels, est.tasks_)),
            # whether the training reaches tell the truth's cost from the fit's (the samples' test)
            "truth_versus_fit": versus_fit(est, w),
            "stop_reason": str(est.stop_reason_),
            "missed": [
                f"{FEATURES[j]} (window {i + 1}) {true[i, j]:.3f} not in [{lo[i, j]:.3f}, {hi[i, j]:.3f}]"
                for i, j in zip(*np.nonzero(~inside), strict=True)
            ],
        }
        if n_windows > 1:
            ja = FEATURES.index("joint_acceleration")
            row |= {
                "total_variation_per_window": np.round(tv, 3).tolist(),
                "joint_acceleration_fit": np.round(fit[:, ja], 2).tolist(),
                "joint_acceleration_true": np.round(true[:, ja], 2).tolist(),
                "claim": u["claim"]["verdict"],
            }
        rows.append(row)
        print(json.dumps(row), flush=True)
    if rows:
        print(
            json.dumps(
                {
                    "fits": len(rows),
                    "mean_coverage": float(np.mean([r["coverage"] for r in rows])),
                    "min_coverage": float(np.min([r["coverage"] for r in rows])),
                    "mean_width": float(np.mean([r["mean_width"] for r in rows])),
                    "width_range": [
                        float(np.min([r["mean_width"] for r in rows])),
                        float(np.max([r["mean_width"] for r in rows])),
                    ],
                    "mean_total_variation": float(np.mean([r["total_variation"] for r in rows])),
                }
            )
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
