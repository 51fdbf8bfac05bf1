"""MO-IRL's multimodal step acceptance (``acceptance="multimodal"``): state and torque merits together."""

import itertools

import numpy as np
import pytest

from moirl_settings import whole_rollout_moirl
from reachirl import MOIRL as _MOIRL
from reachirl import solve_doc
from reachirl.experiments import datasets
from reachirl.irl.moirl import mean_task, multimodal_accept

MOIRL = whole_rollout_moirl(_MOIRL)  # the iteration on whole rollouts, full-state merit


def test_rule():
    assert multimodal_accept(1.0, 1.05, 1.0, 0.8)  # state 5 % worse, torque 20 % better: mean change −7.5 %
    assert not multimodal_accept(1.0, 1.2, 1.0, 0.9)  # +20 %, −10 %: worse on average
    assert not multimodal_accept(1.0, 0.99, 1.0, 1.0, tol=0.01)  # −0.5 % on average is below tol
    assert not multimodal_accept(1.0, np.inf, 1.0, 0.1) and not multimodal_accept(0.0, 0.0, 1.0, 0.5)


def test_fit_accepts_more_steps_than_state_only():
    ds = datasets.toy(n_subjects=1, postures=("P2",), n_trials=3, n_nodes=20, seed=7)
    kw = dict(n_nodes=20, max_iter=4, tol=1e-4)
    state = MOIRL(2, **kw, experimental={"acceptance": "merit"}).fit(ds.trials)
    multi = MOIRL(2, **kw, experimental={"acceptance": "multimodal"}).fit(ds.trials)
    assert multi.weights_.shape == (2, 7) and np.all(multi.weights_ > 0)
    acc = lambda est: sum(h["accepted"] for h in est.history_[1:])  # noqa: E731
    assert acc(multi) >= acc(state)
    # an accepted step either lowered the state merit or passed the multimodal rule: the torque merits of the
    # rollouts before and after the step, re-solved here (the fit's one task: one subject, one posture)
    task = mean_task(ds.trials, 20)
    tau_demos = np.stack([t.knots(20)[2] for t in ds.trials])

    def torque_merit(weights):
        sol = solve_doc(task, np.asarray(weights))
        assert sol.converged
        return float(np.mean(np.sum((tau_demos - sol.tau) ** 2, axis=(1, 2)) / tau_demos.shape[1]))

    def steps(est):  # each accepted step, with the last accepted point before it
        accepted = [h for h in est.history_ if h["accepted"]]
        return list(itertools.pairwise(accepted))

    by_rule = [(prev, h) for prev, h in steps(multi) if h["merit"] >= prev["merit"] * (1 - 1e-4)]
    assert by_rule  # the state merit rose on this data (measured: 2 of 4 steps); state acceptance takes none
    for prev, h in by_rule:
        t_prev, t_new = torque_merit(prev["weights"]), torque_merit(h["weights"])
        assert t_new < t_prev and 0.5 * (h["merit"] / prev["merit"] + t_new / t_prev) < 1 - 1e-4
    assert all(h["merit"] < prev["merit"] for prev, h in steps(state))
    with pytest.raises(ValueError, match="'merit', 'either' or 'multimodal'"):
        MOIRL(2, **kw, experimental={"acceptance": "torque"}).fit(ds.trials)
