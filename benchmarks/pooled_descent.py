"""A pooled fit continued on its own merit with the exact weight Jacobian: does a better optimiser of the merit get
closer to the true cost? Evidence for docs/method.md#uncertainty.

On a built-in virtual subject's five postures (one rollout per posture, the default MO-IRL fit), Levenberg-Marquardt
steps in the free log-weights from the Gauss-Newton model of the merit
(:func:`reachirl.irl.uncertainty.residuals_and_jacobian`), each try one DOC solve per rollout, accepted when the
merit falls, steps capped at 1 in log-weights. One JSON line per accepted iteration: the merit, the total variation
between the fit's cost shares (on its own reaches) and the true weights' (on their own reaches, the whole DOC on the
weights' windows), and at the end the true weights' own merit. A try whose solve fails counts as a rejected try.
Run: ``.venv/bin/python benchmarks/pooled_descent.py --seed 0``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from reachirl import MOIRL
from reachirl.experiments import datasets
from reachirl.experiments.analysis import reference_features, true_weights
from reachirl.experiments.protocol import ProtocolConfig, split_trials
from reachirl.features import cost_shares
from reachirl.irl.uncertainty import residuals_and_jacobian, rollout_errors


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="built-in data seed (default 0)")
    parser.add_argument("--iterations", type=int, default=40, help="Levenberg-Marquardt iterations (default 40)")
    args = parser.parse_args(argv)
    ds = datasets.load(None, seed=args.seed)
    train = [t for p in ("P1", "P2", "P3", "P4", "P5") for t in split_trials(ds.trials, p, ProtocolConfig()).train]
    est = MOIRL(8).fit(train)
    w_true = true_weights(ds.truth, [t.trial_id for t in train])
    w_true = np.maximum(w_true, 1e-6 * w_true.max())
    phi_true = reference_features(train, w_true, est.n_nodes, "casadi", True)
    true = cost_shares(w_true, phi_true)

    def fit_shares() -> np.ndarray:
        return cost_shares(est._w_fit, est.reach_features())

    def distance() -> float:
        return float(np.mean(0.5 * np.abs(fit_shares() - true).sum(axis=1)))

    def merit_at(w):
        errors, cand, runs = rollout_errors(est, w)
        return (None if errors is None else float(errors.mean())), cand, runs

    free = est._movable(est._w_fit.shape)
    cols = np.flatnonzero(free.reshape(-1))
    r, J = residuals_and_jacobian(est, free)
    m = float(np.mean(np.sum(r**2, axis=1)))
    print(json.dumps({"iteration": 0, "merit": m, "total_variation": distance()}), flush=True)
    lam, solves, failed, c0 = 1e-2, 0, 0, time.process_time()
    for it in range(1, args.iterations + 1):
        A = np.einsum("dmp,dmq->pq", J, J) / r.shape[0]
        g = np.einsum("dmp,dm->p", J, r) / r.shape[0]
        while lam <= 1e4:
            eta = np.log(est._w_fit).reshape(-1)
            eta[cols] += np.clip(-np.linalg.solve(A + lam * np.eye(cols.size), g), -1.0, 1.0)
            w = np.exp(eta).reshape(est._w_fit.shape)
            m_try, cand, runs = merit_at(w)
            solves += runs
            failed += m_try is None
            if m_try is not None and m_try < m:
                est._w_fit, est.train_solutions_, lam = w, list(cand), max(lam / 3.0, 1e-6)
                break
            lam *= 4.0
        if lam > 1e4:
            break
        r, J = residuals_and_jacobian(est, free)
        m = float(np.mean(np.sum(r**2, axis=1)))
        print(json.dumps({"iteration": it, "merit": m, "total_variation": distance(), "solves": solves}), flush=True)
    m_true, _, _ = merit_at(w_true)
    print(
        json.dumps(
            {
                "true_weights_merit": m_true,
                "cpu_s": time.process_time() - c0,
                "failed_tries": failed,
                "onset_end_joint_acceleration": {
                    "fit": fit_shares()[[0, -1], 3].tolist(),
                    "truth": true[[0, -1], 3].tolist(),
                },
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
