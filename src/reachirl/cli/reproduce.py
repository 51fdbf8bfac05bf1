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
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from ..io import holding_folder
from ..irl.options import ROLLOUTS
from ..validation import MAX_ITER, NODES_RANGE
from . import SUMMARIES, at_forced_exit
from ._args import int_in, non_negative_int, number_below, refuse_overwrite, samples_or_none

MAX_SUBJECTS = 100

QUICK = {"n_train": 3, "n_cv": 3, "n_iscv": 3, "nodes": 40, "max_iter": 5}
FULL = {"n_train": 10, "n_cv": None, "n_iscv": None, "nodes": 100, "max_iter": 30}

RUN_KEYS = {
    # key: (what it is, check) -- the keys of a run file (--config RUN.toml, --set KEY=VALUE) beside the flags;
    # each is also a flag, --key-name, whose help is this text (progress: --no-progress, with its own)
    "postures": (
        "postures to run (default: every posture of the data; --quick: P2 and P4, else the first two)",
        "names",
    ),
    "methods": ("moirl (default) and/or baselines maxent, bilevel, kkt; the first is the main table", "names"),
    "train_subject": ("subject to learn from (default: the first one)", "str"),
    "train_side": ("learn from this arm's reaches only: right or left (default: either)", "str"),
    "cv": ("rest (the subject's other trials; default) or other-side (its other arm, mirrored)", "str"),
    "n_train": ("training trials per posture, 0 to 1000000 (default 10; --quick 3; 0: all)", "count"),
    "n_cv": ("CV trials per posture, 0 to 1000000 (default: all; --quick 3; 0: all)", "count"),
    "n_iscv": ("ISCV trials per posture, 0 to 1000000 (default: all; --quick 3; 0: all)", "count"),
    "nodes": (f"DOC knots, {NODES_RANGE[0]} to {NODES_RANGE[1]} (default 100; --quick 40)", "nodes"),
    "max_iter": (
        f"MO-IRL/MaxEnt iterations at most, per stage, 1 to {MAX_ITER} (default 30; --quick 5); not bilevel's or kkt's",
        "iters",
    ),
    "tol": ("MO-IRL acceptance threshold, from 0 to below 0.5 (default 1e-4; 0 with --seed-form)", "tol"),
    "rollout": ("MO-IRL rollouts: per_task (default), per_demo or mean", "str"),
    "data_seed": ("seed of the built-in data set, 0 to 1000000 (default 0); not with --data", "count"),
    "markers": (
        "shoulder=A,elbow=B,wrist=C,fingertip=D of a --data folder (default: its truth.json's, else the built-in sets)",
        "str",
    ),
    "max_units": (
        "stop after N new units, 0 to 1000000; rerun into the same --out to resume (default: no limit; 0: no limit)",
        "count",
    ),
    "progress": ("show a progress bar, true or false (default true)", "bool"),
}
"""Run-file keys; an ``[experimental]`` table holds MO-IRL's :class:`reachirl.irl.options.Options` fields."""


def add_parser(subparsers) -> argparse.ArgumentParser:
    keys_text = textwrap.fill(
        "Run-file keys are set in a --config RUN.toml file, by --set KEY=VALUE (repeatable) or by flags, each over "
        "the ones before: "
        + ", ".join((*(k for k in FLAG_KEYS if k != "uncertainty"), "quick"))
        + " and data by the options of those names, the keys of the group 'run-file keys' below by its flags "
        "(key_name as --key-name; methods as --method; progress = false as --no-progress). A run file may also set "
        "workers and scheduler (the flags win), not out. An [experimental] table holds MO-IRL options "
        "(docs/usage.md).",
        width=110,
        break_on_hyphens=False,
    )
    p = subparsers.add_parser(
        "reproduce",
        help=SUMMARIES["reproduce"],
        description=__doc__.replace("``", "") + "\n" + keys_text,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--data",
        metavar="PATH",
        help="trials file (.npz from `reachirl preprocess`) or a folder with manifest.csv [+ subjects.csv]; "
        "default: the built-in virtual subjects",
    )
    p.add_argument(
        "--sections",
        type=int_in(1, NODES_RANGE[1]),
        nargs="+",
        default=None,
        metavar="N",
        help="numbers of weight sections, each 1 to the DOC's knots (default: 1 6 8)",
    )
    p.add_argument("--out", default="results", metavar="DIR", help="output folder (default: results)")
    p.add_argument(
        "--workers",
        type=int_in(1, 256),
        default=None,
        metavar="N",
        help="local worker processes for the units and the figures, 1 to 256 (default: all cores; 1 runs in this "
        "process)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the units on this Dask scheduler (tcp://HOST:PORT) (default: local processes)",
    )
    p.add_argument(
        "--seed",
        type=non_negative_int,
        default=None,
        metavar="N",
        help="seed of the random training trials and of the uncertainty's samples (default 0)",
    )
    p.add_argument(
        "--quick", action="store_true", help="fewer trials (3/3/3) and postures (P2, P4), 40 knots, 5 iterations"
    )
    p.add_argument(
        "--subjects",
        type=int_in(2, MAX_SUBJECTS),
        metavar="N",
        help=f"make N built-in virtual subjects, 2 to {MAX_SUBJECTS} (default 2; 20 is Berret 2011's "
        "design); not with --data",
    )
    p.add_argument(
        "--iscv",
        choices=("one", "all-pairs"),
        default=None,
        help="one: learn from the training subject only (the seed; default); all-pairs: learn from every "
        "subject in turn and predict every other one (iscv_pairs.csv and its heatmaps)",
    )
    p.add_argument(
        "--backend",
        choices=("casadi", "crocoddyl"),
        default=None,
        help="DOC backend of every fit and prediction (default: casadi)",
    )
    p.add_argument(
        "--seed-form",
        action="store_true",
        default=None,
        help="MO-IRL as the seed paper wrote it (docs/method.md lists what the default adds)",
    )
    p.add_argument(
        "--posture-transfer",
        action="store_true",
        default=None,
        help="also learn one cost on every posture but one and predict the held-out one (posture_transfer.csv)",
    )
    p.add_argument(
        "--config",
        type=Path,
        metavar="RUN.toml",
        help="a run file (every run writes its own as DIR/run.toml); flags given override it (default: none)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        dest="assignments",
        help='a run-file key, the value read as TOML (n_train=0, postures=["P2"]); repeatable (default: none)',
    )
    keys = p.add_argument_group("run-file keys, also accepted as flags")
    for key, (what, kind) in RUN_KEYS.items():
        name = "method" if key == "methods" else key.replace("_", "-")
        if kind == "bool":  # progress: the flag turns it off
            keys.add_argument(
                "--no-progress",
                dest=f"key_{key}",
                action="store_false",
                default=None,
                help="no progress bar, nor its line per unit in a log (progress = false; default: shown)",
            )
        elif kind == "names":
            keys.add_argument(f"--{name}", dest=f"key_{key}", nargs="+", default=None, metavar="NAME", help=what)
        else:
            keys.add_argument(
                f"--{name}",
                dest=f"key_{key}",
                type=KEY_TYPES[kind],
                choices=KEY_CHOICES.get(key),
                default=None,
                metavar=KEY_METAVARS[key],
                help=what,
            )
    keys.add_argument(
        "--uncertainty",
        type=samples_or_none(20, 1000),
        default=None,
        metavar="K",
        help="weight samples per main-table MO-IRL/MaxEnt fit, 20-1000, 0: none (default 40); "
        "refused for bilevel/kkt only",
    )
    return p


KEY_METAVARS = {
    "train_subject": "ID",
    "train_side": "SIDE",
    "cv": "SET",
    "n_train": "N",
    "n_cv": "N",
    "n_iscv": "N",
    "nodes": "N",
    "max_iter": "N",
    "tol": "X",
    "rollout": "KIND",
    "data_seed": "N",
    "markers": "MAP",
    "max_units": "N",
}
"""The value's name in the flag of each run-file key that takes one."""

KEY_CHOICES = {
    "train_side": ("right", "left"),
    "cv": ("rest", "other-side"),
    "rollout": ROLLOUTS,
}
"""The values of the keys that take a name from a list: a flag outside it is refused as it is read, naming the
flag (the protocol's own check, which a run file's value meets, names the key)."""

KEY_TYPES = {
    "str": str,
    "count": int_in(0, 10**6),
    "nodes": int_in(*NODES_RANGE),
    "iters": int_in(1, MAX_ITER),
    "tol": number_below(0.0, 0.5),
}


FLAG_KEYS = ("sections", "seed", "subjects", "iscv", "backend", "seed_form", "posture_transfer", "uncertainty")
# what a run file or --set may give for the keys that are also flags (the flags' own types check them there)
OTHER_KEYS = {
    "sections": ("a list of section counts, each 1 or more", "sections"),
    "seed": ("a seed, 0 or more", "count"),
    "subjects": (f"a number of built-in virtual subjects, 2 to {MAX_SUBJECTS}", "subjects"),
    "iscv": ('"one" or "all-pairs"', "str"),
    "backend": ('"casadi" or "crocoddyl"', "str"),
    "seed_form": ("true or false", "bool"),
    "posture_transfer": ("true or false", "bool"),
    "uncertainty": ("weight samples, 20 to 1000, or 0 for none", "uncertainty"),
    "quick": ("true or false", "bool"),
    "data": ("a path", "str"),
    "scheduler": ("a Dask scheduler address", "str"),
    "workers": ("a number of worker processes, 1 to 256", "workers"),
}
# options of how a run is carried out, not of its results: on the command line only
COMMAND_LINE_ONLY = {"out": "--out DIR"}


def run_options(args) -> tuple[dict, set[str]]:
    """The run's options: the run file, then ``--set``, then the flags given; every key checked (exit 2 naming the
    key or the file). ``experimental`` is a table. Also returns the keys whose value is the run file's."""
    from .runfile import parse_assignment, read_run_file, written

    opts: dict = {}
    where = None
    if args.config is not None:
        opts.update(read_run_file(args.config))
        where = args.config
    from_file = set(opts)
    for text in args.assignments:
        try:
            key, value = parse_assignment(text)
        except ValueError as e:
            raise InputError(f"--set: {e}") from None
        opts[key] = value
        from_file.discard(key)
        where = where or "--set"
    for key in FLAG_KEYS:
        v = getattr(args, key)
        if v is not None:
            opts[key] = list(v) if isinstance(v, list) else v
            from_file.discard(key)
    for key in RUN_KEYS:
        v = getattr(args, f"key_{key}", None)
        if v is not None:
            opts[key] = list(v) if isinstance(v, list) else v
            from_file.discard(key)
    for key, flag in COMMAND_LINE_ONLY.items():
        if key in opts:
            raise InputError(f"{key}: not a run-file key; give {flag} on the command line", where)
    known = {*RUN_KEYS, *OTHER_KEYS, "experimental"}
    unknown = sorted(set(opts) - known)
    if unknown:
        raise InputError(f"unknown run option(s) {', '.join(unknown)}; valid: {', '.join(sorted(known))}", where)
    for key in ("postures", "methods"):
        v = opts.get(key)
        if isinstance(v, str):
            opts[key] = [x for x in v.split(",") if x]
        if opts.get(key) is not None and not (
            isinstance(opts[key], list) and all(isinstance(x, str) and x for x in opts[key])
        ):
            raise InputError(f"{key}: expected a list of names, got {written(opts[key])}", where)
    if isinstance(opts.get("sections"), int):
        opts["sections"] = [opts["sections"]]
    exp = opts.get("experimental", {})
    if not isinstance(exp, dict):
        raise InputError("experimental: expected a table of MO-IRL options", where)
    for key, (_, kind) in RUN_KEYS.items():
        if key in opts and not _valid(kind, opts[key]):
            raise InputError(f"{key}: {RUN_KEYS[key][0]}; got {written(opts[key])}", where)
    for key, (what, kind) in OTHER_KEYS.items():  # e.g. seed_form = "no" once read as true
        if key in opts and opts[key] is not None and not _valid(kind, opts[key]):
            raise InputError(f"{key}: expected {what}; got {written(opts[key])}", where)
    return opts, from_file


def _valid(kind: str, v) -> bool:
    num = isinstance(v, int) and not isinstance(v, bool)
    return {
        "names": isinstance(v, list) and len(v) > 0,
        "str": isinstance(v, str),
        "count": num and 0 <= v <= 10**6,
        "nodes": num and NODES_RANGE[0] <= v <= NODES_RANGE[1],
        "iters": num and 1 <= v <= MAX_ITER,
        "tol": isinstance(v, int | float) and not isinstance(v, bool) and 0 <= v < 0.5,
        "bool": isinstance(v, bool),
        "sections": isinstance(v, list)
        and len(v) > 0
        and all(isinstance(x, int) and not isinstance(x, bool) and x >= 1 for x in v),
        "subjects": num and 2 <= v <= MAX_SUBJECTS,
        "uncertainty": num and (v == 0 or 20 <= v <= 1000),
        "workers": num and 1 <= v <= 256,
    }[kind]


def _naming_run_file(err: InputError, run_file, from_file: set[str]) -> InputError:
    """``err`` (a value refused by the protocol's checks, which name the key but not where it came from) naming
    ``run_file`` when the key is one of ``from_file``, those whose value is the run file's (:func:`run_options`)."""
    if err.path is not None or run_file is None:
        return err
    said = {"unknown method": "methods", "train side": "train_side", "--sections": "sections", "--iscv": "iscv"}
    msg = err.reason
    keys = [k for k in from_file if msg.startswith((k, k.replace("_", " ")))]
    keys += [k for text, k in said.items() if msg.startswith(text) and k in from_file]
    return InputError(msg, run_file) if keys else err


def _nodes(args, opts: dict) -> int:
    """The DOC's number of intervals the run asks for (``--nodes``, else the protocol's)."""
    return opts.get("nodes") or (QUICK if args.quick else FULL)["nodes"]


def _config(args, opts: dict):
    from ..experiments.protocol import ProtocolConfig

    base = QUICK if args.quick else FULL

    def pick(name):
        v = opts.get(name)
        if v is None:
            return base[name]
        return None if v == 0 else v

    return ProtocolConfig(
        sections=tuple(opts.get("sections") or (1, 6, 8)),
        postures=tuple(opts["postures"]) if opts.get("postures") else None,
        methods=tuple(opts.get("methods") or ("moirl",)),
        seed=int(opts.get("seed", 0)),
        train_subject=opts.get("train_subject"),
        train_side=opts.get("train_side"),
        n_train=pick("n_train"),
        cv=opts.get("cv", "rest"),
        n_cv=pick("n_cv"),
        n_iscv=pick("n_iscv"),
        n_nodes=_nodes(args, opts),
        max_iter=opts.get("max_iter") or base["max_iter"],
        tol=opts.get("tol"),
        backend=opts.get("backend", "casadi"),
        iscv=opts.get("iscv", "one"),
        seed_form=bool(opts.get("seed_form", False)),
        rollout=opts.get("rollout", "per_task"),
        experimental=dict(opts.get("experimental", {})),
        uncertainty=int(opts.get("uncertainty", 40)),
        posture_transfer=bool(opts.get("posture_transfer", False)),
    )


def _quick_postures(config, dataset):
    """--quick without --postures: P2 and P4 (the seed's Fig. 4) when present, else the first two."""
    from dataclasses import replace

    if config.postures is not None:
        return config
    have = dataset.postures
    chosen = [p for p in ("P2", "P4") if p in have] or have[:2]
    return replace(config, postures=tuple(chosen))


def _timing_line(tm: dict) -> str:
    """The run's time, as printed at its end: the weight samples' part of the fits named, with how to skip it."""
    samples = tm.get("uncertainty_s_sum", 0.0)
    of_it = f", of which weight samples {samples:.1f} s" if samples > 0 else ""
    line = (
        f"time: data {tm['data_s']:.1f} s, units {tm['units_wall_s']:.1f} s (summed over the workers: fits "
        f"{tm['fit_s_sum']:.1f} s{of_it}; evaluation {tm['evaluation_s_sum']:.1f} s), figures/report "
        f"{tm['report_s']:.1f} s"
    )
    return line + "; --uncertainty 0 draws no weight samples" if samples > 0 else line


def _print_table(console, outputs, config, postures) -> None:
    from rich.table import Table

    from ..experiments import tables as tb
    from ..experiments.names import sections_text

    for m, table in outputs["tables"].items():
        t = Table(title=f"{m} ({config.backend} DOC): RMSE of the joint angles (deg), mean ± SD", show_lines=False)
        t.add_column("posture")
        t.add_column("joint")
        for s in tb.SETS:
            for n in config.sections:
                t.add_column(f"{tb.SET_LABELS[s]} ({outputs['n_trials'][s]})\n{sections_text(n)}", justify="center")
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


#: the transports a scheduler of another process is reached by (Dask's inproc:// is within one process: not one)
SCHEDULER_PROTOCOLS = ("tcp", "tls", "ws", "wss", "ucx")


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


RUN_FILE_HEADER = "reproduce: the options of this run"
"""What the first line of a run's own ``run.toml`` says after ``# reachirl VERSION``."""


#: the run-file keys of MO-IRL and the methods built on it (MaxEnt), each with what it is: a run of bilevel and KKT
#: alone takes none (refused when asked, as fit refuses them; left out of its run.toml)
_MOIRL_KEYS = {
    "max_iter": "moirl's and maxent's iterations at most; bilevel stops at its budget of DOC solves, kkt solves once",
    "uncertainty": "weight samples are drawn for moirl and maxent fits only",
    "seed_form": "the paper's MO-IRL form",
    "rollout": "MO-IRL's and MaxEnt's training rollouts",
    "tol": "MO-IRL's and MaxEnt's stopping tolerance",
    "experimental": "the table of MO-IRL's options",
}


def _run_file(out, args, opts: dict, config) -> Callable[[], None]:
    """What writes ``DIR/run.toml``: every option the run uses (a run of bilevel and KKT alone: none of
    :data:`_MOIRL_KEYS`), so that ``reproduce --config DIR/run.toml`` repeats it (called once the units are ready to
    run, so that a stopped or interrupted run has it too).

    When ``--config`` is that very file (resuming a run with its own options), it is left as it is; with other
    options (flags that override it) it would be replaced, so the run is refused here, before any work."""
    import tomllib

    from .. import __version__
    from ..irl.methods import builds_on_moirl
    from ._args import same_file
    from .runfile import dumps, read_run_file, write_run_file

    resolved = {
        "data": None if args.data is None else str(Path(args.data).resolve()),
        "quick": bool(args.quick),
        "sections": list(config.sections),
        "postures": None if config.postures is None else list(config.postures),
        "methods": list(config.methods),
        "seed": config.seed,
        "data_seed": int(opts.get("data_seed", 0)),
        "subjects": opts.get("subjects"),
        "markers": opts.get("markers"),
        "train_subject": config.train_subject,
        "train_side": config.train_side,
        "cv": config.cv,
        "n_train": config.n_train or 0,
        "n_cv": config.n_cv or 0,
        "n_iscv": config.n_iscv or 0,
        "nodes": config.n_nodes,
        "max_iter": config.max_iter,
        "tol": config.tol,
        "backend": config.backend,
        "iscv": config.iscv,
        "seed_form": config.seed_form,
        "rollout": config.rollout,
        "posture_transfer": config.posture_transfer,
        "uncertainty": config.uncertainty,
        "experimental": dict(config.experimental),
    }
    unused = {} if any(builds_on_moirl(m) for m in config.methods) else _MOIRL_KEYS
    resolved = {k: v for k, v in resolved.items() if k not in unused}  # options no method of the run takes
    if args.config is not None and same_file(Path(args.config), out / "run.toml"):
        own = {k: v for k, v in read_run_file(args.config).items() if k not in unused}  # an earlier version's too
        if own == tomllib.loads(dumps(resolved)):
            return lambda: None  # the run's own options: nothing to write
        raise InputError(
            "--config is this run folder's own run.toml, and the options given change it; the run would replace "
            "it (copy it elsewhere first, or choose another --out)",
            args.config,
        )
    from ..irl.moirl import DEFAULT_TOL

    left_out = {  # an option at its default is left out of the TOML (no None there); the comment says what it is
        "data": "the built-in virtual subjects",
        "postures": "every posture of the data",
        "subjects": "2 built-in virtual subjects",
        "train_subject": "the first subject",
        "train_side": "either arm",
        "tol": f"{0.0 if config.seed_form else DEFAULT_TOL:g}, MO-IRL's own",
    }
    if resolved["data"] is not None:
        del left_out["subjects"]  # the data's own subjects
    if "tol" not in resolved:
        del left_out["tol"]
    defaults = [f"{k}: {v}" for k, v in left_out.items() if resolved.get(k) is None]
    if "experimental" in resolved:  # about thirty options: named by the class, not here
        set_here = "every one" if not resolved["experimental"] else "every one not in its table"
        defaults.append(f"[experimental]: {set_here} at the method's default (reachirl.irl.options.Options)")
    header = (
        f"reachirl {__version__} {RUN_FILE_HEADER}; repeat it with "
        f"`reachirl reproduce --config {out / 'run.toml'} --out DIR`"
        + ("\nleft at their defaults: " + "; ".join(defaults) if defaults else "")
    )
    return lambda: write_run_file(out / "run.toml", resolved, header=header)


def _is_run_toml(path: Path) -> bool:
    """Whether ``path`` is a run file a ``reproduce`` run wrote into its folder (by its first line)."""
    try:
        with open(path, encoding="utf-8") as fh:
            first = fh.readline(1000)
    except (OSError, UnicodeDecodeError):
        return False
    words = first.split(" ", 3)  # "#", "reachirl", the version, the rest
    return len(words) == 4 and words[:2] == ["#", "reachirl"] and words[3].startswith(RUN_FILE_HEADER)


def _is_run_results(path: Path) -> bool:
    """Whether ``path`` is a ``results.json`` a ``reproduce`` run wrote (by its format): a run folder of a version
    that wrote no run.toml, or whose run.toml lost its first line to an edit."""
    from ..errors import InputError
    from ..experiments.report import RESULTS_FORMAT
    from ..io import read_json

    try:
        d = read_json(path) if path.is_file() else None
    except InputError:
        return False
    return isinstance(d, dict) and d.get("format") == RESULTS_FORMAT


#: the folders a run writes into (and clears of an earlier run's files)
RUN_OUTPUT_FOLDERS = ("figures", "models", "predictions", "units")


def _refuse_out_in_another_run(out: Path) -> None:
    """Before any work: ``out`` is not inside one of the folders (:data:`RUN_OUTPUT_FOLDERS`) of an earlier run
    above it (a run nested in another's ``units/`` mixes with the checkpoints that run reads back)."""
    from ._args import refuse_out_in_run_folders

    o = out.resolve()
    for run in o.parents:
        if _is_run_toml(run / "run.toml") or _is_run_results(run / "results.json"):
            refuse_out_in_run_folders(out, run, RUN_OUTPUT_FOLDERS, "this run", "runs")
            return


def _refuse_foreign_run_files(out: Path, config: str | None) -> None:
    """Before any work: the files a run replaces or removes at the top of ``out`` (``run.toml`` and
    :data:`~reachirl.experiments.report.RUN_OUTPUT_FILES`) and in its folders (:data:`RUN_OUTPUT_FOLDERS`) are an
    earlier run's, never the user's own: in a folder without a run's ``run.toml`` or ``results.json`` (a folder of
    the user's own, given as --out) such a file is refused (:class:`InputError` naming it), and so is a
    ``run.toml`` that no run wrote, unless it is the --config given."""
    from ..experiments.report import RUN_OUTPUT_FILES
    from ._args import same_file

    if not out.is_dir():
        return
    toml = out / "run.toml"
    if _is_run_toml(toml) or _is_run_results(out / "results.json"):
        return
    given = config is not None and toml.exists() and same_file(Path(config), toml)
    present = [n for n in ("run.toml", *RUN_OUTPUT_FILES) if (out / n).exists() and not (n == "run.toml" and given)]
    for sub in RUN_OUTPUT_FOLDERS:  # a file of the user's own in one of them is replaced or removed alike
        if (out / sub).is_dir():
            present += [str(p.relative_to(out)) for p in sorted((out / sub).rglob("*")) if not p.is_dir()][:1]
    if present:
        raise InputError(
            "--out: exists in a folder that holds no earlier `reachirl reproduce` run (no run.toml or results.json "
            "written by one); the run would replace or remove it (choose another --out, or remove it first)",
            out / present[0],
        )


def _refuse_unused(args, opts: dict, from_file: set[str], key: str, what: str, methods) -> None:
    """Refuse the option ``key`` (``what`` it is, and why the other methods have none) when it was asked for and no
    method of the run (``methods``) takes it: :class:`InputError` naming the flag, ``--set`` or the run file it came
    from. Not given, 0 (none; for ``tol``, 0 is asked), an empty table, or only recorded in a run's own
    ``run.toml`` (which records every option, defaults too: resuming the run is no ask) is no ask."""
    value = opts.get(key)
    asked = value is not None if key == "tol" else bool(value)
    if not asked or (key in from_file and _is_run_toml(Path(args.config))):
        return
    why = f"--method {' '.join(methods)} takes none ({what})"
    from .runfile import written

    if key in from_file:  # in the file's own words: true, "per_demo", [experimental] merit, observe
        said = f"[experimental] {', '.join(value)}" if isinstance(value, dict) else f"{key} = {written(value)}"
        raise InputError(f"{said}: {why}", args.config)
    flag = getattr(args, key) if key in FLAG_KEYS else getattr(args, f"key_{key}", None)
    if flag is None:  # given by --set, as it was written there (a word without its quotes)
        raise InputError(f"{key}={value if isinstance(value, str) else written(value)}: {why}", "--set")
    shown = "" if value is True else f" {value}"  # a switch: --seed-form, not --seed-form True
    raise InputError(f"--{key.replace('_', '-')}{shown}: {why}")


def _stopped(result, written: set[str]) -> int:
    """A run stopped by --max-units: the finished units' models (`evaluate`, `plot`, `simulate` can use them
    now; those ``written`` as they finished are there already) and how to finish."""
    from ..experiments.cost import write_models

    write_models(result, written)
    print(
        f"stopped after {len(result.summary.computed)} new unit(s) (--max-units); rerun with the same --out to finish",
        file=sys.stderr,
    )
    return 0


def run(args) -> int:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from ..validation import check_output_dir

    out = check_output_dir(args.out)
    refuse_overwrite({"--out": out}, [args.data])
    opts, from_file = run_options(args)
    args.workers = args.workers or opts.get("workers")  # how the run is carried out: the flag, else the run file
    from_flag = args.scheduler is not None
    args.scheduler = args.scheduler or opts.get("scheduler")
    try:
        _check_scheduler(args.scheduler)
    except InputError as e:  # a run file's (or --set's) address: named as its key, where it came from
        if from_flag:
            raise
        where = args.config if "scheduler" in from_file else "--set"
        raise InputError(e.reason.replace("--scheduler ", "scheduler: ", 1), where) from None
    args.quick = bool(args.quick or opts.get("quick", False))
    if args.data is None and opts.get("data") is not None:
        args.data = str(opts["data"])
    refuse_overwrite({"--out": out}, [args.data, args.config])
    _refuse_out_in_another_run(out)
    from ..experiments.runner import UnitWorkers, clean_stale_temporaries

    args.workers = args.workers or (os.cpu_count() or 1)
    # ended on leaving, unless the units took them over
    with UnitWorkers(args.workers if args.scheduler is None else 1, _nodes(args, opts)) as unit_workers:
        unit_workers.start()  # on the core this process leaves idle while it imports and loads the data
        _refuse_foreign_run_files(out, args.config)

        def clean() -> None:  # the temporaries of atomic writes an interrupt came in the middle of
            if out.is_dir():
                clean_stale_temporaries(out)

        at_forced_exit(clean)  # a run ended outright, stuck in compiled code after a signal, never reaches the except
        with holding_folder(out, "--out"):  # before any work; a folder made by the run is held once made (the runner)
            try:
                return _run(args, out, opts, from_file, unit_workers)
            except KeyboardInterrupt:  # Ctrl-C or SIGTERM, every worker ended: nothing half written is left behind
                clean()
                raise


def _run(args, out: Path, opts: dict, from_file: set[str], unit_workers) -> int:
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
    from ..experiments.rendering import FigureWorkers
    from ..experiments.report import UnitOutputs, remove_previous_outputs, write_outputs
    from ..experiments.runner import reproduce

    try:
        config = _config(args, opts)
    except InputError as e:
        raise _naming_run_file(e, args.config, from_file) from None
    too_many = [n for n in config.sections if n > config.n_nodes]
    if too_many:
        raise InputError(f"--sections {too_many[0]}: more sections than the DOC's {config.n_nodes} intervals (--nodes)")
    from ..irl.methods import METHODS, builds_on_moirl

    unknown = [m for m in config.methods if m not in METHODS]
    if unknown:
        raise InputError(f"--method {unknown[0]!r}: expected one of {', '.join(METHODS)}")
    if not any(builds_on_moirl(m) for m in config.methods):  # as fit refuses them with --method bilevel or kkt
        for key, what in _MOIRL_KEYS.items():  # a default (not in opts) asks nothing
            _refuse_unused(args, opts, from_file, key, what, config.methods)
    workers = args.workers
    err = Console(stderr=True)
    out_console = Console() if Console().is_terminal else Console(width=200)  # logs: no wrapping

    t0 = time.perf_counter()
    if args.data is None and err.is_terminal:  # a note for a person watching; an error stays one line in a log
        err.print("[dim]loading the built-in virtual subjects (generated and cached on first use)…[/]")
    dataset = datasets.load(
        args.data, seed=int(opts.get("data_seed", 0)), marker_map=opts.get("markers"), n_subjects=opts.get("subjects")
    )
    if args.quick:
        config = _quick_postures(config, dataset)
    data_s = time.perf_counter() - t0
    write_run_toml = _run_file(out, args, opts, config)

    progress = Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("units"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        console=err,
        disable=not opts.get("progress", True) or not err.is_terminal,
        transient=False,
    )
    state = {"done": 0, "total": 0}
    log_lines = opts.get("progress", True) and not err.is_terminal  # e.g. a log file: one line per unit

    def on_start(total, reused):
        # an earlier run's results go before this run's run.toml and first unit: an interrupted rerun never leaves
        # them looking finished beside options they were not run with (its checkpoints stay, to be reused)
        remove_previous_outputs(out)
        write_run_toml()
        state["task"] = progress.add_task("reproduce", total=total)
        state["total"] = total
        if reused:
            err.print(f"[dim]{reused} unit(s) already done in {out / 'units'}; reusing them[/]")

    unit_outputs = UnitOutputs(out)

    def on_done(key, res, reused):
        if not reused:  # its model and predictions now, while the other units run (a reused unit's: at the end)
            unit_outputs(key, res)
        progress.update(state["task"], advance=1, description=f"{key}{' (reused)' if reused else ''}")
        state["done"] += 1
        if state["total"] - state["done"] < workers:  # a core is idle until the run ends: start the figures' workers
            ahead.start()
        if log_lines:
            how = (
                "reused"
                if reused
                else f"fit {res['fit']['time_s']:.1f} s, evaluation {res['evaluation']['time_s']:.1f} s"
            )
            print(f"[{state['done']}/{state['total']}] {key} ({how})", file=sys.stderr, flush=True)

    with FigureWorkers(workers) as ahead:  # ended on leaving: an error, Ctrl-C or a --max-units stop
        with progress:
            result = reproduce(
                dataset,
                config,
                out,
                workers=workers,
                scheduler=args.scheduler,
                max_units=opts.get("max_units") or None,
                data_s=data_s,
                on_start=on_start,
                on_done=on_done,
                out_option="--out",
                ahead=unit_workers,
            )
        if result.stopped:
            return _stopped(result, unit_outputs.written)
        outputs = write_outputs(result, workers=workers, ahead=ahead, units=unit_outputs)
    _print_table(out_console, outputs, config, result.postures)
    for n in outputs["notes"]:
        out_console.print(f"[dim]- {n}[/]", highlight=False)
    out_console.print(_timing_line(outputs["timing"]), highlight=False)
    # each written only when the data allows it (an earlier run's is removed first); asked for and not written:
    # said here as report.md says it, not left for the reader to find missing
    extras = []
    for asked, name, what, needs in (
        (config.iscv == "all-pairs", "iscv_pairs.csv", "all-pairs ISCV", "two subjects"),
        (config.posture_transfer, "posture_transfer.csv", "posture transfer", "two postures"),
    ):
        if (out / name).is_file():
            extras.append(f"; {what} in {out / name}")
        elif asked:
            extras.append(f"; no {what} ({name} not written): it needs at least {needs} (report.md)")
    out_console.print(
        f"wrote {out / 'table.md'}, table.csv, results.json, report.md, run.toml, "
        f"{len(outputs['figures'])} figure(s) in {out / 'figures'}, the models in {out / 'models'} and the "
        f"predictions in {out / 'predictions'}" + "".join(extras),
        highlight=False,
    )
    # the fits' warnings (report.md's notes), said last and only here: a unit's fit logs none of them (a reused
    # unit's, or a Dask worker's, would never reach this terminal as a log line), so each is said once
    # the main table's units, then the all-pairs and posture-transfer ones (report.md's notes name them too)
    every = [*result.results.values(), *result.pairs.values(), *result.transfer.values()]
    for r in sorted(every, key=lambda r: r["key"]):
        for w in r.get("warnings") or []:
            print(f"warning: {r['key']}: {w}", file=sys.stderr)
    return 0
