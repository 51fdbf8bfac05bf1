"""How well do our planar angles agree with the UE-ADL authors' own shoulder and elbow flexion?

Runs every forward reach of a UE-ADL folder through reachirl's pipeline (static calibration, cluster-based
joint centres, filter, sagittal plane, planar IK) and compares q1/q2 with the authors' angles, per subject and
arm: Pearson correlation of the time-normalised onset→offset curves and the mean offset (ours − theirs), in
degrees.

    python examples/ue_adl_agreement.py                     # the one-subject sample shipped in the package
    python examples/ue_adl_agreement.py --root /path/to/ue_adl --distal wrist --per-trial
"""

from __future__ import annotations

import argparse

from reachirl.cli import OneLineParser
from reachirl.data.preprocess import PreprocessOptions
from reachirl.data.ue_adl import SAMPLE_DIR, agreement, agreement_markdown
from reachirl.errors import InputError


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", default=str(SAMPLE_DIR), help="UE-ADL folder (subjects.csv, ADLxxx/)")
    parser.add_argument(
        "--distal",
        choices=("fingertip", "wrist"),
        default="fingertip",
        help="q2 from elbow->fingertip (model) or elbow->wrist (anatomical elbow)",
    )
    parser.add_argument("--plane", choices=("pca", "vertical"), default="pca")
    parser.add_argument("--per-trial", action="store_true", help="also list every trial")
    args = parser.parse_args(argv)
    try:
        rows, trials = agreement(args.root, PreprocessOptions(distal=args.distal, plane=args.plane))
    except InputError as e:  # not a UE-ADL folder, or a damaged recording: one line naming it
        parser.error(str(e))
    print(agreement_markdown(rows))
    if args.per_trial:
        print("\n| trial | frames ours/theirs | shoulder r | elbow r | forearm mm (SD) |\n|---|---|---|---|---|")
        for t in trials:
            print(
                f"| {t['subject']} {t['trial']} | {t['frames_ours']}/{t['frames_theirs']} | "
                f"{t['shoulder_r']:.3f} | {t['elbow_r']:.3f} | "
                f"{t['forearm_mm']:.0f} ({t['forearm_sd_mm']:.1f}) |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
