"""The merit fallback: when the likelihood's step lowers no merit (the demonstrations are dominated by every
rollout on every feature), MO-IRL probes the merit and steps on a per-feature quadratic model of it."""

import numpy as np
import pytest

from moirl_settings import moirl_params, whole_rollout_moirl
from reachirl import ReachingTask, solve_doc
from reachirl.data.trial import trial_from_solution
from reachirl.irl import moirl as moirl_module
from reachirl.irl.moirl import MOIRL as _MOIRL
from reachirl.irl.objective import merit_model_step
from reachirl.virtual import knot_trials

MOIRL = whole_rollout_moirl(_MOIRL)  # the iteration on whole rollouts, full-state merit

N_NODES = 40


def test_the_model_step_is_the_minimiser_of_a_quadratic_merit():
    rng = np.random.default_rng(3)
    a = rng.uniform(0.5, 2.0, 7)  # curvatures
    c = rng.uniform(-0.3, 0.3, 7)  # minimisers, inside the bound

    def m(eta):
        return 1.0 + np.sum(a * (eta - c) ** 2)

    h = 0.5
    plus = [m(np.eye(7)[j] * h) for j in range(7)]
    minus = [m(-np.eye(7)[j] * h) for j in range(7)]
    np.testing.assert_allclose(merit_model_step(m(np.zeros(7)), plus, minus, h), c, rtol=1e-12, atol=1e-14)


def test_the_model_step_is_bounded_goes_downhill_where_concave_and_skips_failed_probes():
    m = 1.0
    plus = np.array([0.5, 1.5, 0.9, np.inf, 2.0, 0.99, 1.0])
    minus = np.array([1.5, 0.5, 0.9, 0.8, 2.0, 0.999, np.nan])
    eta = merit_model_step(m, plus, minus, 0.2)
    assert eta[0] == pytest.approx(0.2)  # a straight slope (no curvature) down towards +: the bound
    assert eta[1] == pytest.approx(-0.2)
    assert eta[2] == pytest.approx(0.0)  # both probes better: symmetric concave model, no slope, no move
    assert eta[3] == 0.0 and eta[6] == 0.0  # a failed probe leaves its feature alone
    assert eta[4] == pytest.approx(0.0)  # a convex bowl centred on ω
    assert 0 < eta[5] <= 0.2  # a shallow slope down towards +
    assert np.all(np.abs(eta) <= 0.2)


@pytest.fixture(scope="module")
def dominated_demos():
    """Noise-free reaches under time-varying (8-window) true weights: one window cannot explain them, and the
    rollout at ω₀ costs less than every demonstration on every feature."""
    return knot_trials(4, "P2", seed=1, n_nodes=N_NODES)


def test_one_window_on_time_varying_reaches_learns_through_the_merit_fallback(dominated_demos):
    seed_rule = MOIRL(1, n_nodes=N_NODES, experimental={"fallback": None}).fit(dominated_demos)
    assert seed_rule.flag_ == "w0" and seed_rule.stop_reason_ == "step_only_rescales"

    est = MOIRL(1, n_nodes=N_NODES).fit(dominated_demos)
    assert est.flag_ != "w0"
    assert est.merit_ < 0.9 * est.initial_merit_
    merit_steps = [h for h in est.history_[1:] if h["step"] == "merit" and h["accepted"]]
    assert merit_steps, "the likelihood cannot move these weights: the progress must come from merit steps"


def test_the_fallback_probes_each_feature_both_ways_and_counts_its_solves(arm, monkeypatch):
    w = np.array([[0.1, 0.2, 0.2, 0.01, 1e-5, 0.02, 0.05]])
    task = ReachingTask(arm, np.deg2rad([-90.0, 90.0]), 0.9 * arm.length, 0.7, n_nodes=N_NODES)
    sol = solve_doc(task, w)
    demos = [trial_from_solution(sol, arm, task.target_x, trial_id=str(i)) for i in range(2)]
    # a likelihood with nothing to say: every step a pure rescale
    monkeypatch.setattr(moirl_module, "solve_step", lambda w, *a, **k: (-0.5 * w, {"nit": 1}))
    probes = []
    real = _MOIRL._rollouts

    def spy(self, tasks, weights, warm, guesses):
        probes.append(np.asarray(weights).copy())
        return real(self, tasks, weights, warm, guesses)

    monkeypatch.setattr(_MOIRL, "_rollouts", spy)
    est = MOIRL(1, n_nodes=N_NODES, max_iter=1, experimental={"w0": 0.05, "merit_model": "probes"}).fit(demos)
    w_start = np.asarray(est.history_[0]["weights"])
    ratios = np.array([p / w_start for p in probes[1:15]])[:, 0]  # after the initial rollout: 14 probes
    # each probe moves one feature's weight, and each feature is probed by ρ and by 1/ρ
    changed = np.array([np.flatnonzero(~np.isclose(r, 1.0)) for r in ratios], dtype=object)
    assert sorted(int(c[0]) for c in changed) == sorted(list(range(7)) * 2)
    assert all(len(c) == 1 for c in changed)
    for j in range(7):
        f = sorted(r[j] for r in ratios if not np.isclose(r[j], 1.0))
        assert f[0] == pytest.approx(1 / f[1], rel=1e-12) and f[1] > 1
    h = est.history_[1]
    assert h["step"] == "merit"
    assert h["doc_solves"] - est.history_[0]["doc_solves"] >= 14 + h["tries"]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fallback": "gradient"}, "fallback must be 'merit' or None"),
        ({"fallback_tol": 1.0}, r"fallback_tol must be in \[0, 1\)"),
    ],
)
def test_bad_fallback_options_are_refused(dominated_demos, kwargs, match):
    with pytest.raises(ValueError, match=match):
        MOIRL(1, n_nodes=N_NODES, **moirl_params(kwargs)).fit(dominated_demos)


def test_the_model_step_refuses_a_point_without_a_merit():
    with pytest.raises(ValueError, match="needs a finite merit at ω and h > 0"):
        merit_model_step(np.inf, np.ones(7), np.ones(7), 0.1)
    with pytest.raises(ValueError, match="needs a finite merit at ω and h > 0"):
        merit_model_step(1.0, np.ones(7), np.ones(7), 0.0)


def test_the_fallback_keeps_held_weights_where_they_are(dominated_demos, monkeypatch):
    """Occlusion refits hold a removed feature and a frozen window: the merit fallback must not move them."""
    monkeypatch.setattr(_MOIRL, "_step", lambda self, w, *a, **k: (-0.5 * w, {"nit": 1}))  # always a rescale
    mask = np.ones((2, 7), dtype=bool)
    mask[:, 4] = False
    est = MOIRL(2, n_nodes=N_NODES, max_iter=3, feature_mask=mask, experimental={"frozen_windows": (0,)})
    est.fit(dominated_demos)
    w0 = np.asarray(est.history_[0]["weights"])
    moved = [np.asarray(h["weights"]) for h in est.history_[1:] if h["accepted"]]
    assert moved, "the fallback must have made a step for this test to mean anything"
    for w in moved:
        np.testing.assert_array_equal(w[0], w0[0])  # the frozen window
        np.testing.assert_array_equal(w[:, 4], w0[:, 4])  # the removed feature (held, 0 in every rollout)
    assert np.all(est.weights_[:, 4] == 0.0)
    assert not np.allclose(moved[-1][1], w0[1])


def test_fit_command_takes_the_fallback_switch(dominated_demos, tmp_path):
    import json

    from reachirl.cli import main
    from reachirl.data.trial import save_trials

    path = tmp_path / "trials.npz"
    save_trials(path, dominated_demos)
    flags = {}
    for choice in ("merit", "none"):
        model = tmp_path / f"{choice}.json"
        run = tmp_path / f"{choice}.toml"
        # the seed's rule: fallback = None, written "" (TOML has no null)
        run.write_text(
            '[experimental]\nobserve = false\nmerit = "state"\n' + ("" if choice == "merit" else 'fallback = ""\n')
        )
        assert (
            main(
                [
                    "fit",
                    str(path),
                    "--sections",
                    "1",
                    "--nodes",
                    str(N_NODES),
                    "--config",
                    str(run),
                    "--out",
                    str(model),
                ]
            )
            == 0
        )
        info = json.loads(model.read_text())["info"]
        flags[choice] = (info["flag"], {h.get("step") for h in info["history"][1:]})
    assert flags["none"][0] == "w0" and flags["none"][1] == {"likelihood"}
    assert flags["merit"][0] != "w0" and "merit" in flags["merit"][1]


def test_reproduce_refuses_an_unknown_fallback(capsys):
    from reachirl.cli import main

    assert main(["reproduce", "--set", 'experimental={fallback = "gradient"}', "--out", "x"]) == 2
    assert "fallback must be 'merit' or None, got 'gradient'" in capsys.readouterr().err
