"""Which cost explains a real subject's reaches?

Preprocesses the UE-ADL subject shipped with reachirl (ADL001: Vicon markers, static calibration trial), learns
8 windows of weights with MO-IRL from its right-arm reaches, predicts its left-arm reaches (mirrored), and prints
the RMSE and, for each window, the cost shares ω·Φ on the fit's own reach that the training data determines
(their 95 % interval from the weights' uncertainty at most 0.25 wide and containing the fit's share); the others
the data cannot tell apart.
Run: ``.venv/bin/python examples/learn_from_ue_adl.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from reachirl import FEATURES, MOIRL
from reachirl.cli import OneLineParser
from reachirl.data.pipeline import preprocess_entries
from reachirl.data.readers import ManifestEntry, read_subject_info
from reachirl.data.ue_adl import SAMPLE_DIR, reach_files
from reachirl.doc.evaluation import evaluate_trials, summarise
from reachirl.errors import InputError
from reachirl.features import cost_shares


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--data", type=Path, default=SAMPLE_DIR, help="a UE-ADL folder (default: the sample shipped in the package)"
    )
    parser.add_argument("--windows", type=int, default=8, help="weight windows, at least 1 (default 8)")
    args = parser.parse_args(argv)
    if args.windows < 1:
        parser.error(f"argument --windows: expected a whole number of at least 1, got {args.windows}")

    try:  # a folder that is not UE-ADL's, or a damaged recording: one line naming it
        entries = [ManifestEntry(file=f, subject="", posture="") for f in reach_files(args.data)]
        trials = preprocess_entries(entries, subject_info=read_subject_info(args.data / "subjects.csv"))
    except InputError as e:
        parser.error(str(e))
    train = [t for t in trials if t.side == "right"]
    test = [t for t in trials if t.side == "left"]
    model = MOIRL(n_windows=args.windows, uncertainty=40).fit(train)
    for name, subset in (("training (right arm)", train), ("validation (left arm)", test)):
        errors = evaluate_trials(
            model.weights_, subset, model.n_nodes, observe=model.observe, path=model.rollout_path()
        )  # as `reachirl evaluate` predicts: as recorded
        r = summarise(errors)["rmse_deg"]["q"]
        print(f"{name:22s} {len(subset)} reaches: RMSE of q {r['mean']:.2f} ± {r['std']:.2f} deg")
    shares = cost_shares(model.weights_, model.reach_features())  # on the fit's own reach, as the intervals
    iv = model.uncertainty_["share_intervals"]
    lo, hi, determined = np.asarray(iv["low"]), np.asarray(iv["high"]), np.asarray(iv["determined"])
    for s, row in enumerate(shares):
        found = [f"{FEATURES[j]} {row[j]:.2f} [{lo[s, j]:.2f}, {hi[s, j]:.2f}]" for j in np.flatnonzero(determined[s])]
        print(f"window {s + 1}: " + ("; ".join(found) if found else "no share determined by the data"))
    print(f"{model.n_iter_} MO-IRL iterations, {model.n_doc_solves_} DOC solves, {model.fit_time_:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
