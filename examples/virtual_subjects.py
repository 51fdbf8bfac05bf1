"""How human-like are the virtual subjects, and what do Berret's initial postures look like?

Generates a small virtual data set (1 subject × 5 postures × 5 trials) into a temporary folder, prints its
human-likeness table next to Berret et al. 2011's numbers and the true weight profile, and draws the five
initial postures under the chosen angle reading and under the rejected one (the figure in
``docs/figures/berret_postures.png``). Run: ``.venv/bin/python examples/virtual_subjects.py --figure
/tmp/berret_postures.png``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from reachirl import FEATURES
from reachirl.cli import OneLineParser
from reachirl.errors import InputError
from reachirl.validation import check_figure_file
from reachirl.virtual import (
    FEATURE_SCALE,
    RELATIVE_IMPORTANCE,
    SynthConfig,
    format_human_likeness,
    generate,
    plot_postures,
)


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", type=Path, required=True, help="where to save the posture figure (PNG)")
    parser.add_argument("--trials", type=int, default=5, help="trials per posture, at least 1 (default 5)")
    args = parser.parse_args(argv)
    if args.trials < 1:
        parser.error(f"argument --trials: expected a whole number of at least 1, got {args.trials}")
    try:  # before any work: a figure file matplotlib can write, in a folder that can be made
        check_figure_file(args.figure, "--figure").parent.mkdir(parents=True, exist_ok=True)
    except InputError as e:
        parser.error(str(e))

    import matplotlib

    matplotlib.use("Agg")
    fig = plot_postures()
    fig.savefig(args.figure, dpi=110)
    print(f"posture figure: {args.figure}")

    print("\ntrue weights = relative importance / feature scale; relative importance per window:")
    print("window " + " ".join(f"{f[:10]:>10}" for f in FEATURES))
    for s, row in enumerate(RELATIVE_IMPORTANCE):
        print(f"{s:>6} " + " ".join(f"{v:>10.3f}" for v in row))
    print("scale  " + " ".join(f"{v:>10.3g}" for v in FEATURE_SCALE))

    with tempfile.TemporaryDirectory() as tmp:
        res = generate(tmp, SynthConfig(n_subjects=1, n_trials=args.trials, seed=0))
        header, cells = format_human_likeness(res.human_likeness)
        print(f"\n{len(res.trials)} reaches in {res.elapsed_s:.1f} s, {res.doc_failures} DOC failures redrawn")
        widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(header)]
        print("  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True)))
        for c in cells:
            print("  ".join(v.rjust(w) for v, w in zip(c, widths, strict=True)))
        first = res.trials[0]
        print(
            f"\nfirst trial {first.subject}/{first.posture}/{first.trial_id}: q0 = "
            f"{np.rad2deg(first.q0).round(1)} deg, horizon {first.horizon_s:.3f} s"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
