"""`reachirl fit` and `reachirl evaluate` end to end on a small virtual dataset, and their error paths."""

import json
import re

import numpy as np
import pytest

from reachirl import ReachingTask, solve_doc
from reachirl.cli import main
from reachirl.data.trial import save_trials, trial_from_solution
from reachirl.features import FEATURES

FEATURE_SCALE = np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])


def _reach(arm, q0, duration, weights, subject, posture, i):
    """The DOC's reach from ``q0`` (rad) to the bar at 90 % of the arm's length, as a trial."""
    task = ReachingTask(arm, q0, 0.9 * arm.length, duration, n_nodes=40)
    sol = solve_doc(task, weights)
    assert sol.converged
    return trial_from_solution(sol, arm, task.target_x, subject=subject, posture=posture, trial_id=str(i))


@pytest.fixture(scope="module")
def trials_file(tmp_path_factory, arm):
    rng = np.random.default_rng(0)
    w_true = np.array([[0.05, 0.5, 0.05, 3.0, 0.2, 0.05, 0.5], [0.05, 1.0, 0.05, 0.5, 0.2, 0.05, 0.5]])
    w_true = w_true / FEATURE_SCALE
    trials = []
    for i in range(4):
        q0 = np.deg2rad([0.0, 90.0]) + np.deg2rad(rng.normal(0, 2, 2))
        duration = 0.7 + 0.03 * rng.normal()
        trials.append(_reach(arm, q0, duration, w_true * np.exp(0.1 * rng.normal(size=w_true.shape)), "S1", "P2", i))
    path = tmp_path_factory.mktemp("cli") / "trials.npz"
    save_trials(path, trials)
    return path


def test_fit_then_evaluate(trials_file, tmp_path, capsys):
    model = tmp_path / "model.json"
    assert (
        main(["fit", str(trials_file), "--sections", "2", "--nodes", "40", "--max-iter", "5", "--out", str(model)]) == 0
    )
    m = json.loads(model.read_text())
    assert m["format"] == "reachirl-model/1" and m["method"] == "moirl" and m["n_windows"] == 2
    w = np.array(m["weights"])
    assert w.shape == (2, 7) and np.all(w >= 0)
    assert m["info"]["n_doc_solves"] >= 1 and len(m["info"]["history"]) >= 1
    # the learned weights predict the trials better than the initial ones (evaluated through the CLI too)
    start = tmp_path / "start.json"
    start.write_text(json.dumps({**m, "weights": m["info"]["history"][0]["weights"]}))
    rmse = {}
    for name, path in (("learned", model), ("start", start)):
        out = tmp_path / f"{name}_metrics.json"
        assert main(["evaluate", "--model", str(path), str(trials_file), "--out", str(out)]) == 0
        rmse[name] = json.loads(out.read_text())["summary"]["rmse_deg"]["q"]["mean"]
    assert rmse["learned"] < 0.8 * rmse["start"], rmse

    metrics = tmp_path / "metrics.json"
    capsys.readouterr()
    assert main(["evaluate", "--model", str(model), str(trials_file), "--out", str(metrics)]) == 0
    said = capsys.readouterr()
    assert said.err == "" and "RMSE q1" in said.out  # no progress bar, nor its blank line, in a log
    out = json.loads(metrics.read_text())
    s = out["summary"]
    assert s["n_trials"] == 4
    for key in ("q1", "q2", "q"):
        assert set(s["rmse_deg"][key]) == {"mean", "std"}
        assert 0 <= s["rmse_deg"][key]["mean"] < 10
    assert [t["id"] for t in out["trials"]] == [f"S1/P2/right/{i}" for i in range(4)]
    assert set(out["trials"][0]["rmse_deg"]) == {"q1", "q2", "q"}
    # q RMSE pools both joints: between the two joints' RMSEs
    t0 = out["trials"][0]["rmse_deg"]
    assert min(t0["q1"], t0["q2"]) - 1e-9 <= t0["q"] <= max(t0["q1"], t0["q2"]) + 1e-9
    assert out["backend"] == "casadi"  # the fit's

    # a model fitted on Crocoddyl is evaluated on Crocoddyl unless told otherwise (it once fell back to CasADi)
    croc = tmp_path / "croc.json"
    croc.write_text(json.dumps({**m, "info": {**m["info"], "backend": "crocoddyl"}}))
    one = ["--posture", "P2", "--subject", "S1"]
    for extra, backend in (([], "crocoddyl"), (["--backend", "casadi"], "casadi")):
        assert main(["evaluate", "--model", str(croc), str(trials_file), *one, *extra, "--out", str(metrics)]) == 0
        assert json.loads(metrics.read_text())["backend"] == backend


@pytest.mark.parametrize(
    ("make_args", "match"),
    [
        (
            lambda d, t: ["fit", str(d / "missing.npz"), "--sections", "1", "--out", str(d / "m.json")],
            r"missing\.npz: file not found",
        ),
        (
            lambda d, t: ["fit", str(d / "bad.npz"), "--sections", "1", "--out", str(d / "m.json")],
            r"bad\.npz: not a trials file",
        ),
        (
            lambda d, t: ["fit", str(t), "--sections", "101", "--out", str(d / "m.json")],
            r"--sections must be between 1 and",
        ),
        (
            lambda d, t: ["evaluate", "--model", str(d / "bad.json"), str(t), "--out", str(d / "x.json")],
            r"bad\.json: line 1: invalid JSON",
        ),
        (
            lambda d, t: ["evaluate", "--model", str(t), str(t), "--out", str(d / "x.json")],
            r"\.npz: not a reachirl model file: an NPZ archive such as a trials file, expected a MODEL\.json$",
        ),
        (
            lambda d, t: ["evaluate", "--model", str(d / "other.json"), str(t), "--out", str(d / "x.json")],
            r"other\.json: not a reachirl model file",
        ),
        (
            lambda d, t: ["fit", str(t), "--sections", "1", "--config", str(d / "run.toml"), "--out", str(d / "m")],
            r"run\.toml: fit reads only the \[experimental\] table of a run file, not max_iter, nodes \(give those as",
        ),
        (
            lambda d, t: ["fit", str(t), "--sections", "1", "--config", str(d / "typo.toml"), "--out", str(d / "m")],
            r"typo\.toml: unknown run-file key\(s\) merrit; fit reads only the \[experimental\] table of a run file$",
        ),
        (
            lambda d, t: ["fit", str(t), "--sections", "1", "--out", str(d / "old.npz")],
            r"old\.npz: --out: exists and is not a \.json file; it would be replaced \(choose another path\)",
        ),
        (
            lambda d, t: ["evaluate", "--model", str(d / "acados.json"), str(t), "--out", str(d / "x.json")],
            r"acados\.json: field 'info\.backend': expected \"casadi\" or \"crocoddyl\", found 'acados'",
        ),
    ],
)
def test_bad_input_exits_2_with_one_line(trials_file, tmp_path, capsys, make_args, match):
    (tmp_path / "bad.npz").write_text("time,q1\n1,2\n")
    (tmp_path / "bad.json").write_text("{not json")
    (tmp_path / "other.json").write_text('{"weights": [[1, 2, 3, 4, 5, 6, 7]]}')
    (tmp_path / "old.npz").write_bytes(b"a trials file given as --out by mistake")
    (tmp_path / "run.toml").write_text('nodes = 40\nmax_iter = 2\n\n[experimental]\nmerit = "state"\n')
    (tmp_path / "typo.toml").write_text('merrit = "state"\n')
    model = {"format": "reachirl-model/1", "features": list(FEATURES), "weights": [[1.0] * 7]}
    (tmp_path / "acados.json").write_text(json.dumps({**model, "info": {"backend": "acados"}}))
    assert main(make_args(tmp_path, trials_file)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert re.search(match, err), err
    assert not (tmp_path / "m.json").exists() and not (tmp_path / "x.json").exists()


def test_usage_error_exits_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["fit"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "reachirl fit: error: the following arguments are required: trials, --sections, --out" in err, err


@pytest.fixture(scope="module")
def mixed_file(tmp_path_factory, trials_file, arm):
    """The four P2 reaches of subject S1, and two reaches of another posture by subject S2."""
    from reachirl.data.trial import load_trials

    w = np.array([[0.05, 0.5, 0.05, 3.0, 0.2, 0.05, 0.5]]) / FEATURE_SCALE
    trials = load_trials(trials_file)
    for i, q0 in enumerate(([-60.0, 100.0], [-55.0, 95.0])):
        trials.append(_reach(arm, np.deg2rad(q0), 0.7, w, "S2", "P4", i))
    path = tmp_path_factory.mktemp("mixed") / "mixed.npz"
    save_trials(path, trials)
    return path


def test_fit_and_evaluate_take_the_chosen_trials_only(mixed_file, tmp_path, capsys):
    model = tmp_path / "p2.json"
    assert (
        main(
            [
                "fit",
                str(mixed_file),
                "--sections",
                "1",
                "--nodes",
                "40",
                "--max-iter",
                "2",
                "--posture",
                "P2",
                "--out",
                str(model),
            ]
        )
        == 0
    )
    info = json.loads(model.read_text())["info"]
    assert info["trial_ids"] == [f"S1/P2/right/{i}" for i in range(4)]
    assert info["selection"] == {"subjects": None, "postures": ["P2"], "sides": None}
    assert not any("postures" in w for w in info["warnings"])
    metrics = tmp_path / "m.json"
    assert (
        main(
            [
                "evaluate",
                "--model",
                str(model),
                str(mixed_file),
                "--subject",
                "S2",
                "S2",
                "--side",
                "right",
                "--out",
                str(metrics),
            ]
        )
        == 0
    )
    out = json.loads(metrics.read_text())
    assert [t["id"] for t in out["trials"]] == ["S2/P4/right/0", "S2/P4/right/1"]
    assert out["selection"] == {"subjects": ["S2"], "postures": None, "sides": ["right"]}


def test_fit_warns_when_one_mean_rollout_would_stand_for_several_postures(mixed_file, tmp_path, capsys):
    model = tmp_path / "all.json"
    assert (
        main(
            [
                "fit",
                str(mixed_file),
                "--sections",
                "1",
                "--nodes",
                "40",
                "--max-iter",
                "1",
                "--rollout",
                "mean",
                "--out",
                str(model),
            ]
        )
        == 0
    )
    info = json.loads(model.read_text())["info"]
    assert info["selection"] is None and len(info["trial_ids"]) == 6
    assert any("span 2 postures (P2, P4)" in w for w in info["warnings"]), info["warnings"]
    assert "span 2 postures" in capsys.readouterr().err


def test_fit_of_several_tasks_learns_one_cost_with_a_rollout_per_task(mixed_file, tmp_path, capsys):
    """The default fit of trials of two postures (and two subjects) solves one rollout per (subject, posture):
    its first iteration solves as many DOCs as there are tasks, and no warning is needed."""
    model = tmp_path / "all.json"
    assert (
        main(["fit", str(mixed_file), "--sections", "1", "--nodes", "40", "--max-iter", "1", "--out", str(model)]) == 0
    )
    info = json.loads(model.read_text())["info"]
    tasks = {tuple(i.split("/")[:2]) for i in info["trial_ids"]}
    assert len(tasks) > 1 and info["postures"] == ["P2", "P4"]
    assert info["history"][0]["doc_solves"] == len(tasks)
    assert not any("postures" in w for w in info["warnings"])


@pytest.mark.parametrize(
    ("selection", "match"),
    [
        (["--posture", "P9"], r"mixed\.npz: no trial of posture P9; they have posture P2, P4$"),
        (
            ["--subject", "S2", "--posture", "P2"],
            r"mixed\.npz: no trial of posture P2 among those of subject S2; they have posture P4$",
        ),
        (["--subject", "S1", "S3"], r"mixed\.npz: no trial of subject S3; they have subject S1, S2$"),
        (["--side", "left"], r"mixed\.npz: no trial of side left; they have side right$"),
    ],
)
@pytest.mark.parametrize("command", ["fit", "evaluate"])
def test_a_selection_no_trial_matches_exits_2_naming_the_file(mixed_file, tmp_path, capsys, selection, match, command):
    from reachirl.irl.model import LearnedModel, save_model

    model = tmp_path / "model.json"
    save_model(model, LearnedModel(weights=np.ones((1, 7)), n_nodes=40, method="moirl", info={}))
    args = (
        ["fit", str(mixed_file), "--sections", "1", "--out", str(tmp_path / "m.json")]
        if command == "fit"
        else ["evaluate", "--model", str(model), str(mixed_file), "--out", str(tmp_path / "m.json")]
    )
    assert main([*args, *selection]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(match, err), err
    assert not (tmp_path / "m.json").exists()


def test_trials_cut_at_two_thresholds_are_refused_naming_the_file(trials_file, tmp_path, capsys):
    # a trials file merged from two `preprocess --threshold` runs: one rollout cannot be seen two ways
    from dataclasses import replace

    from reachirl import MOIRL
    from reachirl.data.trial import load_trials
    from reachirl.errors import InputError

    trials = [replace(t, onset_threshold=0.05 if i < 2 else 0.1) for i, t in enumerate(load_trials(trials_file))]
    with pytest.raises(InputError, match=r"cut at different onset thresholds \[0\.05, 0\.1\]"):
        MOIRL(n_windows=1, n_nodes=20, max_iter=1).fit(trials)
    mixed = tmp_path / "two_thresholds.npz"
    save_trials(mixed, trials)
    out = tmp_path / "m.json"
    assert main(["fit", str(mixed), "--sections", "1", "--nodes", "20", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert re.search(
        r"^reachirl fit: error: \S*two_thresholds\.npz: .*different onset thresholds.*--rollout per_demo", err
    )
    assert not out.exists()


def test_reproduce_refuses_trials_cut_at_two_thresholds_before_any_work(trials_file, tmp_path, capsys):
    from dataclasses import replace

    from reachirl.data.trial import load_trials

    trials = load_trials(trials_file)
    first = (trials[0].subject, trials[0].posture)
    mixed = [
        replace(t, onset_threshold=0.1 if (t.subject, t.posture) == first and i % 2 else 0.05)
        for i, t in enumerate(trials)
    ]
    path = tmp_path / "two_thresholds.npz"
    save_trials(path, mixed)
    out = tmp_path / "run"
    out.mkdir()
    (out / "table.csv").write_text("an earlier run's table\n")
    earlier = "# reachirl 0.1.0 reproduce: the options of this run; repeat it with ...\nquick = true\n"
    (out / "run.toml").write_text(earlier)  # an earlier run's folder (a folder of the user's own is refused)
    args = ["reproduce", "--data", str(path), "--quick", "--workers", "1", "--out", str(out), "--no-progress"]
    assert main([*args, "--postures", first[1]]) == 2
    err = capsys.readouterr().err.strip()
    assert re.search(
        rf"^reachirl reproduce: error: \S*two_thresholds\.npz: {first[0]} {first[1]}: .*--rollout per_demo", err
    )
    assert len(err.splitlines()) == 1, err
    assert (out / "table.csv").read_text() == "an earlier run's table\n" and (out / "run.toml").read_text() == earlier


def test_fit_says_each_warning_once_on_stderr(tiny_trials, tmp_path, cli):
    """A fit warning was said twice: logged while fitting (``WARNING ...``) and printed after it (``warning: ...``).
    Now once, on stderr, after the fit; nothing of it on stdout."""
    model = tmp_path / "m.json"
    proc = cli("fit", tiny_trials, "--sections", "1", "--nodes", "20", "--max-iter", "1", "--out", model)
    assert proc.returncode == 0, proc.stderr
    (warning,) = json.loads(model.read_text())["info"]["warnings"]  # one iteration: a fit of one step
    assert "stopped after one step" in warning
    assert proc.stderr.count(warning) == 1 and f"warning: {warning}\n" in proc.stderr, proc.stderr
    assert warning not in proc.stdout, proc.stdout


def test_model_and_metrics_name_the_trials_file_alike(tiny_trials, tmp_path, monkeypatch, capsys):
    """MODEL.json's info.trials kept the path as typed (relative, through a symlink) where METRICS.json's
    trials_file is absolute and resolved: both are now the resolved absolute path."""
    import shutil

    (tmp_path / "data").mkdir()
    real = tmp_path / "data" / "t.npz"
    shutil.copy(tiny_trials, real)
    (tmp_path / "link.npz").symlink_to(real)
    monkeypatch.chdir(tmp_path)
    assert main(["fit", "link.npz", "--sections", "1", "--nodes", "20", "--max-iter", "1", "--out", "m.json"]) == 0
    assert main(["evaluate", "--model", "m.json", "link.npz", "--out", "metrics.json"]) == 0
    named = json.loads((tmp_path / "m.json").read_text())["info"]["trials"]
    assert named == json.loads((tmp_path / "metrics.json").read_text())["trials_file"] == str(real.resolve())


@pytest.mark.parametrize("extra", [[], ["--uncertainty", "0"], ["--method", "kkt"]])
def test_fit_refuses_a_seed_without_weight_samples(tmp_path, extra):
    """--seed seeds --uncertainty's samples alone (the fit makes no random choice): given without them it changed
    nothing, without a word."""
    from reachirl.cli import build_parser, fit
    from reachirl.errors import InputError

    argv = ["fit", str(tmp_path / "t.npz"), "--sections", "2", "--seed", "3", *extra, "--out", str(tmp_path / "m.json")]
    with pytest.raises(InputError, match=r"--seed seeds the weight samples of --uncertainty, which is not given"):
        fit.run(build_parser().parse_args(argv))


def test_fits_pooling_line_gives_one_width_when_the_tasks_alone_agree():
    """`fit --posture P1 P2 --uncertainty` said "mean share-interval width 0.81 against 0.82-0.82 from each task
    alone": a range of one number. Now one number; a range where the tasks differ."""
    from reachirl.cli.fit import _pooling_words

    def pooling(*alone):
        per_task = {f"S01/P{i + 1}": {"mean_width": w} for i, w in enumerate(alone)}
        return {"pooled": {"mean_width": 0.8076}, "per_task": per_task}

    said = _pooling_words(pooling(0.8238, 0.8230))
    assert said == "pooling 2 tasks: mean share-interval width 0.81 against 0.82 from each task alone", said
    assert _pooling_words(pooling(0.91, 0.94)).endswith("against 0.91-0.94 from each task alone")
