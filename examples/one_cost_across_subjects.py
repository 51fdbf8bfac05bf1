"""Does one cost learned from several subjects predict a new subject better than one subject's own cost?

Leave one subject out on a folder of UE-ADL recordings (or any trials file): learn one cost from the other
subjects' right-arm reaches (one training rollout per subject, ``reachirl fit --subject A B ...``), predict the
held-out subject's right-arm reaches, and compare with each single-subject fit predicting the same reaches (as
``reproduce --iscv all-pairs`` does). Prints one line per held-out subject and the means.
Run: ``.venv/bin/python examples/one_cost_across_subjects.py --data trials.npz`` (a trials file of several
subjects, e.g. from ``reachirl preprocess path/to/ue_adl/ADL0* --markerset ue-adl ...``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from reachirl import MOIRL
from reachirl.cli import OneLineParser
from reachirl.data.trial import load_trials
from reachirl.doc.evaluation import evaluate_trials, summarise
from reachirl.errors import InputError


def _rmse(model: MOIRL, trials) -> float:
    errors = evaluate_trials(model.weights_, trials, model.n_nodes, observe=model.observe, path=model.rollout_path())
    return float(summarise(errors)["rmse_deg"]["q"]["mean"])


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="a trials file of several subjects")
    parser.add_argument("--windows", type=int, default=8, help="weight windows, at least 1 (default 8)")
    parser.add_argument("--side", default="right", help="the arm to learn and predict (default right)")
    args = parser.parse_args(argv)
    if args.windows < 1:
        parser.error(f"argument --windows: expected a whole number of at least 1, got {args.windows}")

    try:
        trials = [t for t in load_trials(args.data) if t.side == args.side]
    except InputError as e:  # not a trials file: one line naming it
        parser.error(str(e))
    subjects = sorted({t.subject for t in trials})
    if len(subjects) < 3:
        parser.error(f"{args.data}: needs at least 3 subjects, found {len(subjects)}")
    own = {s: MOIRL(args.windows).fit([t for t in trials if t.subject == s]) for s in subjects}
    pooled_all, single_all = [], []
    for held in subjects:
        test = [t for t in trials if t.subject == held]
        pooled = _rmse(MOIRL(args.windows).fit([t for t in trials if t.subject != held]), test)
        single = float(np.mean([_rmse(own[s], test) for s in subjects if s != held]))
        pooled_all.append(pooled)
        single_all.append(single)
        print(
            f"{held}: one cost from the {len(subjects) - 1} others {pooled:.2f} deg; "
            f"each other subject's own cost {single:.2f} deg (mean)"
        )
    better = sum(p < s for p, s in zip(pooled_all, single_all, strict=True))
    print(
        f"mean: pooled {np.mean(pooled_all):.2f} deg, single-subject {np.mean(single_all):.2f} deg; pooled better "
        f"for {better} of {len(subjects)} subjects"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
