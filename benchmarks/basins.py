"""The merit on the straight line in log-weights from a fit to the true weights, on a built-in virtual subject.

Evidence for docs/method.md#uncertainty: the true weights' reaches are indistinguishable from the fit's (a one-sided
paired t-test over the demonstrations), yet the merit between the two rises far above either, so the truth lies
in another basin than the fit, where no local posterior sees it. One line per point of the line (``t`` = 0 is the
fit, 1 the truth): the merit, and whether the data can tell it from the fit's. A solve that fails is printed as
such, not as a merit. True weights of 0 are replaced by 1e-6 of the largest (log-weights must be finite).
Run: ``.venv/bin/python benchmarks/basins.py --seed 0 --posture P2``.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from reachirl import MOIRL
from reachirl.experiments import datasets
from reachirl.experiments.analysis import true_weights
from reachirl.experiments.protocol import ProtocolConfig, split_trials
from reachirl.irl.uncertainty import indistinguishable, residuals_and_jacobian, rollout_errors


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="built-in data seed (default 0)")
    parser.add_argument("--posture", default="P2")
    parser.add_argument("--points", type=int, default=11, help="points on the line, ends included (default 11)")
    args = parser.parse_args(argv)
    ds = datasets.load(None, seed=args.seed)
    train = list(split_trials(ds.trials, args.posture, ProtocolConfig()).train)
    est = MOIRL(8).fit(train)
    r, _ = residuals_and_jacobian(est, est._movable(est._w_fit.shape))
    errors_fit = np.sum(r**2, axis=1)
    w_true = true_weights(ds.truth, [t.trial_id for t in train])
    eta_fit, eta_true = np.log(est._w_fit), np.log(np.maximum(w_true, 1e-6 * w_true.max()))
    for t in np.linspace(0.0, 1.0, args.points):
        w = np.exp(eta_fit + t * (eta_true - eta_fit))
        e, _, _ = rollout_errors(est, w)
        row = {"t": round(float(t), 4), "fit_merit": float(errors_fit.mean())}
        if e is not None:
            row |= {"merit": float(e.mean()), "indistinguishable": indistinguishable(e, errors_fit)}
        else:
            row |= {"solve": "failed"}
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
