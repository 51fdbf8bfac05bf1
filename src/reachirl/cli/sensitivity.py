"""``reachirl sensitivity RUN_DIR --out DIR``: which costs does the data need?

For the fits of a ``reachirl reproduce`` run (by default its first method, every posture, its largest section
count): refit with each feature removed and with each window's weights frozen at ω₀ (occlusion: the change in
training, CV and ISCV RMSE, with a paired 95 % interval over trials), change each weight by ±x % (sensitivity:
DOC re-solves of the training trials), and say which weight directions the training trials determine (from the
Jacobian of the observed rollouts). Writes DIR/sensitivity.csv (one row per feature, and per window where it applies),
DIR/sensitivity.md, DIR/identifiability.json and DIR/figures/sensitivity_<posture>.png. Each finished job (a
refit, a window's ±X %, a posture's determination) is kept in DIR/checkpoints/: a run stopped early (Ctrl-C, a
closed terminal) resumes there when started again, running only the jobs whose inputs changed (another --percent
reruns the ±X % jobs alone), and sensitivity.csv, written last, marks a finished analysis.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from ..errors import InputError
from ..io import holding_folder, reading_folder, remove_temporaries
from ..validation import NODES_RANGE, check_output_dir
from . import SUMMARIES
from ._args import int_in, non_negative_int, number_in, refuse_out_in_run_folders, refuse_overwrite

#: local worker processes at most (as reproduce's --workers)
MAX_WORKERS = 256


def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "sensitivity",
        help=SUMMARIES["sensitivity"],
        description=__doc__.replace("``", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("run_dir", metavar="RUN_DIR", help="the --out folder of `reachirl reproduce`")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument(
        "--percent",
        type=number_in(0.001, 99.0),
        default=None,
        metavar="X",
        help="change each weight by ±X %% for the sensitivity, 0.001 to 99 (default 10)",
    )
    p.add_argument(
        "--sections",
        type=int_in(1, NODES_RANGE[1]),
        metavar="N",
        help=f"section count to analyse, 1 to {NODES_RANGE[1]} (default: the run's largest)",
    )
    p.add_argument("--postures", nargs="+", metavar="NAME", help="postures to analyse (default: all of the run)")
    p.add_argument("--method", metavar="NAME", help="method to analyse (default: the run's first)")
    p.add_argument("--no-occlusion", action="store_true", help="skip the occlusion refits")
    p.add_argument("--no-sensitivity", action="store_true", help="skip the ±X %% weight changes")
    p.add_argument(
        "--seed",
        type=non_negative_int,
        default=None,
        metavar="N",
        help="seed of the occlusion's paired bootstrap intervals over trials (default 0)",
    )
    p.add_argument(
        "--workers",
        type=int_in(1, MAX_WORKERS),
        default=None,
        metavar="N",
        help=f"local worker processes, 1 to {MAX_WORKERS} (default: all cores; 1 runs in this process)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress lines")
    return p


def run(args) -> int:
    from ..experiments.sensitivity import SensitivityConfig, run_sensitivity
    from ..experiments.sensitivity_outputs import remove_outputs, write_sensitivity

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder; --out needs a folder", out)
    check_output_dir(out)  # before any work: a folder in which files can be written (not below a file)
    refuse_overwrite({"--out": out}, [args.run_dir])
    refuse_out_in_run_folders(out, Path(args.run_dir), RUN_FOLDERS, "the analysis", "sensitivity")
    _check_analysis_options(args)
    cfg = SensitivityConfig(
        percent=args.percent,
        sections=args.sections,
        postures=tuple(args.postures) if args.postures else None,
        method=args.method,
        occlusion=not args.no_occlusion,
        sensitivity=not args.no_sensitivity,
        seed=args.seed,
    )
    state = {"n": 0, "total": 0}
    t0 = time.perf_counter()

    def on_start(total, reused):
        state["total"] = total
        make_out()  # a folder made by this analysis is held once made
        remove_outputs(out)  # an earlier analysis's results never outlive this one's start
        if reused and not args.no_progress:
            print(f"{reused} of {total} jobs reused from {checkpoints}", file=sys.stderr, flush=True)

    def on_done(name, reused):
        state["n"] += 1
        if not args.no_progress and not reused:
            print(
                f"[{state['n']}/{state['total']}] {name} ({time.perf_counter() - t0:.0f} s)",
                file=sys.stderr,
                flush=True,
            )

    checkpoints = out / "checkpoints"
    for folder in (checkpoints, out / "figures"):  # before any work: a job's checkpoint would fail after it
        if folder.exists() and not folder.is_dir():
            raise InputError("exists and is not a folder; sensitivity writes into it (remove it)", folder)
    _refuse_foreign_outputs(out)
    # one analysis at a time in a folder (a second would remove this one's outputs at its start and mix their
    # checkpoints), released at the end (the system drops it with a killed process)
    # and the run it reads is not being rewritten meanwhile (a reproduce into RUN_DIR is refused while it is read)
    with holding_folder(out, "--out") as make_out, reading_folder(args.run_dir):
        for folder in (out, checkpoints, out / "figures"):
            remove_temporaries(folder)  # what a killed run was writing
        res = run_sensitivity(
            args.run_dir,
            cfg,
            workers=args.workers or (os.cpu_count() or 1),
            checkpoint_dir=checkpoints,
            on_start=on_start,
            on_done=on_done,
        )
        paths = write_sensitivity(res, out)
        print((out / "sensitivity.md").read_text(encoding="utf-8"))
        print(f"wrote {', '.join(str(p) for p in paths)} in {time.perf_counter() - t0:.1f} s")
        return 0


def _check_analysis_options(args) -> None:
    """Refuse --percent with --no-sensitivity and --seed with --no-occlusion (each would be left unused: the analysis
    it sets is skipped), then fill in their defaults."""
    for name, skipped, default in (("percent", "sensitivity", 10.0), ("seed", "occlusion", 0)):
        if getattr(args, name) is None:
            setattr(args, name, default)
        elif getattr(args, f"no_{skipped}"):
            raise InputError(f"--{name} sets the {skipped} analysis, which --no-{skipped} skips")


#: the folders of a `reproduce` run that it writes and reads back (its checkpoints, figures, models, predictions)
RUN_FOLDERS = ("units", "figures", "models", "predictions")


def _refuse_foreign_outputs(out: Path) -> None:
    """Before any work: the files of :data:`~reachirl.experiments.sensitivity_outputs.OUTPUT_FILES` in ``out`` are
    an earlier analysis's (:func:`~reachirl.experiments.sensitivity_outputs.is_analysis`), never the user's own: a
    folder that holds one without an analysis's ``identifiability.json`` is refused (:class:`InputError` naming the
    file), not cleared."""
    from ..experiments.sensitivity_outputs import OUTPUT_FILES, is_analysis

    present = [n for n in OUTPUT_FILES if (out / n).exists()]
    if present and not is_analysis(out):
        raise InputError(
            "--out: exists in a folder that holds no earlier `reachirl sensitivity` analysis (no identifiability.json "
            "written by one); the analysis would replace or remove it (choose another --out, or remove it first)",
            out / present[0],
        )
