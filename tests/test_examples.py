"""The examples run and do what they say (each is a short script with a main())."""

import importlib.util
import json
import re
from pathlib import Path

import pytest

from reachirl import FEATURES

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def one_line(err: str) -> str:
    """The one line an example says on bad input: argparse's usage line came before it."""
    lines = err.splitlines()
    assert len(lines) == 1 and not lines[0].startswith("usage:"), err
    return lines[0]


def test_quickstart_writes_its_figure(tmp_path, capsys):
    out = tmp_path / "q.png"
    assert load("quickstart").main(["--out", str(out)]) == 0
    assert out.stat().st_size > 10_000
    text = capsys.readouterr().out
    assert text.count("converged=True") == 3


@pytest.mark.slow
def test_learn_from_ue_adl_predicts_the_other_arm(capsys):
    assert load("learn_from_ue_adl").main([]) == 0
    lines = capsys.readouterr().out.splitlines()
    rmse = {ln.split()[0]: float(ln.split("RMSE of q ")[1].split()[0]) for ln in lines if "RMSE of q" in ln}
    assert rmse["training"] < 6 and rmse["validation"] < 10
    windows = [ln for ln in lines if ln.startswith("window ")]
    assert len(windows) == 8
    quoted = re.findall(r"([a-z_]+) (\d\.\d\d) \[(\d\.\d\d), (\d\.\d\d)\]", " ".join(windows))
    for feature, share, lo, hi in quoted:  # a quoted share lies in its own interval, which is narrow
        assert feature in FEATURES and float(lo) - 0.01 <= float(share) <= float(hi) + 0.01
        assert float(hi) - float(lo) <= 0.25 + 0.01


@pytest.mark.parametrize(("name", "option"), [("quickstart", "--out"), ("virtual_subjects", "--figure")])
def test_examples_need_an_output_path(name, option, capsys):
    """No default output: an example never writes into the repository or the current folder unasked."""
    with pytest.raises(SystemExit) as e:
        load(name).main([])
    assert e.value.code == 2
    assert one_line(capsys.readouterr().err).endswith(f"error: the following arguments are required: {option}")


def test_one_cost_across_subjects_needs_three_subjects(recorded, capsys):
    with pytest.raises(SystemExit) as e:
        load("one_cost_across_subjects").main(["--data", str(recorded / "trials.npz")])
    assert e.value.code == 2 and "needs at least 3 subjects, found 2" in one_line(capsys.readouterr().err)


@pytest.mark.slow
def test_one_cost_across_subjects_compares_pooled_and_single_fits(tmp_path, capsys):
    from reachirl.data.trial import save_trials
    from reachirl.experiments import datasets

    ds = datasets.toy(n_subjects=3, postures=("P2",), n_trials=2, n_nodes=20, seed=2)
    save_trials(tmp_path / "t.npz", ds.trials)
    assert load("one_cost_across_subjects").main(["--data", str(tmp_path / "t.npz"), "--windows", "2"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 4 and lines[-1].startswith("mean: pooled ")


@pytest.mark.parametrize(("name", "option"), [("quickstart", "--out"), ("virtual_subjects", "--figure")])
@pytest.mark.parametrize(
    ("where", "match"),
    [
        ("folder", r"{path}: {option}: is a folder, expected a file path"),
        ("figure.txt", r"{path}: {option}: expected a figure file name ending in one of \.avif, .*\.png"),
        ("figure", r"{path}: {option}: expected a figure file name ending in one of"),
        ("notes.txt/figure.png", r"{parent}: {option}: {parent} is a file, not a folder"),
    ],
)
def test_examples_refuse_a_bad_figure_path_before_any_work(tmp_path, capsys, name, option, where, match):
    """A folder, a name matplotlib cannot write (or would silently give another name: no suffix) or a path below a
    file: exit 2 with the path named, before any solve (not a traceback after them, nor 'wrote' a file that was
    written elsewhere)."""
    (tmp_path / "folder").mkdir()
    (tmp_path / "notes.txt").write_text("mine\n")
    path = tmp_path / where
    with pytest.raises(SystemExit) as e:
        load(name).main([option, str(path)])
    captured = capsys.readouterr()
    assert e.value.code == 2 and captured.out == ""
    want = match.format(path=re.escape(str(path)), parent=re.escape(str(path.parent)), option=option)
    assert re.search(want, one_line(captured.err)), captured.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "notes.txt"]


def test_virtual_subjects_needs_a_trial(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        load("virtual_subjects").main(["--figure", str(tmp_path / "p.png"), "--trials", "0"])
    assert e.value.code == 2 and "argument --trials: expected a whole number of at least 1, got 0" in one_line(
        capsys.readouterr().err
    )
    assert not (tmp_path / "p.png").exists()


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory, cli):
    """A quick reproduce run on the built-in virtual subjects: 40 knots, 3 training trials, P2, 8 sections."""
    out = tmp_path_factory.mktemp("arm") / "run"
    proc = cli(
        "reproduce", "--quick", "--sections", "8", "--postures", "P2", "--uncertainty", "0", "--workers", "1",
        "--no-progress", "--out", out,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return out


def test_arm_sensitivity_predicts_the_runs_own_training_reach(quick_run, monkeypatch, capsys):
    """The mean reach is the run's training trials' (3 here, not the protocol's default 10) on the run's knots
    (40, not 100), with the weights of the run's main fit."""
    import numpy as np

    module = load("arm_sensitivity")
    seen, weights = [], []
    real_mean_task = module.mean_task

    def mean_task(trials, n_nodes):
        seen.append((len(trials), n_nodes))
        return real_mean_task(trials, n_nodes)

    def predict(task, threshold, w, arm):
        weights.append(np.asarray(w))
        return np.zeros((task.n_nodes + 1, 2))

    monkeypatch.setattr(module, "mean_task", mean_task)
    monkeypatch.setattr(module, "_predict", predict)
    assert module.main([str(quick_run)]) == 0
    assert seen[0] == (3, 40)
    unit = json.loads((quick_run / "units" / "moirl-P2-s8.json").read_text())
    assert any(np.array_equal(w, np.asarray(unit["weights"])) for w in weights)
    assert capsys.readouterr().out.startswith("P2 | own arm:")


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--data-seed", "1"], r"--data-seed 1: not the seed of the run's virtual subjects"),
        (["--sections", "5"], r"run: no MO-IRL fit with 5 sections; the run has 8 sections of moirl"),
    ],
)
def test_arm_sensitivity_refuses_what_the_run_does_not_hold(quick_run, capsys, args, match):
    with pytest.raises(SystemExit) as e:
        load("arm_sensitivity").main([str(quick_run), *args])
    assert e.value.code == 2 and re.search(match, one_line(capsys.readouterr().err))


@pytest.mark.parametrize(
    ("name", "args", "match"),
    [
        ("learn_from_ue_adl", ["--data", "{missing}"], "{missing}: not a folder"),
        ("learn_from_ue_adl", ["--windows", "0"], "argument --windows: expected a whole number of at least 1, got 0"),
        ("one_cost_across_subjects", ["--data", "{missing}"], "{missing}: file not found"),
        ("ue_adl_agreement", ["--root", "{missing}"], "{missing}: not a folder"),
        (
            "arm_sensitivity",
            ["{missing}"],
            "{missing}: no such run folder (expected the --out folder of `reachirl reproduce`)",
        ),
        ("quickstart", ["--out", "{missing}.png", "--bogus"], "error: unrecognized arguments: --bogus"),
        (
            "virtual_subjects",
            ["--figure", "{missing}.png", "--trials", "many"],
            "argument --trials: invalid int value: 'many'",
        ),
    ],
)
def test_examples_refuse_bad_input_in_one_line(tmp_path, capsys, name, args, match):
    """Not an InputError's (or ValueError's) traceback, nor argparse's usage line before the error: exit 2 with one
    line naming the file or option and what is wrong."""
    missing = str(tmp_path / "missing")
    with pytest.raises(SystemExit) as e:
        load(name).main([a.format(missing=missing) for a in args])
    err = capsys.readouterr().err
    assert e.value.code == 2 and one_line(err).endswith(match.format(missing=missing)), err
