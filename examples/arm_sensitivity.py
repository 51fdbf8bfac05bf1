"""Why learned weights transfer to another subject less well than the truth: the arm model, or the reach?

For each posture of a `reachirl reproduce` run on virtual subjects, the learned (the run's main MO-IRL fit at
--sections) and the true weights predict the mean of the run's training reaches, on the run's knots (rest to
rest, seen from onset to offset as the reaches were recorded) on
the subject's own arm, on that arm with its masses and inertias off by 10-15 % (or its forearm's centre of
mass moved), and on the other subject's arm. Printed per posture, in degrees (RMSE of q): how far each arm
moves the learned weights' prediction (dL) and the true weights' (dT), and how far apart the two predictions
are on that arm (L-T).

    reachirl reproduce --data-seed 2 --sections 1 8 --out s2
    python examples/arm_sensitivity.py s2 --data-seed 2
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from reachirl.cli import OneLineParser
from reachirl.doc import solve_doc
from reachirl.doc.observation import common_threshold, observe, rest_to_rest
from reachirl.errors import InputError
from reachirl.experiments import datasets
from reachirl.experiments.protocol import split_trials
from reachirl.experiments.sensitivity import load_run, run_unit
from reachirl.irl.moirl import mean_task


def _rmse_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.rad2deg(np.sqrt(np.mean((a - b) ** 2))))


def _predict(task, threshold: float, weights: np.ndarray, arm) -> np.ndarray:
    """q on the knots of the DOC of ``task`` on ``arm``, seen from onset to offset as the reaches were."""
    t = replace(task, arm=arm)
    return observe(solve_doc(t, weights), t, threshold).knot_state(t.n_nodes)[:, :2]


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="output folder of `reachirl reproduce` on built-in virtual subjects")
    parser.add_argument("--data-seed", type=int, default=0, help="the run's --data-seed (checked against the run)")
    parser.add_argument("--sections", type=int, default=8)
    args = parser.parse_args(argv)

    try:  # the run's own protocol (knots, training trials, subjects), as the run learned its weights with it
        _, config, units, _ = load_run(args.run)
    except InputError as e:
        parser.error(str(e))
    info = json.loads((args.run / "results.json").read_text(encoding="utf-8"))["data"]
    if info.get("kind") != "builtin":
        parser.error(f"{args.run}: a run on {info.get('source')}, not on the built-in virtual subjects (no truth)")
    data = datasets.load(None, seed=args.data_seed)
    if datasets.fingerprint(data.trials) != info.get("fingerprint"):
        parser.error(f"--data-seed {args.data_seed}: not the seed of the run's virtual subjects ({info.get('source')})")
    truth = np.asarray(data.truth["truth"]["nominal_weights"], dtype=float)
    keys = {  # the main table's fits: not another training subject's (all pairs) nor a posture-transfer fit
        e["unit"]["posture"]: k
        for k, e in units.items()
        if e["unit"].get("method") == "moirl"
        and e["unit"].get("sections") == args.sections
        and not e["unit"].get("train_subject")
        and not e["unit"].get("held_out_posture")
    }
    if not keys:
        parser.error(
            f"{args.run}: no MO-IRL fit with {args.sections} sections; the run has "
            f"{', '.join(map(str, config.sections))} sections of {', '.join(config.methods)}"
        )
    learned = {}
    for posture, key in keys.items():
        try:
            learned[posture] = np.asarray(run_unit(args.run, key)["weights"], dtype=float)
        except InputError as e:
            parser.error(str(e))
    trials = list(data.trials)
    for posture, w in learned.items():
        split = split_trials(trials, posture, config)
        train = list(split.train)
        task, threshold = rest_to_rest(mean_task(train, config.n_nodes)), common_threshold(train)
        a = task.arm
        arms = {
            "own arm": a,
            "masses +10 %": replace(a, m1=1.1 * a.m1, m2=1.1 * a.m2, i1=1.1 * a.i1, i2=1.1 * a.i2),
            "forearm -15 %": replace(a, m2=0.85 * a.m2, i2=0.85 * a.i2),
            "forearm CoM +10 %": replace(a, c2=min(1.1 * a.c2, a.l2)),
            "other subject's arm": mean_task(list(split.iscv), config.n_nodes).arm,
        }
        own_l, own_t = _predict(task, threshold, w, a), _predict(task, threshold, truth, a)
        cells = []
        for name, arm in arms.items():
            q_l, q_t = _predict(task, threshold, w, arm), _predict(task, threshold, truth, arm)
            cells.append(
                f"{name}: dL {_rmse_deg(q_l, own_l):.2f} dT {_rmse_deg(q_t, own_t):.2f} L-T {_rmse_deg(q_l, q_t):.2f}"
            )
        print(f"{posture} | " + " | ".join(cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
