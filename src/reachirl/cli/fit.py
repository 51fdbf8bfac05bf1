"""``reachirl fit TRIALS --sections N [--method moirl|maxent|bilevel|kkt] --out MODEL.json``."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from ..data.trial import load_trials
from ..errors import InputError
from ..irl.model import LearnedModel, save_model
from ..validation import MAX_ITER, NODES_RANGE, check_output_file
from ._args import int_in

MIN_NODES, MAX_NODES = NODES_RANGE

METHODS = ("moirl", "maxent", "bilevel", "kkt")


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("fit", help="learn cost weights from demonstration trials")
    p.add_argument("trials", type=Path, help="trials file written by `reachirl preprocess` or `reachirl synth`")
    p.add_argument("--sections", type=int_in(1, MAX_NODES), required=True,
                   help="number of time windows of weights (e.g. 1, 6, 8), 1 to --nodes")
    p.add_argument("--method", choices=METHODS, default="moirl", help="learning method (default: moirl)")
    p.add_argument("--out", type=Path, required=True, help="model JSON to write")
    p.add_argument("--max-iter", type=int_in(1, MAX_ITER), default=30,
                   help=f"MO-IRL iterations at most, 1 to {MAX_ITER} (default 30)")
    p.add_argument("--nodes", type=int_in(MIN_NODES, MAX_NODES), default=100,
                   help=f"DOC knots N, {MIN_NODES} to {MAX_NODES} (default 100)")
    p.add_argument("--rollout", choices=("mean", "per_demo"), default="mean",
                   help="training rollout from the demonstrations' mean start, or one per demonstration")
    return p


def run(args: argparse.Namespace) -> int:
    from ..irl.methods import make_estimator

    console = Console(stderr=True)
    check_output_file(args.out)
    trials = load_trials(args.trials)
    if args.sections > args.nodes:
        raise InputError(f"--sections must be between 1 and --nodes={args.nodes}, got {args.sections}")
    kwargs = {"n_nodes": args.nodes}
    if args.method in ("moirl", "maxent"):
        kwargs.update(max_iter=args.max_iter, rollout=args.rollout)

    with console.status(f"fitting {args.method} with {args.sections} section(s) on {len(trials)} trials") as status:
        def progress(rec: dict) -> None:
            status.update(f"{args.method}: iteration {rec.get('iteration', '?')}, merit {rec.get('merit', '?')}, "
                          f"{rec.get('doc_solves', '?')} DOC solves")

        import inspect

        from ..irl.methods import METHODS

        # only what the method's constructor takes (bilevel and kkt have no callback)
        accepted = inspect.signature(METHODS[args.method].__init__).parameters
        any_kw = any(p.kind is p.VAR_KEYWORD for p in accepted.values())
        kwargs = {k: v for k, v in {**kwargs, "callback": progress}.items() if any_kw or k in accepted}
        est = make_estimator(args.method, args.sections, **kwargs)
        est.fit(trials)
    info = {
        "trials": str(args.trials),
        "n_trials": len(trials),
        "trial_ids": [t.id for t in trials],
        "n_iter": getattr(est, "n_iter_", None),
        "n_doc_solves": getattr(est, "n_doc_solves_", None),
        "fit_time_s": getattr(est, "fit_time_", None),
        "stop_reason": getattr(est, "stop_reason_", None),
        "history": getattr(est, "history_", []),
    }
    save_model(args.out, LearnedModel(weights=est.weights_, n_nodes=args.nodes, method=args.method, info=info))
    print(f"wrote {args.out}: {args.method}, {args.sections} section(s), {info['n_iter']} iterations, "
          f"{info['n_doc_solves']} DOC solves"
          + (f", {info['fit_time_s']:.1f} s" if isinstance(info["fit_time_s"], int | float) else ""))
    return 0
