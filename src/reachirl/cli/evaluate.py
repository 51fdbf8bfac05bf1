"""``reachirl evaluate --model MODEL.json TRIALS --out METRICS.json``: RMSE of each trial's prediction."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console
from rich.progress import Progress

from ..data.trial import load_trials
from ..evaluation import evaluate_trials, summarise
from ..io import atomic_write_json
from ..irl.model import load_model


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("evaluate", help="predict every trial from its own start and report joint-angle RMSE")
    p.add_argument("--model", type=Path, required=True, help="model JSON written by `reachirl fit`")
    p.add_argument("trials", type=Path, help="trials file")
    p.add_argument("--out", type=Path, required=True, help="metrics JSON to write")
    p.add_argument("--backend", choices=("casadi", "crocoddyl"), default="casadi", help="DOC backend")
    p.add_argument("--include-failed", action="store_true",
                   help="average the RMSE of predictions whose DOC did not converge too (default: count them, "
                        "leave them out)")
    return p


def run(args: argparse.Namespace) -> int:
    model = load_model(args.model)
    trials = load_trials(args.trials)
    with Progress(transient=True, console=Console(stderr=True)) as progress:
        task = progress.add_task("predicting", total=len(trials))
        errors = evaluate_trials(model.weights, trials, n_nodes=model.n_nodes, backend=args.backend,
                                 on_trial=lambda e: progress.advance(task))
    summary = summarise(errors, include_failed=args.include_failed)
    atomic_write_json(args.out, {"summary": summary, "trials": [e.to_dict() for e in errors]})
    r = summary["rmse_deg"]
    fails = summary["doc_failures"]
    how = "included in" if args.include_failed else "left out of"
    note = f"; {fails} DOC failure(s) ({args.backend}), {how} the RMSE" if fails else ""
    if r["q"]["mean"] is None:
        print(f"{summary['n_trials']} trials: no prediction converged ({args.backend}); no RMSE")
    else:
        print(f"{summary['n_trials']} trials: RMSE q1 {r['q1']['mean']:.2f} ± {r['q1']['std']:.2f} deg, "
              f"q2 {r['q2']['mean']:.2f} ± {r['q2']['std']:.2f} deg, q {r['q']['mean']:.2f} ± {r['q']['std']:.2f} deg"
              f" over {summary['n_included']} prediction(s){note}")
    print(f"wrote {args.out}")
    return 0
