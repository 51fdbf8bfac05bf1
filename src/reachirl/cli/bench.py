"""``reachirl bench [SUITE ...] [--out BENCH.json] [--quick]``: performance benchmarks.

Suites live in the source checkout's ``benchmarks/`` folder (``bench_<suite>.py`` with ``run(...) -> dict``):
``doc`` (CasADi DOC against a plain formulation), ``predict`` (predictions by exact Newton against fatrop
from the same start), ``checks`` (the uncertainty's checked samples by the interior point on the knots against
fatrop from the same start), ``backends`` (CasADi against Crocoddyl/CSQP) and ``irl``
(MO-IRL against the baselines on virtual subjects). Every timing is reported beside a baseline measured in the
same run, since shared machines are noisy.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path

from ..errors import InputError
from ..io import atomic_write_json
from . import SUMMARIES
from ._args import file_path

SUITES = ("doc", "predict", "checks", "backends", "irl")


def _bench_dir() -> Path:
    return Path(__file__).resolve().parents[3] / "benchmarks"


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "bench",
        help=SUMMARIES["bench"],
        description=__doc__.replace("``", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "suites", nargs="*", metavar="SUITE", help=f"which suites to run: {', '.join(SUITES)} (default: all)"
    )
    p.add_argument(
        "--out", type=file_path, default=None, help="write all figures to this JSON file (default: print only)"
    )
    p.add_argument("--quick", action="store_true", help="fewer repeats (for a smoke test)")
    return p


def _load(suite: str):
    path = _bench_dir() / f"bench_{suite}.py"
    if not path.exists():
        raise InputError(f"benchmark suite {suite!r} not found; `reachirl bench` runs from a source checkout", path)
    spec = importlib.util.spec_from_file_location(f"reachirl_bench_{suite}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(args: argparse.Namespace) -> int:
    suites = args.suites or list(SUITES)
    unknown = sorted(set(suites) - set(SUITES))
    if unknown:
        raise InputError(f"unknown benchmark suite(s) {unknown}; choose from {list(SUITES)}")
    if args.out is not None:
        from ..validation import check_output_file, check_output_kind

        def bench_json(d: object) -> bool:  # an earlier BENCH.json: one object per suite run
            return isinstance(d, dict) and bool(d) and set(d) <= set(SUITES)

        check_output_file(args.out)
        check_output_kind(args.out, ".json", kind=("BENCH.json", bench_json))
        if "irl" in suites:  # its report folder beside --out, checked before any suite runs
            from ..validation import check_output_dir

            check_output_dir(args.out.parent / "bench_irl", "the irl suite's report folder (beside --out)")
    modules = {suite: _load(suite) for suite in suites}  # a suite missing is said before the others run
    results = {}
    for suite, module in modules.items():
        t0 = time.perf_counter()
        print(f"== {suite} ==", flush=True)
        quick = {
            "doc": {"n_repeats": 6, "sweep": False},
            "predict": {"postures": ("P2", "P4"), "stride": 4},
            "checks": {"postures": ("P2",), "n_check": 4},
            "backends": {"n_repeats": 1, "learned_stride": 20},
            "irl": {"quick": True},
        }
        kwargs = dict(quick[suite]) if args.quick else {}
        if suite == "irl" and args.out is not None:
            kwargs["out_dir"] = args.out.parent / "bench_irl"
        res = module.run(**kwargs)
        res["wall_time_s"] = time.perf_counter() - t0
        results[suite] = res
        print(json.dumps(res, indent=2, default=str), flush=True)
    if args.out is not None:
        atomic_write_json(args.out, results)
        print(f"wrote {args.out}")
    return 0
