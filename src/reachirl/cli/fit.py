"""``reachirl fit TRIALS --sections N [--method moirl|maxent|bilevel|kkt] --out MODEL.json``."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from rich.console import Console

from ..data.trial import load_trials
from ..errors import InputError
from ..irl.model import LearnedModel, save_model
from ..irl.options import ROLLOUTS
from ..irl.uncertainty import DEFAULT_SAMPLES, UNDETERMINED_WIDTH, mean_width, prior_gives_verdict
from ..validation import MAX_ITER, NODES_RANGE, check_output_file, check_output_kind
from . import SUMMARIES
from ._args import JSON_KINDS, add_selection, chosen_trials, file_path, int_in, refuse_overwrite, samples_or_none

MIN_NODES, MAX_NODES = NODES_RANGE

METHODS = ("moirl", "maxent", "bilevel", "kkt")


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "fit",
        help=SUMMARIES["fit"],
        description="Learn the time-varying cost weights (n_windows x 7, FEATURES order) behind the trials of a "
        "trials file with MO-IRL or a baseline, and write them with their provenance to MODEL.json "
        "(schema: docs/outputs.md).",
    )
    p.add_argument(
        "trials",
        type=Path,
        help="trials file (NPZ) written by `reachirl preprocess` (from recordings, `reachirl synth`'s too)",
    )
    p.add_argument(
        "--sections",
        type=int_in(1, MAX_NODES),
        required=True,
        help="number of time windows of weights (e.g. 1, 6, 8), 1 to --nodes (at most 1000); required",
    )
    p.add_argument("--method", choices=METHODS, default="moirl", help="learning method (default: moirl)")
    p.add_argument("--out", type=file_path, required=True, help="model JSON to write")
    p.add_argument(
        "--max-iter",
        type=int_in(1, MAX_ITER),
        default=None,
        metavar="N",
        help=(
            f"iterations at most, 1 to {MAX_ITER}: of moirl and maxent per stage (an observed fit runs a whole-rollout "
            "stage, then the observed one; default 30); of bilevel's direct search (default: none, "
            "its budget of 400 DOC solves stops it); not with kkt, which solves once"
        ),
    )
    p.add_argument(
        "--nodes",
        type=int_in(MIN_NODES, MAX_NODES),
        default=100,
        help=f"DOC knots N, {MIN_NODES} to {MAX_NODES} (default 100)",
    )
    p.add_argument(
        "--backend",
        choices=("casadi", "crocoddyl"),
        default="casadi",
        help="DOC backend of the fit's solves (default: casadi)",
    )
    p.add_argument(
        "--rollout",
        choices=ROLLOUTS,
        default=None,
        help="MO-IRL/MaxEnt training rollouts: one per task (subject, posture) from its trials' mean start, "
        "target and duration (per_task, default: several postures or subjects learn one shared cost), "
        "one per trial (per_demo: about five times the fit time), or one for all trials (mean)",
    )
    p.add_argument(
        "--seed-form",
        action="store_true",
        help="MO-IRL/MaxEnt: the seed paper's method exactly as written (raw subproblem with beta, its "
        "alpha search and stopping rule, the DOC over each trial's duration, the full-state merit); "
        "docs/method.md lists what the default adds",
    )
    p.add_argument(
        "--uncertainty",
        type=samples_or_none(20, 1000),
        nargs="?",
        const=DEFAULT_SAMPLES,
        default=None,
        metavar="K",
        help=f"MO-IRL/MaxEnt: also write K weight samples (20 to 1000, default {DEFAULT_SAMPLES} when given; 0: none, "
        "as reproduce's) from "
        "the weights' posterior given the training trials (the merit's Gauss-Newton model at the fit and a broad "
        "prior: docs/method.md), and each window's cost-share intervals (MODEL.json 'uncertainty'; the fit then "
        "takes 1.2-2.3x a plain fit's CPU time)",
    )
    p.add_argument(
        "--seed",
        type=int_in(0, 2**32 - 1),
        default=None,
        metavar="N",
        help="with --uncertainty: seed of the uncertainty's random samples (default 0)",
    )
    p.add_argument(
        "--config",
        type=Path,
        metavar="RUN.toml",
        help="a run file holding only an [experimental] table of MO-IRL options (docs/usage.md; default: none)",
    )
    add_selection(p, "learn from (several postures or subjects: one shared cost)")
    return p


def _experimental(path: Path | None, n_windows: int, seed_form: bool = False) -> dict | None:
    """The ``[experimental]`` table of ``--config`` (checked where the options are defined, and against the fit's
    ``n_windows``); any other key is refused, naming it (a run file of ``reproduce`` holds the protocol's keys,
    which ``fit`` takes as flags)."""
    if path is None:
        return None
    from ..irl.options import check_windows, resolve_options
    from .runfile import read_run_file

    content = read_run_file(path)
    other = sorted(k for k in content if k != "experimental")
    from .reproduce import COMMAND_LINE_ONLY, OTHER_KEYS, RUN_KEYS

    unknown = [k for k in other if k not in {*RUN_KEYS, *OTHER_KEYS, *COMMAND_LINE_ONLY}]
    if unknown:  # not a protocol key of `reproduce` either: no flag of fit's takes it
        raise InputError(
            f"unknown run-file key(s) {', '.join(unknown)}; fit reads only the [experimental] table of a run file",
            path,
        )
    if other:
        raise InputError(
            f"fit reads only the [experimental] table of a run file, not {', '.join(other)} (give those as "
            f"fit's flags: reachirl fit --help)",
            path,
        )
    table = content.get("experimental", {})
    if not isinstance(table, dict):
        raise InputError("[experimental] must be a table of MO-IRL options", path)
    try:
        check_windows(resolve_options(seed_form, table), n_windows)
    except (TypeError, ValueError) as e:
        raise InputError(f"[experimental]: {e}", path) from None
    return table


def run(args: argparse.Namespace) -> int:
    from ..irl.base import caller_shows_fit_warnings
    from ..irl.methods import METHODS as CLASSES
    from ..irl.methods import make_estimator
    from ..irl.moirl import MOIRL

    console = Console(stderr=True)
    check_output_file(args.out)
    refuse_overwrite({"--out": args.out}, [args.trials, *([args.config] if args.config else [])])
    check_output_kind(args.out, ".json", kind=JSON_KINDS["fit"])
    experimental = _experimental(args.config, args.sections, args.seed_form)
    if args.seed is not None and not args.uncertainty:  # the fit itself makes no random choice
        raise InputError(
            "--seed seeds the weight samples of --uncertainty, which is not given; the fit makes no random choice"
        )
    args.seed = 0 if args.seed is None else args.seed
    trials, chosen = chosen_trials(args, load_trials(args.trials))
    if args.sections > args.nodes:
        raise InputError(f"--sections must be between 1 and --nodes={args.nodes}, got {args.sections}")
    kwargs = {"n_nodes": args.nodes, "backend": args.backend}
    is_moirl = issubclass(CLASSES[args.method], MOIRL)
    if is_moirl:
        kwargs.update(
            rollout=args.rollout or "per_task",  # MOIRL's own default
            seed_form=args.seed_form,
            uncertainty=args.uncertainty,
            random_state=args.seed,
            experimental=experimental,
        )
    elif args.seed_form or args.uncertainty or experimental or args.rollout is not None:
        raise InputError(
            f"--seed-form, --uncertainty, --rollout and --config apply to moirl and maxent, not {args.method}"
        )
    elif args.max_iter is not None and args.method == "kkt":  # one solve: no iterations to limit
        raise InputError("--max-iter applies to moirl, maxent and bilevel, not kkt, which solves once")
    if args.max_iter is not None:  # else the method's own: MO-IRL's 30 per stage, bilevel's DOC-solve budget alone
        kwargs["max_iter"] = args.max_iter

    with console.status(f"fitting {args.method} with {args.sections} section(s) on {len(trials)} trials") as status:

        def progress(rec: dict) -> None:
            status.update(
                f"{args.method}: iteration {rec.get('iteration', '?')}, merit {rec.get('merit', '?')}, "
                f"{rec.get('doc_solves', '?')} DOC solves"
            )

        if is_moirl:  # the baselines take no progress callback
            kwargs["callback"] = progress
        est = make_estimator(args.method, args.sections, **kwargs)
        try:
            with caller_shows_fit_warnings():  # said once, below, from the model's info.warnings
                est.fit(trials)
        except InputError as e:  # the trials do not go together (e.g. cut at two thresholds): name their file
            if e.path is not None:
                raise
            raise InputError(e.reason, args.trials) from None
    model = LearnedModel.from_estimator(est, trials)
    # the trials file as METRICS.json names it: absolute, resolved (a relative path means nothing elsewhere)
    trials_file = str(Path(args.trials).resolve())
    model = replace(model, info={**model.info, "trials": trials_file, "selection": chosen})
    info, unc = model.info, model.uncertainty
    save_model(args.out, model)
    for msg in info["warnings"]:  # one line each, on stderr (the fit logged none of them)
        print(f"warning: {msg}", file=sys.stderr)
    extra = ""
    if unc is not None:
        det = unc["determination"]
        cells = [d for row in unc["share_intervals"]["determined"] for d in row]
        prior = unc.get("prior") or {}

        def alone(key: str, fmt) -> str:  # the same quantity under the prior alone, when recorded
            return "" if prior.get(key) is None else f"; {fmt(prior[key])} under the prior alone"

        width = mean_width(unc["share_intervals"])
        extra = (
            f"; {unc['n_samples']} weight samples, {det['n_determined']} of {det['n_directions']} weight "
            f"directions determined by the trials, {cells.count(False)} of {len(cells)} cost shares undetermined "
            f"(95 % interval wider than {UNDETERMINED_WIDTH} or not containing the fit's own share; mean width "
            f"{'-' if width is None else f'{width:.2f}'}{alone('mean_width', lambda v: f'{v:.2f}')})"
        )
        extra += _claim_words(unc.get("claim") or {}, prior)
        if unc.get("pooling"):
            extra += f"; {_pooling_words(unc['pooling'])}"
    form = ""
    if args.seed_form:  # an [experimental] table may still change the paper's method: then it is not as written
        n_dep = len(info.get("departures") or ())
        form = " (seed form)" if not n_dep else f" (seed form with {n_dep} departure(s) from it: info.departures)"
    print(
        f"wrote {args.out}: {args.method}{form}, {args.sections} section(s), "
        f"{_iterations(info)}, {info['n_doc_solves']} DOC solves ({args.backend})"
        + (f" of which {info['n_doc_failures']} did not converge" if info.get("n_doc_failures") else "")
        + (f", {info['fit_time_s']:.1f} s" if isinstance(info["fit_time_s"], int | float) else "")
        + extra
    )
    return 0


def _claim_words(claim: dict, prior: dict) -> str:
    """The summary's words on the paper's claim: its verdict and fraction of the posterior, beside the prior's
    fraction alone; where the prior alone gives the same verdict, that it is not a finding. Nothing without a claim
    record (a model written before it); its reason where the claim does not apply."""
    if claim.get("fraction") is not None:
        percent = (
            ""
            if prior.get("claim_fraction") is None
            else f"; {100 * prior['claim_fraction']:.0f} % under the prior alone"
        )
        if prior_gives_verdict(claim, prior):  # the verdict is the prior's: said, so it is not quoted as the data's
            percent += ", which gives the same verdict without the data: not a finding"
        return (
            f"; the paper's claim (joint acceleration's share higher at onset and end): {claim['verdict']} "
            f"({100 * claim['fraction']:.0f} % of the posterior{percent})"
        )
    if claim.get("reason"):  # said, not left out: a reader looks for the claim here
        return f"; the paper's claim: {claim['verdict']} ({claim['reason']})"
    return ""


def _pooling_words(pooling: dict) -> str:
    """``uncertainty.pooling`` in words: the pooled mean share-interval width against each task's alone, their
    range given as one number when it rounds to one ("0.82", not "0.82-0.82")."""
    alone = [v["mean_width"] for v in pooling["per_task"].values() if v.get("mean_width") is not None]
    pooled = pooling["pooled"]["mean_width"]
    words = f"pooling {len(pooling['per_task'])} tasks: mean share-interval width "
    words += "-" if pooled is None else f"{pooled:.2f}"
    if not alone:
        return words
    lo, hi = f"{min(alone):.2f}", f"{max(alone):.2f}"
    return words + f" against {lo if lo == hi else f'{lo}-{hi}'} from each task alone"


def _iterations(info: dict) -> str:
    """The fit's iterations in words: a one-shot method's, or each stage's of an observed MO-IRL fit."""
    first, n = info.get("first_stage"), info.get("n_iter")
    if info.get("method") == "kkt":
        return "one-shot (no iterations)"
    if first:
        return f"{first['n_iter']} + {n} iterations (whole-rollout stage + observed stage)"
    return f"{n} iteration{'' if n == 1 else 's'}"
