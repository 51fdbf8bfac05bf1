"""The public interface the project's design (design.md, kept outside this repository; not docs/design-notes.md)
promises, spelled as it spells it: the Python names and their signatures, the commands and options, the Makefile
targets and the JSON fields (through docs/outputs.md, whose tables test_outputs_doc.py checks against the files the
commands write). Names may be added, never renamed or
dropped: a rename fails here. Cheap: parsers and signatures, one 20-knot DOC."""

import dataclasses
import inspect
import re
from pathlib import Path

import numpy as np
import pytest

import reachirl
from reachirl import FEATURES, MOIRL, ArmModel, DocSolution, ReachingTask, solve_doc
from reachirl.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]


def _params(f) -> dict:
    return {name: p.default for name, p in inspect.signature(f).parameters.items()}


def test_the_python_names_and_signatures():
    # FEATURES' names and order: tests/test_features.py (test_feature_order_is_the_papers)
    for name in ("FEATURES", "ArmModel", "ReachingTask", "solve_doc", "DocSolution", "MOIRL"):
        # dir() (inspect.getmembers, help) left out MOIRL, which the package imports on first use
        assert name in reachirl.__all__ and name in dir(reachirl) and hasattr(reachirl, name)
    assert dict(inspect.getmembers(reachirl))["MOIRL"] is MOIRL
    assert ArmModel.__dataclass_params__.frozen
    assert [f.name for f in dataclasses.fields(ArmModel)] == ["l1", "l2", "m1", "m2", "c1", "c2", "i1", "i2", "gravity"]
    assert ArmModel.__dataclass_fields__["gravity"].default == 9.81
    assert list(_params(ArmModel.from_anthropometrics)) == [
        "height_m",
        "mass_kg",
        "sex",
        "upper_arm_m",
        "forearm_m",
        "hand_m",
    ]
    assert all(_params(ArmModel.from_anthropometrics)[k] is None for k in ("upper_arm_m", "forearm_m", "hand_m"))
    task = _params(ReachingTask)
    assert list(task)[:5] == ["arm", "q0", "target_x", "duration", "n_nodes"] and task["n_nodes"] == 100
    doc = _params(solve_doc)
    assert list(doc)[:4] == ["task", "weights", "backend", "warm_start"]
    assert doc["backend"] == "casadi" and doc["warm_start"] is None
    moirl = _params(MOIRL)
    assert next(iter(moirl)) == "n_windows" and moirl["n_windows"] == 8
    assert {"seed_form", "uncertainty", "max_iter", "tol"} <= set(moirl)
    fit = _params(MOIRL.fit)  # fit(trials), and scikit-learn's y, ignored (its default None keeps fit(trials))
    assert list(fit)[1:] == ["trials", "y"] and fit["trials"] is inspect.Parameter.empty and fit["y"] is None
    assert list(_params(MOIRL.predict))[1] == "trial_or_task"


def test_the_angle_convention_the_doc_solution_and_the_trial(arm):
    q = np.array([-np.pi / 2 + 0.4, 1.1])
    tip = (arm.l1 * np.cos(q[0]) + arm.l2 * np.cos(q.sum()), arm.l1 * np.sin(q[0]) + arm.l2 * np.sin(q.sum()))
    assert np.allclose(arm.fk(q), tip)
    assert arm.gravity_torque(np.array([-np.pi / 2, 0.0])) == pytest.approx([0.0, 0.0], abs=1e-12)  # hangs still
    task = ReachingTask(arm, np.deg2rad([-80.0, 60.0]), 0.8 * arm.length, 0.7, n_nodes=20)
    sol = solve_doc(task, np.full((2, len(FEATURES)), 0.05))
    assert isinstance(sol, DocSolution) and sol.converged
    assert sol.t.shape == (21,) and sol.q.shape == (21, 2) and sol.qd.shape == (21, 2) and sol.tau.shape == (20, 2)
    assert isinstance(sol.cost, float) and isinstance(sol.iterations, int) and sol.solve_time >= 0
    from reachirl.data.trial import trial_from_solution

    trial = trial_from_solution(sol, arm, task.target_x, subject="S1", posture="P2", trial_id="T0")
    # the data path's Trial (q, q̇, q̈, τ, x0, target, duration, subject, posture): `target` was missing
    assert trial.target == trial.target_x == pytest.approx(task.target_x)
    for name in ("q", "qd", "qdd", "tau", "x0", "duration", "subject", "posture"):
        assert hasattr(trial, name)


def _options(command: str) -> dict:
    """``{option string: action}`` of a command's parser."""
    parser = build_parser().commands[command]
    return {s: a for a in parser._actions for s in a.option_strings}


@pytest.mark.parametrize(
    ("command", "options"),
    [
        (
            "reproduce",
            "--data --sections --out --workers --scheduler --seed --quick --backend --subjects --iscv --seed-form "
            "--posture-transfer --config",
        ),
        ("synth", "--out --subjects --trials --seed --format"),
        (
            "preprocess",
            "--out --format --markers --static --markerset --subject-info --subject --posture --side --manifest",
        ),
        ("fit", "--sections --method --out --backend --uncertainty --posture --subject --seed-form"),
        ("evaluate", "--model --out --predictions"),
        ("simulate", "--model --render"),
        ("plot", "--model --out"),
        ("bench", "--out"),
        ("sensitivity", "--out"),
    ],
)
def test_every_command_and_option(command, options):
    have = _options(command)
    assert set(options.split()) <= set(have), sorted(set(options.split()) - set(have))


def test_the_options_choices_and_defaults():
    def choices(command, option):
        return set(_options(command)[option].choices)

    assert {"auto", "trc", "c3d", "vicon-csv", "mot", "csv"} <= choices("preprocess", "--format")
    assert {"right", "left"} <= choices("preprocess", "--side")
    assert {"trc", "c3d", "mot"} <= choices("synth", "--format")
    assert {"moirl", "maxent", "bilevel", "kkt"} <= choices("fit", "--method")
    for command in ("fit", "reproduce"):
        assert {"casadi", "crocoddyl"} <= choices(command, "--backend")
    assert "all-pairs" in choices("reproduce", "--iscv")
    args = build_parser().parse_args(["reproduce"])
    assert args.sections is None or list(args.sections) == [1, 6, 8]
    from reachirl.experiments.protocol import ProtocolConfig

    assert list(ProtocolConfig().sections) == [1, 6, 8]
    # several --subject (and --posture) values, given together or one by one, choose them all
    argv = "fit t.npz --sections 1 --out m.json --subject A --subject B --posture P1 P2".split()
    fit = build_parser().parse_args(argv)
    assert fit.subject == ["A", "B"] and fit.posture == ["P1", "P2"]
    # plot takes a trials file (with --model) or a run folder as its one positional
    assert build_parser().parse_args(["plot", "RUN_DIR", "--out", "figs"]).model is None


def test_the_makefile_targets_the_readme_and_ci():
    makefile = (ROOT / "Makefile").read_text()
    targets = set(re.findall(r"^([A-Za-z][\w-]*):", makefile, flags=re.M))
    assert {"install", "run", "test", "bench"} <= targets
    for target in ("run", "test", "bench"):
        assert re.search(rf"^{target}:.*\binstall\b", makefile, flags=re.M), target
    assert ".venv" in makefile
    readme = (ROOT / "README.md").read_text()
    assert "make run" in readme and "make test" in readme
    assert re.search(r"^make test\b", (ROOT / ".ci" / "run").read_text(), flags=re.M)
    for doc in ("usage.md", "method.md", "design-notes.md", "benchmarks.md", "cli.md"):
        assert (ROOT / "docs" / doc).is_file()


def test_the_json_fields_are_documented_as_the_design_spells_them():
    from test_outputs_doc import documented

    doc = documented()
    assert {"summary", "trials"} <= set(doc["METRICS.json"])
    assert {"n_trials", "rmse_deg"} <= set(doc["METRICS.json summary"])
    assert {"id", "rmse_deg"} <= set(doc["METRICS.json trials[]"])
    assert {"weights", "features", "n_windows", "uncertainty"} <= set(doc["MODEL.json"])
    assert {"method", "weight_samples", "share_intervals"} <= set(doc["MODEL.json uncertainty"])
    assert {"method", "posture", "sections", "train_subject", "test_subject", "n"} <= set(doc["iscv_pairs.csv"])
    assert {"method", "sections", "held_out_posture", "mean", "sd", "n"} <= set(doc["posture_transfer.csv"])
    assert {"feature", "window"} <= set(doc["sensitivity.csv"])
