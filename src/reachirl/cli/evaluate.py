"""``reachirl evaluate --model MODEL.json TRIALS --out METRICS.json``: RMSE of each trial's prediction."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console
from rich.progress import Progress

from ..data.checks import check_model_rollout
from ..data.trial import load_trials
from ..doc.evaluation import summarise
from ..errors import InputError
from ..experiments.no_data import annotate_no_data
from ..io import atomic_write_json, holding_folder
from ..irl.model import load_model
from ..irl.provenance import fingerprint
from ..validation import check_output_dir, check_output_file, check_output_kind
from . import SUMMARIES
from ._args import (
    JSON_KINDS,
    PREDICTION_BACKEND_HELP,
    add_selection,
    chosen_trials,
    export_names,
    file_path,
    output_folder_files,
    refuse_foreign_export_files,
    refuse_overwrite,
)


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "evaluate",
        help=SUMMARIES["evaluate"],
        description="Predict every trial by the DOC under the model's weights, from the trial's own arm, start, "
        "target and duration, as the model was fitted (seen as recorded, between the crossings of the trial's "
        "onset threshold, unless it was fitted with --seed-form), and write the RMSE of the joint angles "
        "(degrees, on N+1 points of normalised time: the DOC's knots, or the part seen evenly resampled) to "
        "METRICS.json; with --predictions, also the trajectories as CSV and OpenSim MOT (docs/outputs.md).",
    )
    p.add_argument("--model", type=Path, required=True, help="model JSON written by `reachirl fit`")
    p.add_argument("trials", type=Path, help="trials file")
    p.add_argument("--out", type=file_path, required=True, help="metrics JSON to write")
    p.add_argument(
        "--backend",
        choices=("casadi", "crocoddyl"),
        default=None,
        help=PREDICTION_BACKEND_HELP,
    )
    p.add_argument(
        "--include-failed",
        action="store_true",
        help="average the RMSE of predictions whose DOC did not converge too (default: count them, leave them out)",
    )
    p.add_argument(
        "--predictions",
        type=Path,
        default=None,
        metavar="DIR",
        help="also write each trial's demonstration and prediction (q, q̇, τ in SI and degrees) as "
        "DIR/<trial id>.csv and the predicted angles as the OpenSim motion file DIR/<trial id>.mot "
        "(slashes in ids become _; DIR/index.csv maps ids to files). A prediction whose DOC did not converge "
        "is left out: index.csv lists it with no file and converged false (default: none)",
    )
    add_selection(p, "predict")
    return p


def summary_line(summary: dict, backend: str) -> str:
    """One line of :func:`reachirl.doc.evaluation.summarise`'s figures: the RMSE of q1, q2 and q (mean ± SD, deg)
    and the DOC failures."""
    r, fails = summary["rmse_deg"], summary["doc_failures"]
    how = "included in" if summary["failures_included"] else "left out of"
    note = f"; {fails} DOC failure(s) ({backend}), {how} the RMSE" if fails else ""
    if r["q"]["mean"] is None:
        return f"{summary['n_trials']} trials: no prediction converged ({backend}); no RMSE"
    return (
        f"{summary['n_trials']} trials: RMSE q1 {r['q1']['mean']:.2f} ± {r['q1']['std']:.2f} deg, "
        f"q2 {r['q2']['mean']:.2f} ± {r['q2']['std']:.2f} deg, q {r['q']['mean']:.2f} ± {r['q']['std']:.2f} deg"
        f" over {summary['n_included']} prediction(s){note}"
    )


def prediction_exports(trials, errors, set_name: str = ""):
    """One :class:`~reachirl.data.exports.TrajectoryExport` per trial: the demonstration resampled on the DOC's
    knots beside the prediction, and whether its DOC converged (one that did not is listed, not written)."""
    from ..data.exports import TrajectoryExport

    out = []
    for tr, e in zip(trials, errors, strict=True):
        sol = e.prediction
        demo = tr.resample(sol.t.size)
        out.append(
            TrajectoryExport(
                id=tr.id,
                t=sol.t,
                side=tr.side,
                set=set_name,
                demo={"q": demo.q, "qd": demo.qd, "tau": demo.tau[:-1]},
                pred={"q": sol.q, "qd": sol.qd, "tau": sol.tau},
                converged=bool(e.converged),
            )
        )
    return out


def run(args: argparse.Namespace) -> int:
    check_output_file(args.out)
    if args.predictions is None:
        return _evaluate(args, None)
    if args.predictions.exists() and not args.predictions.is_dir():
        raise InputError("exists and is not a folder; --predictions needs a folder", args.predictions)
    check_output_dir(args.predictions, "--predictions")  # every output checked before anything is written
    # one command at a time in the folder: a second export would remove the first one's index and files
    with holding_folder(args.predictions, "--predictions") as make:
        return _evaluate(args, make)


def _evaluate(args: argparse.Namespace, make_predictions) -> int:
    """The evaluation, once the --predictions folder (if any) is held; ``make_predictions()`` makes it and holds
    it, before its first file is written."""
    refuse_overwrite({"--out": args.out, "--predictions": args.predictions}, [args.model, args.trials])
    check_output_kind(args.out, ".json", kind=JSON_KINDS["evaluate"])
    model = load_model(args.model)
    check_model_rollout(model, args.model)
    backend = args.backend or model.backend
    trials, chosen = chosen_trials(args, load_trials(args.trials))
    if args.predictions is not None:
        names = export_names(tr.id for tr in trials)
        output_folder_files(args.predictions, names, [args.model, args.trials], "--predictions", {"--out": args.out})
        refuse_foreign_export_files(args.predictions, names, "--predictions", [args.model, args.trials])
    err = Console(stderr=True)
    with Progress(transient=True, console=err, disable=not err.is_terminal) as progress:  # a log: no blank line
        task = progress.add_task("predicting", total=len(trials))
        errors = model.evaluate(trials, backend=backend, on_trial=lambda e: progress.advance(task))
    summary = summarise(errors, include_failed=args.include_failed)
    if args.predictions is not None:
        make_predictions()  # held before the first change (a folder made meanwhile by another command: refused)
    # METRICS.json last, an earlier one removed first: an interrupt never leaves it beside other predictions
    Path(args.out).unlink(missing_ok=True)
    if args.predictions is not None:
        from ..data.exports import export_trajectories

        export_trajectories(args.predictions, prediction_exports(trials, errors))
    # a mean that cannot be computed (every DOC failed) is written with its reason, never a bare null
    atomic_write_json(
        args.out,
        annotate_no_data(
            {
                "model": str(Path(args.model).resolve()),
                "trials_file": str(Path(args.trials).resolve()),
                "trials_fingerprint": fingerprint(trials),
                "backend": backend,
                "summary": summary,
                "selection": chosen,
                "trials": [e.to_dict() for e in errors],
            }
        ),
    )
    print(summary_line(summary, backend))
    if args.predictions is not None:
        failed = sum(not e.converged for e in errors)
        left_out = f"; {failed} whose DOC did not converge left out (index.csv: converged false)" if failed else ""
        print(f"wrote {len(errors) - failed} trajectories (.csv, .mot) and index.csv to {args.predictions}{left_out}")
    print(f"wrote {args.out}")
    return 0
