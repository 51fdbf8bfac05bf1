"""The weights that fits really produce, and the reaches they are used on: the sweep behind ``reachirl bench
backends``.

``python benchmarks/learned_weights.py [--quick]`` fits MO-IRL, MaxEnt and bilevel at 1/6/8 windows on each
posture of the built-in virtual subjects (training split of :func:`reachirl.experiments.protocol.split_trials`)
and on the UE-ADL sample, and writes ``benchmarks/learned_weights.json``: per fit, the weights and every trial
of the split (training, CV, ISCV) as a DOC task (arm, q0, target, duration). Fits run on the CasADi backend
(the sweep is about what the backends do with these weights, not about the fits themselves). Fit budgets are
kept modest (``--max-iter`` for MO-IRL and MaxEnt, ``--max-evals`` for bilevel; KKT solves once and takes
neither): the weights of a shorter fit are the same kind of numbers.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "learned_weights.json"
UE_ADL = HERE.parent / "src" / "reachirl" / "data" / "ue_adl_sample"


def _task_dict(trial) -> dict:
    return {
        "id": trial.id,
        "arm": asdict(trial.arm),
        "q0": np.asarray(trial.x0[:2], dtype=float).tolist(),
        "target_x": float(trial.target_x),
        "duration": float(trial.duration),
    }


def load(path: Path = OUT) -> list[dict]:
    """The stored fits: ``[{"source", "method", "posture", "sections", "weights", "trials": [task dicts]}]``."""
    return json.loads(Path(path).read_text(encoding="utf-8"))["fits"]


def to_task(d: dict, n_nodes: int = 100):
    from reachirl import ArmModel, ReachingTask

    return ReachingTask(ArmModel(**d["arm"]), np.array(d["q0"]), d["target_x"], d["duration"], n_nodes)


def fit_budget(method: str, max_iter: int, max_evals: int) -> dict:
    """The hyperparameters of a ``method`` fit here: 100 knots, and the budget the method takes: ``max_evals``
    (DOC solves) for bilevel, ``max_iter`` (iterations per stage) for MO-IRL and the estimators built on it
    (:func:`reachirl.irl.methods.builds_on_moirl`), none for KKT, which solves once."""
    from reachirl.irl.methods import builds_on_moirl

    kw: dict = {"n_nodes": 100}
    if method == "bilevel":
        kw["max_evals"] = max_evals
    elif builds_on_moirl(method):
        kw["max_iter"] = max_iter
    return kw


def main(argv=None) -> None:
    from reachirl.experiments import datasets
    from reachirl.experiments.protocol import ProtocolConfig, split_trials
    from reachirl.irl.methods import make_estimator

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sections", type=int, nargs="+", default=[1, 6, 8])
    ap.add_argument("--methods", nargs="+", default=["moirl", "maxent", "bilevel"])
    ap.add_argument("--max-iter", type=int, default=10)
    ap.add_argument("--max-evals", type=int, default=120)
    ap.add_argument("--postures", nargs="+", default=None)
    ap.add_argument("--sources", nargs="+", default=["builtin", "ue_adl"])
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)

    fits = json.loads(args.out.read_text())["fits"] if args.out.exists() else []
    done = {(f["source"], f["method"], f["posture"], f["sections"]) for f in fits}
    config = ProtocolConfig()
    for source in args.sources:
        ds = datasets.load(None if source == "builtin" else UE_ADL)
        trials = list(ds.trials)
        postures = sorted({t.posture for t in trials})
        if args.postures:
            postures = [p for p in postures if p in args.postures]
        for posture in postures:
            cfg = config if source == "builtin" else ProtocolConfig(n_train=None)
            split = split_trials(trials, posture, cfg)
            for method in args.methods:
                for s in args.sections:
                    if (source, method, posture, s) in done:
                        continue
                    est = make_estimator(method, s, **fit_budget(method, args.max_iter, args.max_evals))
                    t0 = time.perf_counter()
                    est.fit(list(split.train))
                    fits.append(
                        {
                            "source": source,
                            "method": method,
                            "posture": posture,
                            "sections": s,
                            "fit_time_s": time.perf_counter() - t0,
                            "weights": np.asarray(est.weights_).tolist(),
                            "trials": {k: [_task_dict(t) for t in v] for k, v in split.sets().items()},
                        }
                    )
                    tmp = args.out.with_suffix(".tmp")
                    tmp.write_text(json.dumps({"fits": fits}), encoding="utf-8")
                    tmp.replace(args.out)
                    print(f"{source} {method} {posture} s{s}: {time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main()
