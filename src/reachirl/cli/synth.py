"""``reachirl synth``: write virtual subjects on Berret's protocol, their true weights in ``truth.json``."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from . import SUMMARIES
from ._args import float_in, int_in, non_negative_int


def add_parser(subparsers) -> argparse.ArgumentParser:
    from ..virtual import FORMATS, POSTURES

    p = subparsers.add_parser(
        "synth",
        help=SUMMARIES["synth"],
        description=(
            "Generate virtual subjects reaching to a vertical bar from Berret et al. 2011's five initial "
            "postures. Each reach is the DOC solution under the subject's true time-varying weights "
            "(jittered per trial), recorded as markers SHO, ELB, WRI, FTP at 100 Hz in mm (TRC in OpenSim's "
            "Y-up axes, C3D with the lab's Z up) or as joint angles (MOT, degrees). Writes the recordings, "
            "manifest.csv, subjects.csv, truth.json and human_likeness.csv. Read them back with: reachirl preprocess "
            "DIR/*.trc --manifest DIR/manifest.csv --subject-info DIR/subjects.csv "
            "--markers shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"
        ),
    )
    p.add_argument(
        "--out",
        required=True,
        help="output folder: a new one, one without synth's file names, or an earlier synth data set (replaced; "
        "one interrupted while its files were written is finished)",
    )
    p.add_argument(
        "--subjects", type=int_in(1, 100), default=2, help="number of virtual subjects, 1 to 100 (default 2)"
    )
    p.add_argument("--trials", type=int_in(1, 1000), default=20, help="trials per posture, 1 to 1000 (default 20)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="random seed (default 0); same seed, same bytes")
    p.add_argument("--format", dest="fmt", choices=FORMATS, default="trc", help="file format (default trc)")
    p.add_argument(
        "--postures",
        nargs="+",
        choices=POSTURES,
        default=list(POSTURES),
        help="initial postures to record (default all five)",
    )
    p.add_argument(
        "--target-fraction",
        type=float_in(0.5, 1.0),
        default=0.95,
        help="bar distance as a fraction of arm length (default 0.95, the seed's; Berret used 0.85); at least 0.1 "
        "beyond every chosen posture's start fingertip, so 0.72 or more with P2 and 0.74 or more with P4",
    )
    p.add_argument(
        "--truth",
        metavar="CSV",
        help="the true cost (default: the paper's pattern, 8 windows, joint acceleration dominating onset and "
        "end): a CSV whose header names the 7 features and whose rows (one per equal time window, 1 to 20) give "
        "each feature's relative importance in that window (weights = importance / the feature's typical size)",
    )
    p.add_argument("--workers", type=int_in(1, 256), default=2, help="worker processes, 1 to 256 (default 2)")
    return p


def run(args) -> int:
    from ..virtual import SynthConfig, format_human_likeness, generate
    from ..virtual.files import read_relative_importance

    if args.truth is not None and Path(args.out).resolve() in Path(args.truth).resolve().parents:
        raise InputError(
            "--truth lies in --out, whose files synth replaces (a truth named manifest.csv or human_likeness.csv "
            "was overwritten): keep it outside the folder",
            args.truth,
        )
    truth = None if args.truth is None else read_relative_importance(args.truth)
    try:
        config = SynthConfig(
            n_subjects=args.subjects,
            n_trials=args.trials,
            seed=args.seed,
            postures=tuple(args.postures),
            fmt=args.fmt,
            target_fraction=args.target_fraction,
            workers=args.workers,
            relative_importance=truth,
        )
    except ValueError as e:
        raise InputError(str(e)) from None
    from ..io import holding_folder
    from ..validation import check_output_dir

    check_output_dir(args.out)
    from ..virtual.files import synth_folder_clash

    # one command at a time in the folder: a second synth would remove the first one's description and
    # recordings while it writes them
    with holding_folder(args.out, "--out") as make:
        clash = synth_folder_clash(args.out)
        if clash is not None:
            raise InputError(
                f"--out holds {clash} and is not a synth data set (no truth.json or synth-incomplete.json from "
                "reachirl synth); synth would replace it: choose a new folder, or empty this one",
                args.out,
            )
        try:
            make()  # generate() makes it first thing too
            result = generate(args.out, config)
        except OSError as e:
            raise InputError(f"cannot write ({e.strerror or e})", args.out) from None
    n = len(result.trials)
    print(
        f"wrote {n} {config.fmt.upper()} trials of {len(result.subjects)} subjects to {result.out_dir} "
        f"in {result.elapsed_s:.1f} s ({result.doc_failures} DOC failures redrawn)"
    )
    print("  manifest.csv, subjects.csv, truth.json (true weights), human_likeness.csv")
    _print_table(format_human_likeness(result.human_likeness))
    return 0


def _print_table(table) -> None:
    header, cells = table
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:  # pragma: no cover - rich is a dependency
        print("\t".join(header))
        for row in cells:
            print("\t".join(row))
        return
    from rich import box

    t = Table(title="Human-likeness vs Berret 2011 (fingertip, 5 % of peak speed onset/offset)", box=box.SIMPLE)
    for h in header:
        t.add_column(h, justify="right", no_wrap=True)
    for row in cells:
        t.add_row(*row)
    console = Console()
    Console(width=max(console.width, 110)).print(t)
