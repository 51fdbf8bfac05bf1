"""`reachirl plot --model` predicts as `evaluate` does (trials cut at a speed threshold seen as recorded), takes
the same trial choice, and reads the model through the one checked loader."""

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from folder_locks import held_elsewhere
from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.cli import build_parser, main, plot
from reachirl.data.trial import load_trials, save_trials
from reachirl.doc.evaluation import evaluate_trials
from reachirl.doc.observation import observe
from reachirl.errors import InputError
from reachirl.virtual import nominal_weights, posture_q

N = 20
ARM = ArmModel.from_anthropometrics(1.76, 70.0, "M")
THRESHOLD = 0.05


def _recorded(subject: str, k: int, offset: float) -> object:
    """A rest-to-rest reach under the nominal weights, cut at its own crossings of the speed threshold, as a
    recording is."""
    task = ReachingTask(
        ARM, posture_q("P2") + np.deg2rad([offset, -offset]), 0.95 * ARM.length, 0.75 + 0.02 * k, n_nodes=N
    )
    sol = solve_doc(task, nominal_weights())
    assert sol.converged
    return replace(
        observe(sol, task, THRESHOLD), subject=subject, posture="P2", trial_id=f"T{k}", onset_threshold=THRESHOLD
    )


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """Cut trials of two subjects, and a model fitted on S01's (observed rollouts: the fit's default)."""
    d = tmp_path_factory.mktemp("plot")
    trials = [_recorded(s, k, off) for s in ("S01", "S02") for k, off in enumerate((-3.0, 0.0, 3.0))]
    path = save_trials(d / "trials.npz", trials)
    model = d / "model.json"
    assert (
        main(
            [
                "fit",
                str(path),
                "--subject",
                "S01",
                "--sections",
                "2",
                "--nodes",
                str(N),
                "--max-iter",
                "2",
                "--out",
                str(model),
            ]
        )
        == 0
    )
    assert json.loads(model.read_text())["info"]["observe"] is True
    return d, path, model


def _summary_line(out: str) -> str:
    return next(line for line in out.splitlines() if "trials: RMSE" in line)


def test_plot_gives_evaluates_rmse_on_the_chosen_held_out_trials(fitted, capsys):
    d, trials, model = fitted
    capsys.readouterr()
    assert main(["evaluate", "--model", str(model), str(trials), "--subject", "S02", "--out", str(d / "m.json")]) == 0
    evaluated = _summary_line(capsys.readouterr().out)
    assert (
        main(["plot", "--model", str(model), str(trials), "--subject", "S02", "--no-pdf", "--out", str(d / "figs")])
        == 0
    )
    plotted = _summary_line(capsys.readouterr().out)
    assert plotted == evaluated and plotted.startswith("3 trials:")
    assert (d / "figs" / "prediction.png").is_file() and (d / "figs" / "convergence.png").is_file()
    # the prediction a plot that ignored the model's `observe` would make is measurably another one
    weights = np.array(json.loads(model.read_text())["weights"])
    held_out = [t for t in load_trials(trials) if t.subject == "S02"]
    metrics = json.loads((d / "m.json").read_text())["summary"]["rmse_deg"]["q"]["mean"]
    whole = np.mean([e.rmse_q for e in evaluate_trials(weights, held_out, N, observe=False)])
    assert abs(whole - metrics) > 0.05


@pytest.mark.parametrize(("field", "value"), [("observe", "yes"), ("seed_form", "no")])
def test_plot_reads_the_model_through_the_checked_loader(fitted, capsys, field, value):
    # info.seed_form "no" was read as true: the figures' titles said "moirl (seed form)" of a default fit
    d, trials, model = fitted
    bad = json.loads(model.read_text())
    bad["info"][field] = value
    (d / f"bad_{field}.json").write_text(json.dumps(bad))
    capsys.readouterr()
    assert main(["plot", "--model", str(d / f"bad_{field}.json"), str(trials), "--out", str(d / field)]) == 2
    err = capsys.readouterr().err
    assert f"{d / f'bad_{field}.json'}: field 'info.{field}': expected true or false, found '{value}'" in err
    assert len(err.strip().splitlines()) == 1 and not (d / field).exists()


@pytest.mark.parametrize(("which", "name"), [("model", "weights.png"), ("trials", "prediction.pdf")])
def test_plot_never_writes_over_an_input_named_as_one_of_its_figures(fitted, tmp_path, capsys, which, name):
    """--out DIR where DIR/<figure> is the model or the trials file read (the earlier figures are removed first,
    even with --no-pdf): refused before anything is removed or drawn, the input left as it was."""
    _, trials, model = fitted
    inputs = {"model": model, "trials": trials}
    victim = tmp_path / name
    victim.write_bytes(inputs[which].read_bytes())
    inputs[which] = victim
    capsys.readouterr()
    argv = ["plot", "--model", str(inputs["model"]), str(inputs["trials"]), "--trial", "0", "--no-pdf"]
    assert main([*argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--out ({victim}) is the input file {victim}; it would be overwritten" in err[0], err
    assert victim.read_bytes() == (model if which == "model" else trials).read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"info.history": "garbage"}, "field 'info.history': expected a list of objects"),
        # entries the convergence figure cannot plot drew an empty figure, exit 0
        (
            {"info.history": [{"iteration": 0, "merit": 0.5}, {"iteration": "x", "merit": "y"}]},
            "field 'info.history', entry 1: 'iteration' expected a whole number >= 0, found 'x'",
        ),
        (
            {"info.history": [{"iteration": 0, "merit": "y"}]},
            "field 'info.history', entry 0: 'merit' expected a finite number or null, found 'y'",
        ),
        ({"method": "foo"}, "field 'method': expected one of moirl, maxent, bilevel, kkt, found 'foo'"),
        ({"uncertainty": {"share_intervals": None}}, "field 'uncertainty.share_intervals': expected an object"),
        ({"uncertainty": []}, "field 'uncertainty': expected an object or null"),
        (
            {"uncertainty": {"weight_samples": [[[float("nan")] * 7] * 2], "share_intervals": None}},
            "field 'uncertainty.weight_samples': expected a list of 2 × 7 matrices of numbers >= 0",
        ),
    ],
)
def test_a_models_optional_fields_are_checked_before_any_figure(fitted, capsys, tmp_path, change, match):
    """A damaged history or uncertainty record is refused before the predictions and figures, not halfway."""
    _, trials, model = fitted
    bad = json.loads(model.read_text())
    for key, value in change.items():
        if key.startswith("info."):
            bad["info"][key[5:]] = value
        else:
            bad[key] = value
    (tmp_path / "bad2.json").write_text(json.dumps(bad))
    capsys.readouterr()
    assert main(["plot", "--model", str(tmp_path / "bad2.json"), str(trials), "--out", str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "y").exists()


def test_plot_of_a_run_folder_refuses_a_trial_choice(tmp_path, capsys):
    (tmp_path / "run").mkdir()
    assert main(["plot", str(tmp_path / "run"), "--subject", "S01", "--out", str(tmp_path / "f")]) == 2
    assert "--subject chooses trials, so it needs --model" in capsys.readouterr().err


def test_plot_of_a_run_folder_refuses_a_backend(tmp_path):
    """`--backend` chooses the backend of --model's predictions; a run folder's figures solve no DOC, so the flag
    was ignored there without a word (figures said to be on crocoddyl were CasADi's)."""
    (tmp_path / "run").mkdir()
    args = build_parser().parse_args(["plot", str(tmp_path / "run"), "--backend", "crocoddyl", "--out", str(tmp_path)])
    with pytest.raises(InputError, match=r"--backend chooses the backend of the predictions of --model"):
        plot._plot(args, tmp_path / "f", lambda: None)


@pytest.mark.parametrize("command", ["plot", "sensitivity"])
def test_a_run_stopped_before_its_outputs_is_called_unfinished(tmp_path, capsys, command):
    """A run stopped by --max-units holds run.toml, units/ and models/ but no results.json: `plot` called it "not a
    `reachirl reproduce` folder"."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.toml").write_text("quick = true\n")
    assert main([command, str(run), "--out", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err
    unfinished = r"run: not a finished `?(reachirl )?reproduce`? run: no results\.json \(rerun reproduce into it"
    assert re.search(unfinished, err), err


def test_a_negative_trial_index_is_refused(tmp_path, capsys):
    from reachirl.cli import main
    from reachirl.data.trial import save_trials
    from reachirl.experiments import datasets
    from reachirl.irl.model import LearnedModel, save_model

    trials = datasets.toy(n_subjects=1, postures=("P2",), n_trials=2, n_nodes=20, seed=1).trials
    save_trials(tmp_path / "t.npz", trials)
    model = save_model(tmp_path / "m.json", LearnedModel(np.full((1, 7), 0.1), n_nodes=20))
    for command in (
        ["plot", "--model", str(model), str(tmp_path / "t.npz"), "--out", str(tmp_path / "f")],
        ["simulate", "--model", str(model), str(tmp_path / "t.npz"), "--out", str(tmp_path / "s.json")],
    ):
        assert main([*command, "--trial", "-1"]) == 2
        err = capsys.readouterr().err
        assert "--trial -1: index out of range, expected 0 to 1" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "f").exists() and not (tmp_path / "s.json").exists()


def test_a_trial_index_counts_among_the_selected_trials(tmp_path, capsys, monkeypatch):
    """`--posture P2 --trial 0` is the file's first P2 trial (once the index counted in the whole file, whose
    first trial is P1's, and the choice was refused); an index past the selection says how many it holds."""
    from reachirl.cli import main
    from reachirl.cli import plot as plot_cli
    from reachirl.data.trial import save_trials
    from reachirl.experiments import datasets
    from reachirl.irl.model import LearnedModel, save_model

    path = tmp_path / "t.npz"
    save_trials(path, datasets.toy(n_subjects=1, postures=("P1", "P2"), n_trials=2, n_nodes=20, seed=1).trials)
    model = save_model(tmp_path / "m.json", LearnedModel(np.full((1, 7), 0.1), n_nodes=20))
    drawn = []
    monkeypatch.setattr(
        plot_cli, "model_figures", lambda m, trials, *a, **k: drawn.append([t.id for t in trials]) or []
    )
    plot = ["plot", "--model", str(model), str(path), "--out", str(tmp_path / "f")]
    assert main([*plot, "--posture", "P2", "--trial", "1", "--trial", "S01_P2_T01"]) == 0
    assert main([*plot, "--trial", "3"]) == 0  # without a choice, the index counts in the whole file
    assert main([*plot, "--subject", "S01", "--side", "right", "--trial", "0"]) == 0  # every trial chosen
    assert drawn == [
        ["S01/P2/right/S01_P2_T02", "S01/P2/right/S01_P2_T01"],
        ["S01/P2/right/S01_P2_T02"],
        ["S01/P1/right/S01_P1_T01"],
    ]
    simulate = ["simulate", "--model", str(model), str(path), "--out", str(tmp_path / "s.json")]
    for command in (plot, simulate):
        for extra, said in (
            (
                ["--posture", "P2", "--trial", "2"],
                "--trial 2: index out of range, expected 0 to 1 (the selection --posture P2 holds 2 of the file's 4 "
                "trials)",
            ),
            (
                ["--subject", "S01", "--posture", "P1", "--trial", "-1"],
                "--trial -1: index out of range, expected 0 to 1 (the selection --subject S01 --posture P1 holds 2 "
                "of the file's 4 trials)",
            ),
            (["--trial", "4"], "--trial 4: index out of range, expected 0 to 3 (the file holds 4 trials)"),
            (
                ["--posture", "P2", "--trial", "S01_P1_T01"],
                "--trial S01_P1_T01: S01/P1/right/S01_P1_T01 is not among the selected trials (the selection "
                "--posture P2 holds 2 of the file's 4 trials)",
            ),
            (
                ["--posture", "P2", "--trial", "T9"],
                "--trial T9: no trial with that id, trial_id or index (the selection --posture P2 holds 2 of the "
                "file's 4 trials)",
            ),
        ):
            capsys.readouterr()
            assert main([*command, *extra]) == 2
            err = capsys.readouterr().err.strip()
            assert err.endswith(f"{path}: {said}") and len(err.splitlines()) == 1, err
    assert not (tmp_path / "s.json").exists()


def test_plot_of_a_run_with_a_damaged_checkpoint_names_it(fitted, capsys):
    d, trials, _ = fitted
    run = d / "run"
    args = ["reproduce", "--data", str(trials), "--quick", "--sections", "1", "--uncertainty", "0"]
    assert main([*args, "--workers", "1", "--no-progress", "--out", str(run)]) == 0
    (npz,) = sorted((run / "units").glob("*.npz"))[:1]
    npz.write_bytes(npz.read_bytes()[:100])  # truncated
    capsys.readouterr()
    assert main(["plot", str(run), "--out", str(d / "figs"), "--no-pdf"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{npz}: damaged checkpoint" in err and "rerun `reachirl reproduce`" in err, err
    assert len(err.splitlines()) == 1


def test_plot_of_a_run_with_other_predictions_in_a_units_place_names_the_file(run_folder, tmp_path, capsys):
    """A unit's NPZ replaced by other predictions (another unit's copied over it, here its own edited): plot drew
    them under the unit's title without a word, where reproduce into the folder refuses it by the checksum its JSON
    checkpoint holds."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    b = sorted((run / "units").glob("*.npz"))[0]
    with np.load(b) as z:
        arrays = {k: z[k] for k in z.files}
    key = next(k for k in arrays if k.endswith("pred_q"))
    arrays[key] = arrays[key] * np.float32(1.01)
    np.savez(b, **arrays)
    capsys.readouterr()
    assert main(["plot", str(run), "--out", str(tmp_path / "figs"), "--no-pdf"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{b}: damaged checkpoint, content differs from the one its JSON" in err, err
    assert not (tmp_path / "figs").exists()


def test_plot_of_a_run_whose_unit_predictions_are_missing_names_them(run_folder, tmp_path, capsys):
    """A unit NPZ removed (its JSON checkpoint says it wrote one): the figures drawn from it were left out without
    a word (exit 0, fig2_prediction and fig4_iscv not written); now refused in one line naming the file."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    for npz in (run / "units").glob("*.npz"):
        npz.unlink()
    capsys.readouterr()
    assert main(["plot", str(run), "--out", str(tmp_path / "figs"), "--no-pdf"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and ".npz: missing: the predictions of the run's unit" in err, err
    assert f"rerun `reachirl reproduce` into {run} to recompute it" in err
    assert not (tmp_path / "figs").exists()


def test_plot_of_a_run_refused_leaves_no_out_folder_it_made(run_folder, tmp_path, capsys):
    # a damaged checkpoint found while drawing: the --out folder made for the figures was left behind, empty
    import shutil

    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    for npz in (run / "units").glob("*.npz"):
        npz.write_bytes(npz.read_bytes()[:100])  # truncated
    capsys.readouterr()
    assert main(["plot", str(run), "--out", str(tmp_path / "new" / "figs"), "--no-pdf"]) == 2
    assert "damaged checkpoint" in capsys.readouterr().err
    assert not (tmp_path / "new" / "figs").exists()
    (tmp_path / "mine").mkdir()  # a folder that was there stays
    assert main(["plot", str(run), "--out", str(tmp_path / "mine"), "--no-pdf"]) == 2
    assert (tmp_path / "mine").is_dir()


@pytest.fixture(scope="module")
def run_folder(fitted):
    d, trials, _ = fitted
    run = d / "run_for_results"
    args = ["reproduce", "--data", str(trials), "--quick", "--sections", "1", "--uncertainty", "0", "--max-iter", "1"]
    assert main([*args, "--workers", "1", "--no-progress", "--out", str(run)]) == 0
    return run


def test_plot_of_a_run_leaves_no_figure_of_an_earlier_set_beside_its_own(run_folder, tmp_path, capsys):
    """`plot runA --out F` then `plot runB --out F --no-pdf` left runA's PDFs beside runB's PNGs (and a methods
    figure of a run with two methods after one with one); then `reproduce` into a run whose figures were plotted
    beside its results (`plot RUN --out RUN`) left them there, the earlier run's beside the new one's."""
    import shutil

    figs = tmp_path / "F"
    assert main(["plot", str(run_folder), "--out", str(figs)]) == 0
    pdfs = sorted(p.name for p in figs.glob("*.pdf"))
    assert pdfs and (figs / "methods.png").exists() is False
    shutil.copyfile(figs / "fig2_prediction.png", figs / "methods.png")  # an earlier set's methods figure
    mine = figs / "fig3_weights_mine.pdf"
    mine.write_bytes(b"%PDF-1.4 my own")
    assert main(["plot", str(run_folder), "--out", str(figs), "--no-pdf"]) == 0
    assert sorted(p.name for p in figs.glob("*.pdf")) == [mine.name]  # the user's own stays
    assert not (figs / "methods.png").exists() and mine.exists() and (figs / "fig2_prediction.png").exists()
    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    assert main(["plot", str(run), "--out", str(run), "--no-pdf"]) == 0
    assert (run / "fig2_prediction.png").exists()
    shutil.copyfile(run / "run.toml", tmp_path / "cfg.toml")
    args = ["reproduce", "--config", str(tmp_path / "cfg.toml"), "--set", "seed=4", "--workers", "1", "--out", str(run)]
    assert main([*args, "--no-progress"]) == 0
    assert not (run / "fig2_prediction.png").exists() and (run / "figures" / "fig2_prediction.png").exists()


def _earlier_figure(path: Path) -> bytes:
    """A figure an earlier `plot` wrote (reachirl's, which a new one may replace); returns its bytes."""
    import matplotlib.pyplot as plt

    from reachirl.experiments.figures import save

    fig = plt.figure()
    plt.plot([0, 1])
    save(fig, path)
    return path.read_bytes()


def _protocol(d, key, value):
    d["protocol"][key] = value


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (
            lambda d: _protocol(d, "sections", "abc"),
            r"field 'protocol\.sections': expected a non-empty list of integers",
        ),
        (
            lambda d: _protocol(d, "methods", 5),
            r"field 'protocol\.methods': expected a non-empty list of strings, found 5",
        ),
        (lambda d: _protocol(d, "methods", []), r"field 'protocol\.methods': expected a non-empty list of strings"),
        (lambda d: _protocol(d, "sections", [1, 999]), r"field 'protocol': --sections 999 exceeds the \d+ DOC"),
        (lambda d: d.update(protocol=[1]), r"field 'protocol': expected an object, found list"),
        (lambda d: d["units"][0].pop("key"), r"field 'units', unit 0: expected a list of objects with a 'key'"),
        (lambda d: d.update(units={"a": 1}), r"field 'units': expected a list of objects"),
        (lambda d: d["units"][0].pop("sets"), r"malformed results file \(KeyError: 'sets'\)"),
        (lambda d: d["units"][0]["sets"].pop("cv"), r"malformed results file \(KeyError: 'cv'\)"),
        (
            lambda d: d["units"][0].update(history=5),
            r"field 'units', unit 0 \(moirl-P2-s1\): 'history': expected a list of objects whose 'iteration' is a "
            r"number, found 5",
        ),
        (
            lambda d: d["units"][0]["history"].append({"iteration": "one"}),
            r"field 'units', unit 0 \(moirl-P2-s1\): 'history': expected a list of objects",
        ),
        (
            lambda d: d["units"][0].update(cost_shares="abc"),
            r"field 'units', unit 0 \(moirl-P2-s1\): 'cost_shares': expected rows of 7 numbers \(one per window\), "
            r"found 'abc'",
        ),
        (
            lambda d: d["units"][0].update(cost_shares=[[0.5, 0.5]]),
            r"field 'units', unit 0 \(moirl-P2-s1\): 'cost_shares': expected rows of 7 numbers",
        ),
        (
            lambda d: d["units"][0].update(flag=[1]),
            r"field 'units', unit 0 \(moirl-P2-s1\): 'flag': expected a string or null, found \[1\]",
        ),
        (
            lambda d: d["units"][0].update(uncertainty={"share_intervals": {"determined": [True]}}),
            r"field 'units', unit 0 \(moirl-P2-s1\): 'uncertainty\.share_intervals\.determined': expected booleans "
            r"shaped as 'cost_shares' \(1 × 7\), found \[True\]",
        ),
        # a boolean among the weights was drawn as 1, "n_train": true read as 1 trial
        (
            lambda d: d["units"][0]["weights"][0].__setitem__(2, True),
            r"field 'units', unit 0 \(.+\), 'weights': expected numbers, found a boolean \(true\) among the numbers, "
            r"at \[0\]\[2\]$",
        ),
        (lambda d: _protocol(d, "n_train", True), r"field 'protocol': n_train must be a number, got True$"),
    ],
)
def test_plot_of_a_run_with_a_damaged_results_file_names_it(run_folder, tmp_path, capsys, change, match):
    """results.json damaged or edited by hand: exit 2 naming the file and the field, not an internal error."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    d = json.loads((run / "results.json").read_text())
    change(d)
    (run / "results.json").write_text(json.dumps(d))
    figs = tmp_path / "figs"
    figs.mkdir()
    earlier = _earlier_figure(figs / "fig3_weights.png")
    capsys.readouterr()
    assert main(["plot", str(run), "--out", str(figs), "--no-pdf"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(re.escape(f"{run / 'results.json'}: ") + match, err[0]), err
    # no figure of the failed drawing is left, nor a mix with the earlier set
    assert [p.name for p in figs.iterdir()] == ["fig3_weights.png"]
    assert (figs / "fig3_weights.png").read_bytes() == earlier


@pytest.mark.parametrize("error", [TypeError, KeyError, ValueError, ZeroDivisionError])
def test_plot_of_a_run_reports_a_drawing_bug_as_an_internal_error(run_folder, tmp_path, capsys, monkeypatch, error):
    """An error of the drawing code itself is the program's (exit 1, internal error), not a malformed results file;
    the figures of --out are left as they were."""
    from reachirl.experiments import figures

    def broken(*args, **kwargs):
        raise error("a bug in the figure code")

    monkeypatch.setattr(figures, "plot_weights", broken)
    figs = tmp_path / "figs"
    figs.mkdir()
    earlier = _earlier_figure(figs / "fig3_weights.png")
    capsys.readouterr()
    assert main(["plot", str(run_folder), "--out", str(figs), "--no-pdf"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"reachirl plot: internal error: {error.__name__}: "), err
    assert "a bug in the figure code" in err[0] and "malformed" not in err[0], err
    assert [p.name for p in figs.iterdir()] == ["fig3_weights.png"]
    assert (figs / "fig3_weights.png").read_bytes() == earlier


def test_plot_of_a_run_replaces_the_figures_once_all_are_drawn(run_folder, tmp_path):
    figs = tmp_path / "figs"
    figs.mkdir()
    (figs / ".plot-partial-killed").mkdir()  # what a killed drawing left
    assert main(["plot", str(run_folder), "--out", str(figs), "--no-pdf"]) == 0
    names = sorted(p.name for p in figs.iterdir())
    assert names and all(n.endswith(".png") for n in names) and "fig3_weights.png" in names, names


def test_plot_of_a_run_syncs_its_folder_after_moving_the_figures_in(run_folder, tmp_path, monkeypatch):
    """The figures are drawn in a hidden folder and renamed into --out: the renames are synced to the disk too
    (each figure is, as it is drawn), so a crash of the system leaves the earlier figures or the new ones."""
    import os
    import stat

    figs = tmp_path / "figs"
    figs.mkdir()
    events, real_fsync, real_replace = [], os.fsync, os.replace

    def fsync(fd):
        st = os.fstat(fd)
        events.append(("fsync folder" if stat.S_ISDIR(st.st_mode) else "fsync file", st.st_ino))
        return real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", os.path.dirname(dst)))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    assert main(["plot", str(run_folder), "--out", str(figs), "--no-pdf"]) == 0
    into = [i for i, e in enumerate(events) if e == ("replace", str(figs))]
    assert into and events[-1] == ("fsync folder", figs.stat().st_ino) and into[-1] < len(events) - 1


def test_a_model_from_the_estimator_predicts_as_the_estimator(fitted, tmp_path):
    """LearnedModel.from_estimator keeps what prediction needs (observe, the fit's own reach): saved, loaded and
    evaluated, it predicts the estimator's reaches."""
    from reachirl import MOIRL
    from reachirl.data.trial import load_trials
    from reachirl.irl.model import LearnedModel, load_model, save_model

    _, trials_path, _ = fitted
    trials = load_trials(trials_path)
    own = [t for t in trials if t.subject == "S01"]
    est = MOIRL(2, n_nodes=N, max_iter=2).fit(own)
    model = load_model(save_model(tmp_path / "m.json", LearnedModel.from_estimator(est, own)))
    assert model.observe and model.rollout_q is not None and model.method == "moirl"
    for trial, err in zip(trials[3:], model.evaluate(trials[3:]), strict=True):
        np.testing.assert_allclose(err.prediction.q, est.predict(trial).q, atol=1e-9)
        np.testing.assert_allclose(model.predict(trial).q, est.predict(trial).q, atol=1e-9)
    # a task given on other knots is solved on the model's, from the fit's own reach, as the estimator does
    task = ReachingTask(ARM, posture_q("P2") + np.deg2rad([2.0, -2.0]), 0.95 * ARM.length, 0.8, n_nodes=2 * N)
    sol = model.predict(task)
    assert sol.converged and sol.q.shape == (N + 1, 2)
    np.testing.assert_allclose(sol.q, est.predict(task).q, atol=1e-9)
    with pytest.raises(TypeError, match="predict takes a Trial or a ReachingTask, got str"):
        model.predict("trials.npz")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"weights": np.zeros((2, 7))}, "all weights are zero"),
        ({"weights": np.ones((2, 7)), "n_nodes": 3}, "n_nodes"),
        ({"weights": np.ones((2, 7)), "info": {"backend": "foo"}}, "field 'info.backend'"),
    ],
)
def test_a_model_that_would_not_load_is_not_built(kwargs, match):
    from reachirl.irl.model import LearnedModel

    with pytest.raises(ValueError, match=match):
        LearnedModel(**kwargs)


def test_simulate_plays_the_prediction_evaluate_scores(fitted):
    """An observed model's playback is of the reach `evaluate` scores (its part above the onset threshold, from
    the fit's rollout), not of the DOC over the trial's own duration."""
    pytest.importorskip("mujoco")
    from reachirl.irl.model import load_model
    from reachirl.sim.simulate import simulate_trial

    _, path, model_path = fitted
    model = load_model(model_path)
    trial = next(t for t in load_trials(path) if t.subject == "S02")
    scored = model.evaluate([trial])[0].prediction
    played = simulate_trial(
        trial, model.weights, model.n_nodes, substeps=1, observe=model.observe, path=model.rollout_q
    )
    np.testing.assert_array_equal(played.solution.q, scored.q)
    assert played.solution.t[-1] < trial.duration / 0.9 * 0.99  # the observed part, not the rest-to-rest DOC
    # at the DOC's own step, MuJoCo's semi-implicit Euler from the part's first (moving) state retraces it
    assert played.result.rmse_deg["q"] < 1e-6 and abs(played.result.final_x_error) < 1e-9


def test_simulate_leaves_a_failed_doc_out_of_its_summary(fitted, tmp_path, capsys, monkeypatch):
    pytest.importorskip("mujoco")
    import reachirl.sim.simulate as sim

    _, path, model = fitted
    real = sim.predict

    def failing_first(trial, *args, **kwargs):
        whole, seen = real(trial, *args, **kwargs)
        if trial.trial_id == "T0":
            whole, seen = replace(whole, converged=False), replace(seen, converged=False)
        return whole, seen

    monkeypatch.setattr(sim, "predict", failing_first)
    out = tmp_path / "sim.json"
    capsys.readouterr()
    assert main(["simulate", "--model", str(model), str(path), "--subject", "S02", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "S02/P2/right/T0: DOC (casadi) NOT converged" in text
    summary = next(line for line in text.splitlines() if "trials: RMSE" in line)
    assert summary.startswith("2 of 3 trials") and summary.endswith("1 DOC failure(s) left out")
    rows = json.loads(out.read_text())
    assert rows["doc_failures"] == 1 and [t["doc"]["converged"] for t in rows["trials"]] == [False, True, True]
    kept = [t["mujoco"]["rmse_deg"]["q"] for t in rows["trials"][1:]]
    assert f"RMSE q {np.mean(kept):.3f} ± {np.std(kept):.3f}°" in summary


def test_a_doc_answer_with_non_finite_values_is_a_failure_counted_not_a_crash(fitted, tmp_path, capsys, monkeypatch):
    """A solver that reports success over NaN knots: the prediction is not converged (DocSolution refuses the
    report), is not cut at the speed threshold, and evaluate counts it as a DOC failure and exits 0."""
    import reachirl.doc.observation as ob

    _, path, model = fitted
    real, calls = ob.solve_doc, []

    def nan_once(task, *args, **kwargs):  # the first prediction's knots NaN, its solver's report kept
        sol = real(task, *args, **kwargs)
        calls.append(task)
        return replace(sol, q=np.full_like(sol.q, np.nan)) if len(calls) == 1 else sol

    monkeypatch.setattr(ob, "solve_doc", nan_once)
    out = tmp_path / "metrics.json"
    capsys.readouterr()
    assert main(["evaluate", "--model", str(model), str(path), "--subject", "S02", "--out", str(out)]) == 0
    metrics = json.loads(out.read_text())
    assert metrics["summary"]["doc_failures"] == 1 and metrics["summary"]["n_included"] == 2
    failed = [t for t in metrics["trials"] if not t["converged"]]
    assert len(failed) == 1 and failed[0]["rmse_deg"]["q"] is None


def _figures_drawn(monkeypatch) -> dict:
    """``{file name: (title, [(x, y) of each line of the first axes])}`` of every figure saved from now on."""
    from reachirl.experiments import figures as fg

    drawn, real = {}, fg.save

    def save(fig, path, close=True):
        lines = [(ln.get_xdata(), ln.get_ydata()) for ln in fig.axes[0].get_lines()]
        drawn[Path(path).name] = (fig._suptitle.get_text() if fig._suptitle else "", lines)
        real(fig, path, close=close)

    monkeypatch.setattr(fg, "save", save)
    return drawn


def test_plot_leaves_a_failed_prediction_out_and_says_so(fitted, tmp_path, capsys, monkeypatch):
    """A prediction whose DOC failed is not an answer of the model: it is not drawn as one, and the title counts
    it; an earlier figure set in the folder does not stay beside the new one."""
    import reachirl.doc.evaluation as ev

    _, path, model = fitted
    out = tmp_path / "figs"
    out.mkdir()
    earlier = _earlier_figure(out / "convergence.png")  # an earlier model's
    real = ev.predict

    def failing_first(trial, *args, **kwargs):
        whole, seen = real(trial, *args, **kwargs)
        return (whole, replace(seen, converged=False)) if trial.trial_id == "T0" else (whole, seen)

    monkeypatch.setattr(ev, "predict", failing_first)
    drawn = _figures_drawn(monkeypatch)
    argv = ["plot", "--model", str(model), str(path), "--subject", "S02", "--no-pdf", "--out", str(out)]
    assert main(argv) == 0
    title, lines = drawn["prediction.png"]
    assert "2 demonstration(s) (dashed) vs predictions (solid) (1 of 3 DOC failure(s) not drawn)" in title
    assert len(lines) == 4  # a demonstration and a prediction for each of the two converged trials
    assert "convergence.png" in drawn and (out / "convergence.png").read_bytes() != earlier


def test_plot_draws_a_bilevel_search_per_evaluation_and_names_the_seed_form(fitted, tmp_path, monkeypatch):
    import json as js

    _, path, model = fitted
    d = js.loads(model.read_text())
    # a failed evaluation's merit is written as null (MODEL.json holds no Infinity)
    history = [
        {"evaluation": k + 1, "merit": m, "converged": m is not None} for k, m in enumerate((0.5, 0.4, None, 0.3))
    ]
    bilevel = tmp_path / "bilevel.json"
    bilevel.write_text(
        js.dumps({**d, "method": "bilevel", "info": {**d["info"], "method": "bilevel", "history": history}})
    )
    seed = tmp_path / "seed.json"
    seed.write_text(js.dumps({**d, "info": {**d["info"], "seed_form": True}}))
    drawn = _figures_drawn(monkeypatch)
    for m, out in ((bilevel, "b"), (seed, "s")):
        argv = ["plot", "--model", str(m), str(path), "--subject", "S02", "--no-pdf", "--out", str(tmp_path / out)]
        assert main(argv) == 0
        if m == bilevel:  # the convergence figure: one point per evaluation whose DOC converged
            title, lines = drawn["convergence.png"]
            assert title == "bilevel: merit of each evaluation"
            assert [list(x) for x, _ in lines] == [[1, 2, 4]] and list(lines[0][1]) == [0.5, 0.4, 0.3]
    assert all(drawn[f][0].startswith("moirl (seed form)") for f in ("prediction.png", "weights.png"))


def test_plot_of_a_model_without_samples_suggests_only_what_its_method_takes(fitted, tmp_path, monkeypatch):
    """weights.png's footnote suggests --uncertainty for a MO-IRL model only: kkt and bilevel refuse it; a KKT
    model's shares are on the plotted trials (it solves no DOC), and its footnote says so."""
    import json as js

    from reachirl.experiments import figures as fg

    _, path, model = fitted
    kkt = tmp_path / "kkt.json"
    assert main(["fit", str(path), "--subject", "S01", "--sections", "2", "--nodes", str(N), "--method", "kkt",
                 "--out", str(kkt)]) == 0  # fmt: skip
    bilevel = tmp_path / "bilevel.json"  # the moirl model, named bilevel (its reach and no samples)
    d = js.loads(model.read_text())
    bilevel.write_text(js.dumps({**d, "method": "bilevel", "info": {**d["info"], "method": "bilevel"}}))
    notes, real = {}, fg.save

    def save(fig, where, close=True):
        notes[Path(where).parent.name, Path(where).name] = fig.texts[-1].get_text()  # the footnote, last
        real(fig, where, close=close)

    monkeypatch.setattr(fg, "save", save)
    for m in (model, kkt, bilevel):
        argv = ["plot", "--model", str(m), str(path), "--subject", "S02", "--no-pdf", "--out", str(tmp_path / m.stem)]
        assert main(argv) == 0
    assert notes["model", "weights.png"] == fg.NO_SAMPLES and "--uncertainty of fit" in fg.NO_SAMPLES
    assert notes["kkt", "weights.png"] == (
        "Shares on the plotted trials' own features (kkt solves no DOC: it has no reach of its own). No weight "
        "samples: kkt draws none (moirl and maxent fits do, with --uncertainty); nothing is hatched, and no share "
        "here is a finding."
    )
    assert notes["bilevel", "weights.png"] == (
        "No weight samples: bilevel draws none (moirl and maxent fits do, with --uncertainty); nothing is hatched, "
        "and no share here is a finding."
    )


def _users_figure(path: Path) -> bytes:
    """A figure of the user's own, saved by matplotlib without reachirl's mark (as any other program's)."""
    import matplotlib.pyplot as plt

    fig = plt.figure()
    plt.plot([0, 1], [1, 0])
    fig.savefig(path)
    plt.close(fig)
    return path.read_bytes()


@pytest.mark.parametrize("name", ["prediction.png", "weights.pdf", "convergence.png"])
def test_plot_never_replaces_a_figure_of_the_users_own(fitted, tmp_path, capsys, name):
    """`plot --model` replaced (or, for a PDF with --no-pdf, removed) any file of --out named as one of its
    figures. A file reachirl did not write (no reachirl mark in its metadata) is refused before any work, naming
    it; reachirl's own figures are replaced as before."""
    _, trials, model = fitted
    mine = _users_figure(tmp_path / name)
    capsys.readouterr()
    argv = ["plot", "--model", str(model), str(trials), "--trial", "0", "--no-pdf", "--out", str(tmp_path)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"reachirl plot: error: {tmp_path / name}: --out: exists and is not a figure written by reachirl (no "
        "reachirl mark in its metadata); it would be replaced (choose another folder, or remove it first)"
    ], err
    assert (tmp_path / name).read_bytes() == mine and sorted(p.name for p in tmp_path.iterdir()) == [name]
    # reachirl's own figures, from an earlier plot, are replaced
    (tmp_path / name).unlink()
    argv.remove("--no-pdf")  # PNG and PDF
    assert main(argv) == 0 and main(argv) == 0
    assert {"prediction.png", "prediction.pdf", "weights.png", "weights.pdf"} <= {p.name for p in tmp_path.iterdir()}


def test_plot_of_a_run_never_replaces_a_figure_of_the_users_own(run_folder, tmp_path, capsys):
    """Nor `plot RUN_DIR`: refused before drawing, --out left as it was."""
    mine = _users_figure(tmp_path / "fig3_weights.png")
    capsys.readouterr()
    assert main(["plot", str(run_folder), "--out", str(tmp_path), "--no-pdf"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{tmp_path / 'fig3_weights.png'}: --out: exists and is not a figure written by" in err[0]
    assert (tmp_path / "fig3_weights.png").read_bytes() == mine
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig3_weights.png"]


def test_plot_of_a_run_into_its_own_figures_folder_replaces_its_figures(run_folder, tmp_path, capsys):
    """The run's own figures/ holds what reproduce drew there, marked or (a run of before the mark) not: plot RUN_DIR
    --out RUN_DIR/figures draws them again."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    (run / "figures").mkdir(exist_ok=True)
    old = _users_figure(run / "figures" / "fig3_weights.png")  # unmarked, as every figure of before the mark
    assert main(["plot", str(run), "--out", str(run / "figures"), "--no-pdf"]) == 0
    assert (run / "figures" / "fig3_weights.png").read_bytes() != old
    from reachirl.experiments.figures import is_marked_figure

    assert is_marked_figure(run / "figures" / "fig3_weights.png")


@pytest.mark.parametrize("inside", ["units", "units/figs", "models", "predictions", "predictions/a/b"])
def test_plot_of_a_run_refuses_an_out_among_the_runs_data(run_folder, tmp_path, capsys, inside):
    """plot RUN --out RUN/units drew the figures (and the hidden folder they are drawn in) among the run's
    checkpoints, which a rerun reads back; so for its models and exported predictions. Refused before any work,
    exit 2 in one line naming --out; the run's folder is left as it was."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    (run / "models").mkdir(exist_ok=True)
    (run / "predictions").mkdir(exist_ok=True)
    before = sorted(p for p in run.rglob("*"))
    out = run / inside
    capsys.readouterr()
    assert main(["plot", str(run), "--out", str(out), "--no-pdf"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    name = inside.split("/")[0]
    assert err == [
        f"reachirl plot: error: {out}: --out is inside the run's own {name}/ folder, which `reachirl reproduce` "
        f"writes and reads back; choose another --out for the figures (e.g. {run.resolve() / 'figures'})"
    ], err
    assert sorted(p for p in run.rglob("*")) == before
    # the run's folder itself and its figures folder stay allowed
    assert main(["plot", str(run), "--out", str(run), "--no-pdf"]) == 0
    assert main(["plot", str(run), "--out", str(run / "figures"), "--no-pdf"]) == 0


def test_plot_of_a_run_being_written_is_refused_until_the_writer_ends(run_folder, tmp_path, capsys):
    """plot RUN --out RUN/figures while a reproduce runs into RUN (which holds RUN, not RUN/figures) drew a run
    being rewritten into the folder the run writes; it is refused (exit 2) before it changes anything, and draws
    once the writer has ended."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    (run / "figures").mkdir(exist_ok=True)
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    argv = ["plot", str(run), "--out", str(run / "figures"), "--no-pdf"]
    with held_elsewhere(run):  # a reproduce running into the folder, as it holds it
        assert main(argv) == 2
        assert capsys.readouterr().err.strip().splitlines() == [
            f"reachirl plot: error: {run}: another reachirl command is writing into this folder now; wait for it to end"
        ]
        assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
    assert main(argv) == 0  # a finished run, nothing running: plotted
    assert main(["plot", str(run), "--out", str(run), "--no-pdf"]) == 0  # into the folder read: held by this plot


def test_plot_titles_name_a_backend_other_than_casadi(fitted, tmp_path, monkeypatch):
    """A Crocoddyl fit's figures did not say so: its titles name the backend beside the method (CasADi, the default,
    goes unsaid), and the predictions' backend when it is not the fit's."""
    _, path, model = fitted
    m = json.loads(model.read_text())
    croc = tmp_path / "croc.json"
    croc.write_text(json.dumps({**m, "info": {**m["info"], "backend": "crocoddyl"}}))
    drawn = _figures_drawn(monkeypatch)
    base = ["plot", str(path), "--trial", "0", "--no-pdf"]
    assert main([*base, "--model", str(croc), "--backend", "casadi", "--out", str(tmp_path / "c")]) == 0
    assert drawn["prediction.png"][0].startswith("moirl (crocoddyl), 2 sections: 1 demonstration(s) (dashed) vs ")
    assert "vs predictions on casadi (solid)" in drawn["prediction.png"][0]
    assert drawn["weights.png"][0] == "moirl (crocoddyl): each feature's share of its window's cost"
    assert drawn["convergence.png"][0] == "moirl (crocoddyl): convergence"
    assert main([*base, "--model", str(model), "--out", str(tmp_path / "k")]) == 0
    assert not any("casadi" in title or "crocoddyl" in title for title, _ in drawn.values())
    assert "vs predictions (solid)" in drawn["prediction.png"][0]


def test_a_runs_weights_figure_knows_its_method_for_the_footnote(run_folder, tmp_path, monkeypatch):
    """fig3 without weight samples says what draws them for the main table's method (kkt and bilevel: nothing)."""
    from reachirl.experiments import report

    kwargs, real = {}, report.figure_jobs

    def figure_jobs(*args, **kw):
        jobs, figs = real(*args, **kw)
        kwargs.update({Path(job.paths[-1]).name: job.kwargs for job in jobs})
        return jobs, figs

    monkeypatch.setattr(report, "figure_jobs", figure_jobs)
    assert main(["plot", str(run_folder), "--out", str(tmp_path / "figs"), "--no-pdf"]) == 0
    assert kwargs["fig3_weights.png"]["method"] == "moirl"


def test_a_runs_figure_titles_name_a_backend_other_than_casadi(run_folder, tmp_path, monkeypatch):
    """plot RUN_DIR (and reproduce, with the same jobs): the prediction, ISCV and convergence titles say a run
    solved on Crocoddyl."""
    import shutil

    from reachirl.experiments import report

    titles, real = {}, report.figure_jobs

    def figure_jobs(*args, **kwargs):
        jobs, figs = real(*args, **kwargs)
        titles.update({Path(job.paths[-1]).name: job.kwargs.get("title") for job in jobs})
        return jobs, figs

    monkeypatch.setattr(report, "figure_jobs", figure_jobs)
    for backend in ("crocoddyl", "casadi"):
        run = tmp_path / backend
        shutil.copytree(run_folder, run)
        res = json.loads((run / "results.json").read_text())
        res["protocol"]["backend"] = backend
        (run / "results.json").write_text(json.dumps(res))
        assert main(["plot", str(run), "--out", str(tmp_path / f"figs-{backend}"), "--no-pdf"]) == 0
        said = {name: title for name, title in titles.items() if title and "crocoddyl" in title}
        if backend == "crocoddyl":
            assert said["fig2_prediction.png"].endswith("vs moirl predictions on crocoddyl (solid)"), said
            assert said["convergence.png"] == "MO-IRL convergence (accepted steps) on crocoddyl", said
            assert said["fig4_iscv.png"].endswith("predicted on crocoddyl (solid)")
        else:
            assert not said, said


def test_plot_draws_each_demonstration_on_its_own_time(fitted, tmp_path, monkeypatch):
    """The x axis says time (s): a demonstration ends at its own duration, not at its prediction's (an observed
    prediction lasts longer or shorter than its trial; the demonstrations were stretched to the predictions' time)."""
    _, path, model = fitted
    drawn = _figures_drawn(monkeypatch)
    argv = ["plot", "--model", str(model), str(path), "--subject", "S02", "--no-pdf", "--out", str(tmp_path / "f")]
    assert main(argv) == 0
    _, lines = drawn["prediction.png"]
    trials = [t for t in load_trials(path) if t.subject == "S02"]
    demo_ends = [float(x[-1]) for x, _ in lines[0::2]]  # a demonstration, then its prediction, per trial
    pred_ends = [float(x[-1]) for x, _ in lines[1::2]]
    assert demo_ends == pytest.approx([t.duration for t in trials], rel=1e-12)
    assert max(abs(p - d) for p, d in zip(pred_ends, demo_ends, strict=True)) > 1e-3  # the two times differ here


def _prediction_drawn(monkeypatch) -> dict:
    """``{file name: (x label of the bottom-left axes, [x of each line of the top-left axes])}`` of every prediction
    figure drawn from now on."""
    from reachirl.experiments import figures as fg

    drawn, real = {}, fg.plot_prediction

    def plot_prediction(arrays, set_name="train", title="", axes=None):
        fig = real(arrays, set_name, title, axes)
        drawn[set_name] = (fig.axes[2].get_xlabel(), [np.asarray(ln.get_xdata()) for ln in fig.axes[0].get_lines()])
        return fig

    monkeypatch.setattr(fg, "plot_prediction", plot_prediction)
    return drawn


def _units_as_written_before_demonstration_times(run: Path) -> None:
    """Rewrite the run's checkpoints as a reachirl of before ``<set>/demo_t`` wrote them: the NPZ without those
    entries, its SHA-256 and the JSON's checksum to match."""
    import hashlib

    from reachirl.experiments.results import content_checksum
    from reachirl.io import npz_bytes

    for npz in sorted((run / "units").glob("*.npz")):
        with np.load(npz, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if not k.endswith("/demo_t")}
        data = npz_bytes(dict(sorted(arrays.items())))
        npz.write_bytes(data)
        js = npz.with_suffix(".json")
        res = json.loads(js.read_text())
        res["npz_sha256"] = hashlib.sha256(data).hexdigest()
        res["checksum"] = content_checksum(res)
        js.write_text(json.dumps(res))


def test_a_runs_prediction_figure_draws_each_demonstration_on_its_own_time(fitted, run_folder, tmp_path, monkeypatch):
    """fig2_prediction stretched the demonstrations to their predictions' time (the units held no other); the units
    now hold each demonstration's own times, and the figure draws each on them, its x axis saying time (s).
    Checkpoints without them (written before) are still plotted, and reused by a resume of the same inputs and
    code, their demonstrations drawn on their predictions' time as the x axis says."""
    import shutil

    _, trials, _ = fitted
    durations = {t.id: t.duration for t in load_trials(trials)}
    drawn = _prediction_drawn(monkeypatch)
    assert main(["plot", str(run_folder), "--out", str(tmp_path / "f"), "--no-pdf"]) == 0
    label, lines = drawn["train"]
    (npz,) = (run_folder / "units").glob("*.npz")
    with np.load(npz) as z:
        ids, pred_t = list(z["train/ids"]), z["train/t"]
    demo_ends = [float(x[-1]) for x in lines[0::2]]  # a demonstration, then its prediction, per trial
    assert label == "time (s)" and demo_ends == pytest.approx([durations[i] for i in ids], rel=1e-6)
    assert [float(x[-1]) for x in lines[1::2]] == pytest.approx(pred_t[:, -1].tolist())

    run = tmp_path / "run"  # a run of before: its units without the demonstrations' times
    shutil.copytree(run_folder, run)
    _units_as_written_before_demonstration_times(run)
    before = {p.name: p.read_bytes() for p in (run / "units").iterdir()}
    assert main(["plot", str(run), "--out", str(tmp_path / "g"), "--no-pdf"]) == 0
    label, lines = drawn["train"]
    assert label == "prediction's time (s); demonstrations scaled to it"
    assert [float(x[-1]) for x in lines[0::2]] == pytest.approx(pred_t[:, -1].tolist())
    table = (run / "table.csv").read_bytes()
    args = ["reproduce", "--data", str(trials), "--quick", "--sections", "1", "--uncertainty", "0", "--max-iter", "1"]
    assert main([*args, "--workers", "1", "--no-progress", "--out", str(run)]) == 0  # resumed: every unit reused
    assert {p.name: p.read_bytes() for p in (run / "units").iterdir()} == before
    assert (run / "table.csv").read_bytes() == table
    assert drawn["train"][0] == "prediction's time (s); demonstrations scaled to it"


def test_a_prediction_figure_without_the_demonstrations_times_says_they_are_scaled():
    """A run's fig2_prediction from units written before they recorded the demonstrations' times: the
    demonstrations are drawn on their predictions' time, which the x axis says (it said time (s), as if it were
    theirs)."""
    import matplotlib.pyplot as plt

    from reachirl.experiments import figures as fg

    t = np.linspace(0.0, 1.1, 5)[None]
    arrays = {"train/t": t, **{f"train/{k}_{v}": np.zeros((1, 5, 2)) for k in ("demo", "pred") for v in ("q", "qd")}}
    fig = fg.plot_prediction(arrays, "train")
    assert fig.axes[2].get_xlabel() == "prediction's time (s); demonstrations scaled to it"
    plt.close(fig)
    fig = fg.plot_prediction({**arrays, "train/demo_t": np.linspace(0.0, 1.0, 5)[None]}, "train")
    assert fig.axes[2].get_xlabel() == "time (s)" and fig.axes[2].get_lines()[0].get_xdata()[-1] == 1.0
    plt.close(fig)
