"""One model, one set of defaults: the estimator, ``reachirl fit`` and ``reachirl reproduce`` learn the same weights
from the same trials; ``--seed-form`` is the paper's step; what reproduce writes is what the other commands read.
Every test runs on recorded trials (markers with noise, cut at a fingertip-speed threshold: the ``recorded``
fixture)."""

import json
import re
import tomllib

import numpy as np
import pytest
from scipy.optimize import minimize

from reachirl import MOIRL, ReachingTask, solve_doc
from reachirl.cli import main
from reachirl.data.trial import load_trials, select_trials, trial_from_solution
from reachirl.features import windowed_features
from reachirl.irl.moirl import mean_task

FAST = {"n_nodes": 40, "max_iter": 3}
FAST_ARGS = ["--nodes", "40", "--max-iter", "3"]


@pytest.fixture(scope="module")
def p2(recorded):
    """Subject S01's P2 reaches, as recorded (cut at a speed threshold)."""
    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])
    assert all(t.onset_threshold is not None for t in trials)
    return trials


def test_the_estimator_and_the_fit_command_learn_the_same_model(recorded, p2, tmp_path):
    est = MOIRL(2, **FAST).fit(p2)
    out = tmp_path / "model.json"
    assert (
        main(
            [
                "fit",
                str(recorded / "trials.npz"),
                "--sections",
                "2",
                *FAST_ARGS,
                "--subject",
                "S01",
                "--posture",
                "P2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    model = json.loads(out.read_text())
    np.testing.assert_array_equal(np.array(model["weights"]), est.weights_)
    assert model["info"]["observe"] is True and model["info"]["options"]["merit"] == "normalised"
    assert model["info"]["parameters"]["rollout"] == "per_task" and model["info"]["departures"]
    assert model["info"]["versions"]["reachirl"] and len(model["info"]["trials_fingerprint"]) == 16


def test_a_model_with_the_default_weight_samples_records_them_alike_from_python_and_the_cli(recorded, p2, tmp_path):
    """MOIRL(uncertainty=True) recorded `uncertainty: true` in MODEL.json's parameters where `fit --uncertainty`
    recorded 40, for the same weights and the same 40 samples."""
    from reachirl.irl.model import LearnedModel, save_model

    est = MOIRL(2, uncertainty=True, **FAST).fit(p2)
    save_model(tmp_path / "py.json", LearnedModel.from_estimator(est))
    args = ["fit", str(recorded / "trials.npz"), "--sections", "2", *FAST_ARGS, "--subject", "S01", "--posture", "P2"]
    assert main([*args, "--uncertainty", "--out", str(tmp_path / "cli.json")]) == 0
    py, cli = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("py", "cli"))
    assert py["info"]["parameters"]["uncertainty"] == cli["info"]["parameters"]["uncertainty"] == 40
    assert py["weights"] == cli["weights"] and py["uncertainty"]["n_samples"] == cli["uncertainty"]["n_samples"] == 40


def test_reproduce_writes_each_units_model_as_fit_would_and_the_other_commands_read_it(recorded, tmp_path, capsys):
    run = tmp_path / "run"
    assert (
        main(
            [
                "reproduce",
                "--data",
                str(recorded / "trials.npz"),
                "--out",
                str(run),
                "--sections",
                "2",
                "--postures",
                "P2",
                *FAST_ARGS,
                "--n-train",
                "3",
                "--workers",
                "1",
                "--no-progress",
                "--uncertainty",
                "0",
            ]
        )
        == 0
    )
    res = json.loads((run / "results.json").read_text())
    (unit,) = res["units"]
    model_path = run / "models" / f"{unit['key']}.json"
    model = json.loads(model_path.read_text())
    np.testing.assert_array_equal(model["weights"], unit["weights"])
    # recorded trials are cut at a threshold: the fit's iteration 0 is where its whole-rollout stage, from ω₀, ended
    first = model["info"]["first_stage"]
    assert first["n_iter"] == len(first["history"]) - 1
    assert first["history"][0]["iteration"] == 0 and first["history"][0]["merit"] == first["initial_merit"]
    np.testing.assert_allclose(model["info"]["history"][0]["weights"], first["weights"])
    # the same weights from `fit` on the unit's training trials
    train = [t["id"] for t in unit["sets"]["train"]["trials"]]
    trials = [t for t in load_trials(recorded / "trials.npz") if t.id in train]
    np.testing.assert_array_equal(MOIRL(2, **FAST).fit(trials).weights_, np.array(unit["weights"]))
    # evaluate on the model reproduces the unit's own ISCV RMSE, trial by trial
    metrics = tmp_path / "m.json"
    assert (
        main(
            [
                "evaluate",
                "--model",
                str(model_path),
                str(recorded / "trials.npz"),
                "--posture",
                "P2",
                "--subject",
                "S02",
                "--out",
                str(metrics),
            ]
        )
        == 0
    )
    got = {t["id"]: t["rmse_deg"]["q"] for t in json.loads(metrics.read_text())["trials"]}
    want = {t["id"]: t["rmse_deg"]["q"] for t in unit["sets"]["iscv"]["trials"]}
    assert got.keys() == want.keys()
    assert all(got[k] == pytest.approx(want[k], abs=1e-9) for k in got)
    assert (
        main(
            [
                "simulate",
                "--model",
                str(model_path),
                str(recorded / "trials.npz"),
                "--trial",
                "0",
                "--out",
                str(tmp_path / "sim.json"),
            ]
        )
        == 0
    )
    # run.toml repeats the run: the same table, byte for byte
    # the trials are cut at a speed threshold: the report says where the weights' windows lie on them
    edges = json.loads(model_path.read_text())["info"]["window_edges"]
    assert len(edges) == 3 and edges[0] < 0 < 1 < edges[-1]
    assert "Windows: the weights act on equal windows of the rest-to-rest DOC" in (run / "report.md").read_text()
    run_file = tomllib.loads((run / "run.toml").read_text())
    assert run_file["sections"] == [2] and run_file["rollout"] == "per_task" and run_file["uncertainty"] == 0
    # an option at its default is not in the TOML, and its comment says what it is
    assert "tol" not in run_file and "tol: 0.0001, MO-IRL's own" in (run / "run.toml").read_text()
    assert (
        run_file["experimental"] == {}
        and "[experimental]: every one at the method's default" in (run / "run.toml").read_text()
    )
    again = tmp_path / "again"
    assert main(["reproduce", "--config", str(run / "run.toml"), "--out", str(again), "--workers", "1"]) == 0
    assert (again / "table.csv").read_bytes() == (run / "table.csv").read_bytes()
    # a run resumed from its own run.toml leaves it as it is; options that change it would replace the input: refused
    text = (run / "run.toml").read_bytes()
    own = ["reproduce", "--config", str(run / "run.toml"), "--out", str(run), "--workers", "1", "--no-progress"]
    assert main(own) == 0 and (run / "run.toml").read_bytes() == text
    capsys.readouterr()
    assert main([*own, "--max-iter", "1"]) == 2
    err = capsys.readouterr().err.strip()
    own_file = r"run\.toml: --config is this run folder's own run\.toml, and the options given change it"
    assert re.fullmatch(rf"reachirl reproduce: error: .*{own_file}.*", err), err
    assert (run / "run.toml").read_bytes() == text


def test_a_run_file_with_an_unknown_key_is_refused_naming_it(tmp_path, capsys):
    bad = tmp_path / "run.toml"
    bad.write_text("n_trian = 3\n")
    assert main(["reproduce", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "run.toml: unknown run option(s) n_trian" in err and len(err.strip().splitlines()) == 1
    bad.write_text('[experimental]\nmerit = "l1"\n')
    assert main(["reproduce", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "merit must be 'state' or 'normalised', got 'l1'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_run_file_says_how_to_run_but_not_where_to_write(tmp_path, capsys, monkeypatch):
    rf = tmp_path / "run.toml"
    rf.write_text('out = "elsewhere"\n')
    assert main(["reproduce", "--config", str(rf), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "run.toml: out: not a run-file key; give --out DIR on the command line" in err
    rf.write_text("subjects = 1\n")
    assert main(["reproduce", "--config", str(rf), "--out", str(tmp_path / "o")]) == 2
    assert "subjects: expected a number of built-in virtual subjects, 2 to 100" in capsys.readouterr().err
    rf.write_text('workers = 1\nscheduler = "nohost"\n')  # read, and checked as the flags are
    assert main(["reproduce", "--config", str(rf), "--out", str(tmp_path / "o")]) == 2
    assert "run.toml: scheduler: 'nohost': expected an address like tcp://HOST:PORT" in capsys.readouterr().err
    assert main(["reproduce", "--set", 'scheduler="nohost"', "--out", str(tmp_path / "o")]) == 2
    assert "error: --set: scheduler: 'nohost': expected an address" in capsys.readouterr().err
    assert main(["reproduce", "--config", str(rf), "--scheduler", "x y", "--out", str(tmp_path / "o")]) == 2
    assert "error: --scheduler 'x y': expected an address" in capsys.readouterr().err  # the flag's, named so
    seen = {}

    def stop(units, splits, out_dir, *, workers=1, scheduler=None, **kw):
        seen.update(workers=workers, scheduler=scheduler)
        raise KeyboardInterrupt

    monkeypatch.setattr("reachirl.experiments.runner.run_units", stop)
    rf.write_text("workers = 1\nquick = true\n")
    assert main(["reproduce", "--config", str(rf), "--out", str(tmp_path / "o"), "--no-progress"]) == 130
    assert seen == {"workers": 1, "scheduler": None}
    assert main(["reproduce", "--config", str(rf), "--workers", "2", "--out", str(tmp_path / "o")]) == 130
    assert seen["workers"] == 2  # the flag wins


def test_a_pooled_fit_given_one_task_is_the_single_task_fit(p2):
    pooled = MOIRL(2, **FAST).fit(p2)  # one rollout per (subject, posture): here one
    single = MOIRL(2, rollout="mean", **FAST).fit(p2)
    np.testing.assert_array_equal(pooled.weights_, single.weights_)

    def steps(est):
        return [{k: v for k, v in h.items() if k != "wall_time"} for h in est.history_]

    assert steps(pooled) == steps(single)


def test_a_pooled_fit_solves_one_rollout_per_task(recorded):
    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"])
    est = MOIRL(2, n_nodes=40, max_iter=1).fit(trials)
    assert len(est.tasks_) == 2 and sorted(set(est.task_of_demo_.tolist())) == [0, 1]
    for r, task in enumerate(est.tasks_):  # each rollout starts from its own posture's mean start
        mine = [t for t, g in zip(trials, est.task_of_demo_, strict=True) if g == r]
        np.testing.assert_allclose(task.q0, np.mean([t.x0[:2] for t in mine], axis=0))
    assert not any("postures" in w for w in est.warnings_)


def test_the_seed_form_is_the_papers_step_computed_by_hand(arm):
    """One iteration of ``seed_form=True`` against the paper's Eq. 4 and its α search, written out here."""
    rng = np.random.default_rng(4)
    truth = np.array([[0.1, 1.0, 0.1, 0.01, 1e-4, 0.02, 0.05], [0.1, 0.5, 0.2, 0.003, 1e-4, 0.02, 0.05]])
    demos = []
    for i in range(3):
        task = ReachingTask(
            arm,
            np.deg2rad([-80.0, 95.0]) + np.deg2rad(rng.normal(0, 2, 2)),
            0.9 * arm.length,
            0.7 + 0.02 * i,
            n_nodes=20,
        )
        sol = solve_doc(task, truth)
        demos.append(trial_from_solution(sol, arm, task.target_x, subject="S", posture="P", trial_id=f"T{i}"))
    est = MOIRL(2, n_nodes=20, max_iter=1, seed_form=True).fit(demos)

    # the paper: ω₀ = 0.05, one rollout from the mean task, over its duration, at rest at both ends
    w = np.full((2, 7), 0.05)
    task = mean_task(demos, 20)
    roll = solve_doc(task, w)
    phi_i = windowed_features(task.arm, roll.q, roll.qd, roll.tau, task.duration / 20, 2)
    phi_d = [windowed_features(d.arm, *d.knots(20), d.duration / 20, 2) for d in demos]

    def eq4(dw_flat):  # Σ_d −log(1 / (1 + γ e^{−C(x, Δω)})) + β/2 ‖Δω‖², γ e^{−C(x, Δω)} = e^{−(ω+Δω)ᵀ(Φ−Φ*)}
        dw = dw_flat.reshape(2, 7)
        return sum(np.log1p(np.exp(-np.sum((w + dw) * (phi_i - pd)))) for pd in phi_d) + 0.5e-10 * np.sum(dw**2)

    res = minimize(
        eq4,
        np.zeros(14),
        method="L-BFGS-B",
        bounds=[(-(1 - 1e-3) * x, None) for x in w.ravel()],
        options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 500},
    )
    dw = res.x.reshape(2, 7)
    x_demos = np.stack([d.knot_state(20) for d in demos])

    def merit(sol):  # (1/D) Σ_d (1/N) ‖x*_d − x‖² over (q, q̇)
        x = np.hstack([sol.q, sol.qd])
        return np.mean([np.sum((xd - x) ** 2) / 21 for xd in x_demos])

    m0, alpha = merit(roll), 1.0
    for _ in range(10):  # the α search: 1, 0.25, 0.25², …; the first fall of the merit is taken
        m = merit(solve_doc(task, w + alpha * dw, warm_start=roll))
        if m < m0:
            break
        alpha *= 0.25
    else:
        pytest.fail("the hand-written step found no α: choose other demonstrations")
    assert est.history_[0]["merit"] == pytest.approx(m0, rel=1e-6)
    assert est.history_[1]["alpha"] == alpha and est.history_[1]["step"] == "likelihood"
    np.testing.assert_allclose(est.weights_, w + alpha * dw, rtol=1e-4)
    assert est.history_[1]["merit"] == pytest.approx(m, rel=1e-4)


def test_the_seed_form_and_the_default_differ_where_the_docs_say(p2):
    from reachirl.irl.options import departures
    from reachirl.irl.provenance import estimator_info

    seed = MOIRL(2, seed_form=True, **FAST).fit(p2)
    assert seed.options_.observe is False and seed.options_.merit == "state" and seed.options_.scaling is None
    assert seed.options_.fallback is None and seed.tol_ == 0.0 and seed.plain_fit_ is None
    assert departures(seed.options_, "mean", seed.tol_) == []
    # MODEL.json's account: from one task its one rollout is the paper's (it once listed "one rollout per task")
    assert len(seed.tasks_) == 1 and estimator_info(seed, "moirl", p2)["departures"] == []
    default = MOIRL(2, **FAST).fit(p2)
    words = " ".join(departures(default.options_, default.rollout, default.tol_))
    for what in ("observed rollouts", "normalised merit", "scale-free steps", "merit fallback", "acceptance threshold"):
        assert what in words


def test_cv_and_iscv_trials_never_reach_a_fit(recorded, monkeypatch):
    """The protocol's units fit on their training trials only: every trial any ``fit`` sees is a training one."""
    from reachirl.experiments import protocol
    from reachirl.experiments.protocol import ProtocolConfig, make_units, run_unit, split_trials

    seen = []
    real = protocol.make_estimator

    def spy(unit):
        est = real(unit)
        fit = est.fit

        def recording_fit(trials):
            seen.extend(t.id for t in trials)
            return fit(trials)

        est.fit = recording_fit
        return est

    monkeypatch.setattr(protocol, "make_estimator", spy)
    trials = load_trials(recorded / "trials.npz")
    config = ProtocolConfig(sections=(2,), n_train=2, n_nodes=40, max_iter=1, uncertainty=0, posture_transfer=True)
    for posture in ("P2",):
        split = split_trials(trials, posture, config)
        (unit,) = [u for u in make_units(["P2"], config) if u.is_main]
        run_unit(unit, split)
        train = {t.id for t in split.train}
        assert set(seen) == train and not train & {t.id for t in (*split.cv, *split.iscv)}


def test_posture_transfer_learns_on_the_other_postures_and_predicts_the_held_out_one(recorded, tmp_path, capsys):
    from test_outputs_doc import documented

    run = tmp_path / "run"
    assert (
        main(
            [
                "reproduce",
                "--data",
                str(recorded / "trials.npz"),
                "--out",
                str(run),
                "--sections",
                "2",
                *FAST_ARGS,
                "--n-train",
                "2",
                "--workers",
                "1",
                "--no-progress",
                "--uncertainty",
                "0",
                "--posture-transfer",
            ]
        )
        == 0
    )
    assert f"posture transfer in {run / 'posture_transfer.csv'}" in " ".join(capsys.readouterr().out.split())
    rows = (run / "posture_transfer.csv").read_text().splitlines()
    assert rows[0].split(",")[:6] == ["method", "sections", "held_out_posture", "mean", "sd", "n"]
    assert sorted(rows[0].split(",")) == sorted(documented()["posture_transfer.csv"])  # docs/outputs.md's table
    assert sorted(r.split(",")[2] for r in rows[1:]) == ["P2", "P4"]
    for held, other in (("P2", "P4"), ("P4", "P2")):
        model = json.loads((run / "models" / f"moirl-xfer-{held}-s2.json").read_text())
        assert model["info"]["postures"] == [other]  # learned on the other posture only
        row = next(r.split(",") for r in rows[1:] if r.split(",")[2] == held)
        assert int(row[5]) == 4 and int(row[8]) == 4  # S01's and S02's reaches of the held-out posture
    report = (run / "report.md").read_text()
    assert "## Posture transfer" in report and "every other posture (one rollout per posture)" in report
    # the fit time counts every unit this run computed, the transfer units' fits included
    units = [json.loads(f.read_text()) for f in (run / "units").glob("*.json")]
    assert any("xfer" in u["key"] for u in units)
    timing = json.loads((run / "results.json").read_text())["timing"]
    assert timing["fit_s_sum"] == pytest.approx(sum(u["fit"]["time_s"] for u in units), rel=1e-9)


def test_the_posture_transfer_text_names_the_rollout_its_fits_used():
    from reachirl.experiments.cost import _rollout_words

    def unit(options):
        return {"unit": {"estimator_options": options}}

    assert _rollout_words({"a": unit([["rollout", "per_demo"], ["seed_form", False]])}) == (
        "one rollout per demonstration"
    )
    assert _rollout_words({"a": unit({"rollout": "mean"}), "b": unit([])}) == (
        "one rollout for every posture's trials together; baseline: its own way"
    )
    # reproduce --method moirl kkt --posture-transfer: the rollout words are MO-IRL's, not KKT's (it has none)
    kkt = {"unit": {"method": "kkt", "estimator_options": []}}
    assert _rollout_words({"a": unit([["rollout", "per_task"]]), "b": kkt}) == (
        "one rollout per posture; kkt: its own way"
    )
    assert _rollout_words({"b": unit([])}) == "each method's own way"


@pytest.mark.parametrize(
    "text, match",
    [
        # each value as the run file wrote it, not as Python does ('false', True)
        ('seed_form = "false"', r'seed_form: expected true or false; got "false"'),
        ("subjects = true", r"subjects: expected a number of built-in virtual subjects, 2 to 100; got true"),
        ('methods = ["moirl", 2]', r'methods: expected a list of names, got \["moirl", 2\]'),
        ("posture_transfer = 1", r"posture_transfer: expected true or false; got 1"),
        ("uncertainty = 40.5", r"uncertainty: expected weight samples, 20 to 1000, or 0 for none; got 40\.5"),
        ("sections = [8, 0]", r"sections: expected a list of section counts, each 1 or more; got \[8, 0\]"),
        ("subjects = 0", r"subjects: expected a number of built-in virtual subjects, 2 to 100; got 0"),
    ],
)
def test_a_run_file_value_of_the_wrong_kind_is_refused(tmp_path, capsys, text, match):
    # `seed_form = "false"` (a non-empty string) once switched the paper's form on
    run = tmp_path / "run.toml"
    run.write_text(text + "\n")
    assert main(["reproduce", "--config", str(run), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert re.fullmatch(rf"reachirl reproduce: error: {re.escape(str(run))}: {match}", err), err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["reproduce", "fit"])
@pytest.mark.parametrize("text", ["", "# reachirl reproduce run file\n# written by a run that was cut short\n"])
def test_a_run_file_that_sets_nothing_is_refused(tmp_path, capsys, command, text):
    """An empty run file, or one cut short inside its header comment, is not taken for "every default" (which
    runs the whole protocol)."""
    run = tmp_path / "run.toml"
    run.write_text(text)
    argv = {
        "reproduce": ["reproduce", "--config", str(run), "--out", str(tmp_path / "o")],
        "fit": [
            "fit",
            str(tmp_path / "t.npz"),
            "--sections",
            "1",
            "--config",
            str(run),
            "--out",
            str(tmp_path / "m.json"),
        ],
    }[command]
    (tmp_path / "t.npz").write_bytes(b"")
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert re.fullmatch(
        rf"reachirl {command}: error: {re.escape(str(run))}: the run file sets no option \(empty, or comments "
        r"only\); leave --config out for the defaults",
        err,
    ), err
    assert not (tmp_path / "o").exists() and not (tmp_path / "m.json").exists()
