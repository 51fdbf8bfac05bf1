"""``reachirl fit TRIALS --sections N [--method moirl|maxent|bilevel|kkt] --out MODEL.json``."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from ..data.trial import load_trials
from ..errors import InputError
from ..irl.model import LearnedModel, save_model
from ..validation import MAX_ITER, NODES_RANGE, check_output_file
from ._args import add_selection, chosen_trials, int_in, refuse_overwrite

MIN_NODES, MAX_NODES = NODES_RANGE

METHODS = ("moirl", "maxent", "bilevel", "kkt")


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "fit",
        help="learn cost weights from demonstration trials",
        description="Learn the time-varying cost weights (n_windows x 7, FEATURES order) behind the trials of a "
        "trials file with MO-IRL or a baseline, and write them with their provenance to MODEL.json "
        "(schema: docs/outputs.md).",
    )
    p.add_argument("trials", type=Path, help="trials file written by `reachirl preprocess` or `reachirl synth`")
    p.add_argument("--sections", type=int_in(1, MAX_NODES), required=True,
                   help="number of time windows of weights (e.g. 1, 6, 8), 1 to --nodes; required")
    p.add_argument("--method", choices=METHODS, default="moirl", help="learning method (default: moirl)")
    p.add_argument("--out", type=Path, required=True, help="model JSON to write")
    p.add_argument("--max-iter", type=int_in(1, MAX_ITER), default=30,
                   help=f"iterations at most of moirl and maxent, 1 to {MAX_ITER}; bilevel and kkt ignore it "
                   "(default 30)")
    p.add_argument("--nodes", type=int_in(MIN_NODES, MAX_NODES), default=100,
                   help=f"DOC knots N, {MIN_NODES} to {MAX_NODES} (default 100)")
    p.add_argument("--backend", choices=("casadi", "crocoddyl"), default="casadi",
                   help="DOC backend of the fit's solves (default: casadi)")
    p.add_argument("--rollout", choices=("mean", "per_demo"), default="mean",
                   help="MO-IRL/MaxEnt training rollouts: one from the demonstrations' mean start, target and "
                   "duration (mean, the seed, default), or one per demonstration, each compared with its own "
                   "(per_demo: about five times the fit time)")
    p.add_argument("--observe", action=argparse.BooleanOptionalAction, default=True,
                   help="MO-IRL/MaxEnt: see each rollout as the trials were recorded, between its own crossings of "
                   "their onset threshold (default; `evaluate` then predicts the same way); --no-observe: whole "
                   "rollouts, as the seed")
    p.add_argument("--merit", choices=("state", "normalised"), default="normalised",
                   help="MO-IRL/MaxEnt merit: each channel of (q, q̇) by the demonstrations' spread (normalised, "
                   "default) or the seed's full-state error (state)")
    p.add_argument("--fallback", choices=("merit", "none"), default="merit",
                   help="MO-IRL/MaxEnt: when the likelihood's step lowers no merit, step on a model of the merit "
                   "(merit, default) or stop there (none: the seed's rule)")
    p.add_argument("--merit-model", choices=("probes", "gauss-newton"), default="probes",
                   help="MO-IRL/MaxEnt's model of the merit for those steps: 14 probe solves per rollout (probes, "
                   "default) or Gauss-Newton from the DOC's sensitivities (gauss-newton: no solve; also tried when the "
                   "likelihood's step gains less than 1 %%)")
    add_selection(p, "learn from")
    return p


def _accepts(method: str, name: str) -> bool:
    """Whether ``method``'s estimator takes the keyword ``name``, following ``**kwargs`` up to the base classes
    (``MaxEntIRL(**kwargs)`` passes them on to ``MOIRL``)."""
    import inspect

    from ..irl.methods import METHODS as CLASSES

    for cls in CLASSES[method].__mro__:
        if "__init__" not in cls.__dict__ or cls is object:
            continue
        params = inspect.signature(cls.__init__).parameters
        if name in params:
            return True
        if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
            return False
    return False


def run(args: argparse.Namespace) -> int:
    from ..irl.methods import make_estimator

    console = Console(stderr=True)
    check_output_file(args.out)
    refuse_overwrite({"--out": args.out}, [args.trials])
    trials, chosen = chosen_trials(args, load_trials(args.trials))
    if args.sections > args.nodes:
        raise InputError(f"--sections must be between 1 and --nodes={args.nodes}, got {args.sections}")
    kwargs = {"n_nodes": args.nodes, "backend": args.backend}
    if args.method in ("moirl", "maxent"):
        kwargs.update(max_iter=args.max_iter, rollout=args.rollout, observe=args.observe, merit=args.merit,
                      fallback=None if args.fallback == "none" else args.fallback, merit_model=args.merit_model)

    with console.status(f"fitting {args.method} with {args.sections} section(s) on {len(trials)} trials") as status:
        def progress(rec: dict) -> None:
            status.update(f"{args.method}: iteration {rec.get('iteration', '?')}, merit {rec.get('merit', '?')}, "
                          f"{rec.get('doc_solves', '?')} DOC solves")

        if _accepts(args.method, "callback"):  # the baselines take no progress callback
            kwargs["callback"] = progress
        est = make_estimator(args.method, args.sections, **kwargs)
        est.fit(trials)
    path = est.rollout_path()
    info = {
        "trials": str(args.trials),
        "n_trials": len(trials),
        "selection": chosen,  # --subject/--posture/--side (None: every trial of the file)
        "backend": args.backend,
        "observe": bool(getattr(est, "observe", False)),  # `evaluate` predicts as the fit saw its rollouts
        "rollout_q": None if path is None else path.tolist(),  # the fit's own reach: `evaluate`'s cold start
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
          f"{info['n_doc_solves']} DOC solves ({args.backend})"
          + (f", {info['fit_time_s']:.1f} s" if isinstance(info["fit_time_s"], int | float) else ""))
    return 0
