"""``reachirl fit TRIALS --sections N [--method moirl|maxent|bilevel|kkt] --out MODEL.json``."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from ..data.trial import load_trials
from ..errors import InputError
from ..irl.model import LearnedModel, save_model

METHODS = ("moirl", "maxent", "bilevel", "kkt")


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("fit", help="learn cost weights from demonstration trials")
    p.add_argument("trials", type=Path, help="trials file written by `reachirl preprocess` or `reachirl synth`")
    p.add_argument("--sections", type=int, required=True, help="number of time windows of weights (e.g. 1, 6, 8)")
    p.add_argument("--method", choices=METHODS, default="moirl", help="learning method (default: moirl)")
    p.add_argument("--out", type=Path, required=True, help="model JSON to write")
    p.add_argument("--max-iter", type=int, default=30, help="MO-IRL iterations at most (default 30)")
    p.add_argument("--nodes", type=int, default=100, help="DOC knots N (default 100)")
    p.add_argument("--backend", choices=("casadi", "crocoddyl"), default="casadi",
                   help="DOC backend of the fit's solves (default: casadi)")
    p.add_argument("--rollout", choices=("mean", "per_demo"), default="mean",
                   help="training rollout from the demonstrations' mean start, or one per demonstration")
    return p


def run(args: argparse.Namespace) -> int:
    from ..irl.methods import make_estimator

    console = Console(stderr=True)
    trials = load_trials(args.trials)
    if args.sections < 1 or args.sections > args.nodes:
        raise InputError(f"--sections must be between 1 and --nodes={args.nodes}, got {args.sections}")
    kwargs = {"n_nodes": args.nodes, "backend": args.backend}
    if args.method in ("moirl", "maxent"):
        kwargs.update(max_iter=args.max_iter, rollout=args.rollout)

    with console.status(f"fitting {args.method} with {args.sections} section(s) on {len(trials)} trials") as status:
        def progress(rec: dict) -> None:
            status.update(f"{args.method}: iteration {rec['iteration']}, merit {rec['merit']:.4g}, "
                          f"{rec['doc_solves']} DOC solves")

        est = make_estimator(args.method, args.sections, callback=progress, **kwargs)
        est.fit(trials)
    info = {
        "trials": str(args.trials),
        "n_trials": len(trials),
        "backend": args.backend,
        "trial_ids": [t.id for t in trials],
        "n_iter": getattr(est, "n_iter_", None),
        "n_doc_solves": getattr(est, "n_doc_solves_", None),
        "fit_time_s": getattr(est, "fit_time_", None),
        "stop_reason": getattr(est, "stop_reason_", None),
        "flag": getattr(est, "flag_", None),
        "warnings": list(getattr(est, "warnings_", [])),
        "history": getattr(est, "history_", []),
    }
    save_model(args.out, LearnedModel(weights=est.weights_, n_nodes=args.nodes, method=args.method, info=info))
    for msg in info["warnings"]:
        console.print(f"[bold yellow]warning:[/] {msg}")
    print(f"wrote {args.out}: {args.method}, {args.sections} section(s), {info['n_iter']} iterations, "
          f"{info['n_doc_solves']} DOC solves ({args.backend}), {info['fit_time_s']:.1f} s")
    return 0
