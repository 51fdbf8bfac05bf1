"""``reachirl reproduce``: the seed paper's protocol (train / CV / ISCV × 1/6/8 sections) on the built-in
virtual subjects or on PATH, with the RMSE table, figures and a report under DIR.

Each (posture, sections) unit runs as one task in local processes (``--workers``) or on a Dask cluster
(``--scheduler tcp://HOST:PORT``) and is checkpointed under DIR/units/; rerunning into the same DIR skips the
finished units. ``--quick`` runs the same code path on fewer trials and postures (P2 and P4), smaller DOCs and
fewer iterations.

``--iscv all-pairs`` learns from every subject in turn and predicts every other one (iscv_pairs.csv and its
heatmaps; --n-iscv then counts trials per test subject). ``--subjects N`` makes N built-in virtual subjects
(20 × 5 postures × 20 trials is Berret 2011's design).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from ..errors import InputError
from ..validation import MAX_ITER, NODES_RANGE
from ._args import int_in, non_negative_int, number_in, positive_int, refuse_overwrite

QUICK = {"n_train": 3, "n_cv": 3, "n_iscv": 3, "nodes": 40, "max_iter": 5}
FULL = {"n_train": 10, "n_cv": None, "n_iscv": None, "nodes": 100, "max_iter": 30}


def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "reproduce",
        help="run the seed paper's protocol and write its table and figures",
        description=__doc__.replace("``", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--data",
        metavar="PATH",
        help="trials file (.npz from `reachirl preprocess`) or a folder with manifest.csv "
        "[+ subjects.csv]; default: the built-in virtual subjects",
    )
    p.add_argument(
        "--sections",
        type=int_in(1, NODES_RANGE[1]),
        nargs="+",
        default=[1, 6, 8],
        metavar="N",
        help="numbers of weight sections, each 1 to --nodes (default: 1 6 8)",
    )
    p.add_argument("--out", default="results", metavar="DIR", help="output folder (default: results)")
    p.add_argument(
        "--workers",
        type=int_in(1, 256),
        default=None,
        metavar="N",
        help="local worker processes, 1 to 256 (default: all cores; 1 runs in this process)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the units on this Dask scheduler (tcp://HOST:PORT) (default: local processes)",
    )
    p.add_argument(
        "--seed", type=non_negative_int, default=0, metavar="N", help="seed of the random training trials (default 0)"
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="fewer trials (3/3/3) and postures (P2, P4), 40 knots, 5 iterations",
    )
    p.add_argument(
        "--subjects",
        type=int_in(2, 100),
        metavar="N",
        help="make N built-in virtual subjects, 2 to 100 (default 2; 20 is Berret 2011's design); not with --data",
    )
    p.add_argument(
        "--iscv",
        choices=("one", "all-pairs"),
        default="one",
        help="one: learn from the training subject only (the seed); all-pairs: learn from every subject in turn "
        "and predict every other one, writing iscv_pairs.csv and its heatmaps (default one)",
    )
    g = p.add_argument_group("protocol options")
    g.add_argument("--postures", nargs="+", metavar="NAME", help="postures to run (default: all in the data)")
    g.add_argument(
        "--method",
        nargs="+",
        default=["moirl"],
        metavar="NAME",
        help="moirl (default) and/or baselines (maxent, bilevel, kkt); the first one is the main table",
    )
    g.add_argument(
        "--backend",
        choices=("casadi", "crocoddyl"),
        default="casadi",
        help="DOC backend of every fit and prediction (default: casadi)",
    )
    g.add_argument(
        "--acceptance",
        choices=("merit", "either", "multimodal"),
        default=None,
        help="MO-IRL step acceptance: merit (the seed, default), either, or multimodal (state and torque merits)",
    )
    g.add_argument(
        "--rollout",
        choices=("mean", "per_demo"),
        default="mean",
        help="MO-IRL's training rollouts: one DOC from the demonstrations' mean start, target and duration (mean, "
        "the seed, default) or one per demonstration, each compared with its own (per_demo: about five times the "
        "fit time; see the README for what it changes)",
    )
    g.add_argument(
        "--observe",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="predict each reach as it was recorded: the rest-to-rest DOC seen between its own crossings of the "
        "trials' onset threshold, MO-IRL's rollouts too (trials not cut at a threshold are predicted whole; "
        "default); --no-observe: the DOC over the trial's own duration, as the seed",
    )
    g.add_argument(
        "--merit",
        choices=("state", "normalised"),
        default="normalised",
        help="MO-IRL's merit: each channel of (q, q̇) divided by the demonstrations' spread (normalised, default) "
        "or the seed's full-state error (state)",
    )
    g.add_argument(
        "--fallback",
        choices=("merit", "none"),
        default=None,
        help="MO-IRL/MaxEnt when the likelihood's step lowers no merit: step on a model of the merit (merit, "
        "default) or stop (none: the seed's rule)",
    )
    g.add_argument(
        "--merit-model",
        choices=("probes", "gauss-newton"),
        default=None,
        help="MO-IRL/MaxEnt's model of the merit for those steps: 14 probe solves per rollout (probes, default) or "
        "Gauss-Newton from the DOC's sensitivities (gauss-newton, no solve; also tried when the likelihood's step "
        "gains less than 1 %%)",
    )
    g.add_argument("--train-subject", metavar="ID", help="subject to learn from (default: the first one)")
    g.add_argument("--train-side", choices=("right", "left"), help="learn from this arm's reaches only "
                   "(default: either arm; with --cv other-side, right)")
    g.add_argument(
        "--cv",
        choices=("rest", "other-side"),
        default="rest",
        help="cross-validate on the subject's other trials (rest; the seed) or on its other arm "
        "(other-side; UE-ADL: learn right, validate on the mirrored left) (default rest)",
    )
    g.add_argument(
        "--n-train", type=non_negative_int, metavar="N", help="training trials per posture (default 10; 0: all)"
    )
    g.add_argument("--n-cv", type=non_negative_int, metavar="N", help="CV trials per posture (default: all; 0: all)")
    g.add_argument(
        "--n-iscv", type=non_negative_int, metavar="N", help="ISCV trials per posture (default: all; 0: all)"
    )
    g.add_argument("--nodes", type=int_in(*NODES_RANGE), metavar="N",
                   help=f"DOC knots, {NODES_RANGE[0]} to {NODES_RANGE[1]} (default 100, as the DOC; --quick 40)")
    g.add_argument("--max-iter", type=int_in(1, MAX_ITER), metavar="N",
                   help=f"MO-IRL iterations at most, 1 to {MAX_ITER} (default 30)")
    g.add_argument("--tol", type=number_in(0.0, 0.5), metavar="X",
                   help="MO-IRL: a step must lower the merit by more than this fraction, 0 to 0.5 (default 1e-4)")
    g.add_argument(
        "--data-seed", type=non_negative_int, default=0, metavar="N", help="seed of the built-in data set (default 0)"
    )
    g.add_argument(
        "--markers", metavar="MAP",
        help="shoulder=A,elbow=B,wrist=C,fingertip=D for a marker folder (default: truth.json's markers, else "
        "the built-in marker sets)"
    )
    g.add_argument(
        "--max-units",
        type=positive_int,
        metavar="N",
        help="stop after N new units (resume later into the same --out) (default: no limit)",
    )
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def _config(args):
    from ..experiments.protocol import ProtocolConfig

    base = QUICK if args.quick else FULL

    def pick(name, arg):
        v = getattr(args, arg)
        if v is None:
            return base[name]
        return None if v == 0 else v

    postures = args.postures
    return ProtocolConfig(
        sections=tuple(args.sections),
        postures=tuple(postures) if postures else None,
        methods=tuple(args.method),
        seed=args.seed,
        train_subject=args.train_subject,
        train_side=args.train_side,
        n_train=pick("n_train", "n_train"),
        cv=args.cv,
        n_cv=pick("n_cv", "n_cv"),
        n_iscv=pick("n_iscv", "n_iscv"),
        n_nodes=args.nodes or base["nodes"],
        max_iter=args.max_iter or base["max_iter"],
        **({} if args.tol is None else {"tol": args.tol}),
        backend=args.backend,
        iscv=args.iscv,
        estimator_options=_estimator_options(args),
        observe=args.observe,
        merit=args.merit,
        rollout=args.rollout,
    )


def _estimator_options(args) -> dict:
    """MO-IRL options set on the command line (only those given, so the default units keep their keys)."""
    opts = {}
    if args.acceptance:
        opts["acceptance"] = args.acceptance
    if args.fallback:
        opts["fallback"] = None if args.fallback == "none" else args.fallback
    if args.merit_model:
        opts["merit_model"] = args.merit_model
    return opts


def _quick_postures(config, dataset):
    """--quick without --postures: P2 and P4 (the seed's Fig. 4) when present, else the first two."""
    from dataclasses import replace

    if config.postures is not None:
        return config
    have = dataset.postures
    chosen = [p for p in ("P2", "P4") if p in have] or have[:2]
    return replace(config, postures=tuple(chosen))


def _print_table(console, outputs, config, postures) -> None:
    from rich.table import Table

    from ..experiments import tables as tb

    for m, table in outputs["tables"].items():
        t = Table(title=f"{m} ({config.backend} DOC): RMSE of the joint angles (deg), mean ± SD", show_lines=False)
        t.add_column("posture")
        t.add_column("joint")
        for s in tb.SETS:
            for n in config.sections:
                t.add_column(f"{tb.SET_LABELS[s]} ({outputs['n_trials'][s]})\n{n} sec.", justify="center")
        rows = tb.table_rows(table, postures, config.sections)
        for i, row in enumerate(rows):
            p, j = row[0], row[1]
            t.add_row(
                p if j == "q1" else "",
                f"[bold]{j}[/]" if j == "q" else j,
                *[c.replace(" ± ", "±") for c in row[2:]],
                end_section=(j == "q" and i < len(rows) - 1),
            )
        console.print(t)


SCHEDULER_PROTOCOLS = ("tcp", "tls", "inproc", "ws", "wss", "ucx")


def _check_scheduler(address: str | None) -> None:
    """A Dask address ``PROTOCOL://HOST:PORT`` (or ``HOST:PORT``) with a protocol Dask knows."""
    if not address:
        return
    import re

    m = re.fullmatch(r"(?:([a-z]+)://)?([^\s/:]+|\[[0-9a-fA-F:]+\]):(\d{1,5})/?", address)
    if not m or (m.group(1) and m.group(1) not in SCHEDULER_PROTOCOLS) or not 0 < int(m.group(3)) < 65536:
        raise InputError(
            f"--scheduler {address[:60]!r}: expected an address like tcp://HOST:PORT "
            f"(protocols: {', '.join(SCHEDULER_PROTOCOLS)})"
        )


def run(args) -> int:
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from ..experiments import datasets
    from ..experiments.report import write_outputs
    from ..experiments.runner import reproduce

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from ..validation import check_output_dir

    out = check_output_dir(args.out)
    refuse_overwrite({"--out": out}, [args.data])
    _check_scheduler(args.scheduler)
    config = _config(args)
    too_many = [n for n in config.sections if n > config.n_nodes]
    if too_many:
        raise InputError(f"--sections {too_many[0]}: more sections than the DOC's {config.n_nodes} intervals (--nodes)")
    from ..irl.methods import METHODS

    unknown = [m for m in config.methods if m not in METHODS]
    if unknown:
        raise InputError(f"--method {unknown[0]!r}: expected one of {', '.join(METHODS)}")
    workers = args.workers or (os.cpu_count() or 1)
    err = Console(stderr=True)
    out_console = Console() if Console().is_terminal else Console(width=200)  # logs: no wrapping

    t0 = time.perf_counter()
    if args.data is None:
        err.print("[dim]loading the built-in virtual subjects (generated and cached on first use)…[/]")
    dataset = datasets.load(args.data, seed=args.data_seed, marker_map=args.markers, n_subjects=args.subjects)
    if args.quick:
        config = _quick_postures(config, dataset)
    data_s = time.perf_counter() - t0

    progress = Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("units"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        console=err,
        disable=args.no_progress or not err.is_terminal,
        transient=False,
    )
    state = {"done": 0, "total": 0}
    log_lines = not args.no_progress and not err.is_terminal  # e.g. a log file: one line per unit

    def on_start(total, reused):
        state["task"] = progress.add_task("reproduce", total=total)
        state["total"] = total
        if reused:
            err.print(f"[dim]{reused} unit(s) already done in {out / 'units'}; reusing them[/]")

    def on_done(key, res, reused):
        progress.update(state["task"], advance=1, description=f"{key}{' (reused)' if reused else ''}")
        state["done"] += 1
        if log_lines:
            how = (
                "reused"
                if reused
                else f"fit {res['fit']['time_s']:.1f} s, evaluation {res['evaluation']['time_s']:.1f} s"
            )
            print(f"[{state['done']}/{state['total']}] {key} ({how})", file=sys.stderr, flush=True)

    with progress:
        result = reproduce(
            dataset,
            config,
            out,
            workers=workers,
            scheduler=args.scheduler,
            max_units=args.max_units,
            data_s=data_s,
            on_start=on_start,
            on_done=on_done,
        )
    if result.stopped:
        print(
            f"stopped after {len(result.summary.computed)} new unit(s) (--max-units); rerun with the same --out "
            f"to finish",
            file=sys.stderr,
        )
        return 0
    outputs = write_outputs(result)
    _print_table(out_console, outputs, config, result.postures)
    for n in outputs["notes"]:
        out_console.print(f"[dim]- {n}[/]", highlight=False)
    tm = outputs["timing"]
    out_console.print(
        f"time: data {tm['data_s']:.1f} s, units {tm['units_wall_s']:.1f} s (fits {tm['fit_s_sum']:.1f} s + "
        f"evaluation {tm['evaluation_s_sum']:.1f} s over the workers), figures/report {tm['report_s']:.1f} s",
        highlight=False,
    )
    out_console.print(
        f"wrote {out / 'table.md'}, table.csv, results.json, report.md, "
        f"{len(outputs['figures'])} figure(s) in {out / 'figures'} and the predictions in {out / 'predictions'}"
        + (f"; all-pairs ISCV in {out / 'iscv_pairs.csv'}" if config.iscv == "all-pairs" else ""),
        highlight=False,
    )
    return 0
