"""``reachirl reproduce`` end to end on a tiny trials file: files, resume, determinism, local processes,
bad input."""

import json
import tomllib

import numpy as np
import pytest

from folder_locks import held_elsewhere
from reachirl.cli import main
from reachirl.data.trial import save_trials
from reachirl.experiments import datasets
from reachirl.features import FEATURES
from reachirl.io import atomic_write_json


def _same_table(a, b) -> None:
    la, lb = (p.joinpath("table.csv").read_text().splitlines() for p in (a, b))
    assert [x for x in la if x not in lb] == [] and la == lb


ARGS = ["--quick", "--sections", "1", "8", "--max-iter", "3", "--no-progress"]


@pytest.fixture(scope="module")
def trials_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("toy")
    ds = datasets.toy(n_subjects=2, postures=("P2", "P4"), n_trials=4, n_nodes=40, seed=1)
    save_trials(d / "trials.npz", ds.trials)
    atomic_write_json(d / "truth.json", ds.truth)  # virtual subjects: the truth beside the trials
    return d / "trials.npz"


@pytest.fixture(scope="module")
def reference_run(trials_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "out"
    assert main(["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]) == 0
    return out


def test_outputs(reference_run, capsys):
    out = reference_run
    table_csv = (out / "table.csv").read_text()
    assert table_csv.startswith("method,posture,joint,train_1_mean")
    assert {ln.split(",")[1] for ln in table_csv.splitlines()[1:]} == {"P2", "P4", "ALL", "ALL (trials)"}
    md = (out / "table.md").read_text()
    assert "| P2 |" in md and "Training" in md and "DOC failures" in md
    res = json.loads((out / "results.json").read_text())
    for k in (
        "data",
        "protocol",
        "tables",
        "headline",
        "seed_table",
        "doc",
        "units",
        "timing",
        "figures",
        "truth_comparison",
        "all_postures_convention",
    ):
        assert k in res, k
    assert {"data_s", "units_wall_s", "fit_s_sum", "evaluation_s_sum", "figures_s", "report_s"} <= set(res["timing"])
    assert len(res["units"]) == 4 and res["protocol"]["postures_run"] == ["P2", "P4"]
    u = res["units"][0]
    assert {"weights", "history", "sets", "fit", "evaluation"} <= set(u)
    assert u["sets"]["iscv"]["summary"]["n_trials"] == 3
    report = (out / "report.md").read_text()
    figs = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert {
        "fig2_prediction.png",
        "fig3_weights.png",
        "fig4_iscv.png",
        "convergence.png",
        "weights_vs_truth.png",
    } <= set(figs)
    import matplotlib.image as mpimg

    for name in figs:
        img = mpimg.imread(out / "figures" / name)  # decodes: a valid PNG
        h, w = img.shape[:2]
        assert h >= 300 and w >= 400, (name, img.shape)
        ink = np.mean(np.any(img[..., :3] < 0.9, axis=-1))  # share of pixels that are not (near) white
        assert 0.01 < ink < 0.9, (name, ink)  # drawn on, and not a solid block
        assert f"figures/{name}" in report
    assert "seed" in report.lower() and "10.41 ± 3.81" in report  # the seed's own numbers beside ours


def test_resume_gives_the_same_table(trials_file, reference_run, tmp_path, capsys):
    out = tmp_path / "out"
    base = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]
    assert main([*base, "--max-units", "2"]) == 0
    assert "rerun" in capsys.readouterr().err
    assert len(list((out / "units").glob("*.json"))) == 2 and not (out / "table.csv").exists()
    # what a stopped run has already: its options and the finished units' models (once: checkpoints only)
    assert tomllib.loads((out / "run.toml").read_text())["data"] == str(trials_file.resolve())
    units = sorted(p.stem for p in (out / "units").glob("*.json"))
    assert sorted(p.stem for p in (out / "models").glob("*.json")) == units
    assert main(base) == 0
    res = json.loads((out / "results.json").read_text())
    assert len(res["run"]["reused"]) == 2 and len(res["run"]["computed"]) == 2
    # determinism: same seed, same bytes (this run was interrupted and resumed, the reference was not)
    _same_table(out, reference_run)


def test_the_fits_warnings_are_said_on_stderr_at_the_end(trials_file, tmp_path, capsys, caplog):
    """Each fit warning (report.md's notes) is a line of its own on stderr naming its unit, at the end of the run;
    also for a unit reused from its checkpoint, whose fit logged nothing in this run. Only there: a unit computed
    in this run logged it too while it ran, so that it was said twice."""
    out = tmp_path / "out"
    argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", "--quick"]
    argv += ["--sections", "1", "--max-iter", "1", "--no-progress"]  # one iteration: each fit warns of one step
    for reused in (0, 2):  # computed, then every unit reused
        capsys.readouterr()
        caplog.clear()
        assert main(argv) == 0
        err = capsys.readouterr().err.splitlines()
        res = json.loads((out / "results.json").read_text())
        assert len(res["run"]["reused"]) == reused
        said = [f"warning: {u['key']}: {w}" for u in res["units"] for w in u["warnings"]]
        assert len(said) == 2 and all("stopped after one step" in s for s in said), said
        assert err[-2:] == said, err
        assert not [r.getMessage() for r in caplog.records if "stopped after one step" in r.getMessage()]


def test_the_all_pairs_units_failures_flags_and_warnings_are_said_too(trials_file, tmp_path, capsys):
    """The report's notes counted the main table's units only (UE-ADL's every pair: "0 rollouts of 433 solves",
    "0 of 240 predictions", of 24 units' 4227 and 1920), and the other training subjects' fits' flags and warnings
    were said nowhere, neither in report.md nor on stderr. Now a note says them for those units, and stderr names
    each warning with its unit."""
    out = tmp_path / "out"
    argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", "--quick"]
    argv += ["--sections", "1", "--max-iter", "1", "--no-progress", "--iscv", "all-pairs"]
    capsys.readouterr()
    assert main(argv) == 0
    err = capsys.readouterr().err.splitlines()
    units = [json.loads(p.read_text()) for p in sorted((out / "units").glob("*-t*.json"))]
    assert units and all(u["unit"]["train_subject"] for u in units)
    said = [f"warning: {u['key']}: {w}" for u in units for w in u["warnings"]]
    assert said and all(s in err for s in said), (said, err)
    (note,) = [n for n in json.loads((out / "results.json").read_text())["notes"] if "all-pairs units" in n]
    solves = sum(u["fit"]["doc_solves"] for u in units)
    predictions = sum(u["evaluation"]["doc_solves"] for u in units)
    assert f"The {len(units)} all-pairs units" in note and f"of {solves} solves" in note
    assert f"of {predictions} predictions" in note
    assert all(u["key"] in note for u in units if u["flag"] or u["warnings"])
    assert note in (out / "report.md").read_text()


def _files(folder) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_units_model_and_predictions_are_written_as_it_finishes_and_a_reused_units_at_the_end(
    trials_file, tmp_path, monkeypatch
):
    """While the other units run, not after the last: what the end of the run writes is what was left. A rerun
    that reuses every unit writes them all at the end, the same files."""
    from reachirl.experiments import report

    seen = []
    real = report.write_predictions

    def at_the_end(run, skip=frozenset()):
        there = {d.name for d in (run.out_dir / "predictions").iterdir() if (d / "index.csv").is_file()}
        seen.append((set(skip), there, {p.stem for p in (run.out_dir / "models").glob("*.json")}))
        return real(run, skip)

    monkeypatch.setattr(report, "write_predictions", at_the_end)
    out = tmp_path / "out"
    argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]
    assert main(argv) == 0
    keys = {p.stem for p in (out / "units").glob("*.json")}
    assert len(keys) == 4 and seen[0] == (keys, keys, keys)
    first = {k: _files(out / k) for k in ("predictions", "models")}
    assert main(argv) == 0  # every unit reused: nothing written until the end, then all of it
    assert seen[1][:2] == (set(), set())  # (the models, written just before the predictions, are there)
    assert {k: _files(out / k) for k in ("predictions", "models")} == first


def test_a_run_interrupted_while_writing_its_outputs_never_looks_finished(
    trials_file, reference_run, tmp_path, monkeypatch
):
    """Ctrl-C while the outputs are written (here: during the predictions' exports) leaves no table, report or
    results.json, not even the previous run's in the same folder; rerunning writes them all."""
    import shutil

    from reachirl.experiments import report

    out = tmp_path / "out"
    shutil.copytree(reference_run, out)  # a finished run: every unit is reused
    finished = ("table.md", "table.csv", "report.md", "results.json")
    assert all((out / f).exists() for f in finished)

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "write_predictions", interrupted)
    argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]
    assert main(argv) == 130
    assert not any((out / f).exists() for f in finished)
    monkeypatch.undo()
    assert main(argv) == 0
    _same_table(out, reference_run)


def test_an_interrupt_inside_an_atomic_write_leaves_no_temporary(trials_file, tmp_path, monkeypatch):
    """Ctrl-C just after an atomic write made its temporary and before its own cleanup could run (here: as the
    temporary's permissions are set, the first unit's checkpoint being written) leaves no temporary in the run's
    folders."""
    import os

    from reachirl import io

    chmod = os.chmod

    def interrupted(path, mode, *args, **kwargs):
        if str(path).endswith(".tmp") and f"{os.sep}units{os.sep}" in str(path):
            raise KeyboardInterrupt
        return chmod(path, mode, *args, **kwargs)

    monkeypatch.setattr(io.os, "chmod", interrupted)
    out = tmp_path / "out"
    argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]
    assert main(argv) == 130
    assert (out / "units").is_dir()
    assert [p.name for p in out.rglob(".*") if p.is_file()] == []


def test_a_run_that_swallows_an_interrupt_is_ended_outright_and_leaves_no_temporary(trials_file, tmp_path):
    """A SIGINT that code swallows and runs on after (as compiled solvers can), here while the first unit's
    checkpoint is synced: the command is ended outright after the grace period, and the temporary that write had
    made is removed first, as the command's own cleanup would have."""
    from children import interrupted_while_syncing

    out, marker = tmp_path / "out", tmp_path / "syncing"
    argv = ["reproduce", "--data", trials_file, "--out", out, "--workers", "1", *ARGS]
    unit_checkpoint = "path.name.endswith('.tmp') and path.parent.name == 'units'"
    rc, err = interrupted_while_syncing(argv, unit_checkpoint, marker, out / "units")
    assert rc == 130, err
    assert [f.name for f in out.rglob(".*") if f.is_file()] == []


def test_the_tables_are_written_last(trials_file, reference_run, tmp_path, monkeypatch, capsys):
    """Ctrl-C once the report and results.json are written: still no table, so the folder reads as unfinished."""
    import shutil

    from reachirl.experiments import report

    out = tmp_path / "out"
    shutil.copytree(reference_run, out)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "write_tables", interrupted)
    argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]
    assert main(argv) == 130
    assert (out / "results.json").is_file() and (out / "report.md").is_file()
    assert not (out / "table.csv").exists() and not (out / "table.md").exists()
    capsys.readouterr()
    for cmd in (
        ["plot", str(out), "--out", str(tmp_path / "f")],
        ["sensitivity", str(out), "--out", str(tmp_path / "s")],
    ):
        assert main(cmd) == 2  # and the commands that read a finished run say it is not one
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "no table.csv" in err[0], err


def test_a_rerun_with_other_options_stopped_early_leaves_no_earlier_results(trials_file, reference_run, tmp_path):
    """A rerun into a finished run's folder with other options, stopped before its end (here by --max-units; an
    interrupt stops at the same place), leaves neither the earlier tables nor its unit models beside the new
    run.toml: the folder reads as unfinished."""
    import shutil

    out = tmp_path / "out"
    shutil.copytree(reference_run, out)
    mine = next((out / "predictions").iterdir()) / "my_notes.txt"
    mine.write_text("keep")  # a file of the user's own beside an export: it stays
    argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]
    assert main([*argv, "--seed", "1", "--max-units", "1"]) == 0
    assert tomllib.loads((out / "run.toml").read_text())["seed"] == 1
    finished = ("table.md", "table.csv", "report.md", "results.json")
    assert not any((out / f).exists() for f in finished)
    assert not list((out / "figures").glob("fig*.png"))
    assert mine.read_text() == "keep"
    models = [json.loads(p.read_text())["info"] for p in (out / "models").glob("*.json")]
    assert len(models) == 1  # only the new run's finished unit (the earlier run wrote 4), and its predictions
    exports = sorted(d.name for d in (out / "predictions").iterdir() if (d / "index.csv").is_file())
    assert exports == [models[0]["unit"]]
    others = [p for p in (out / "predictions").rglob("*") if p.is_file() and p.parent.name != exports[0]]
    assert others == ([] if mine.parent.name == exports[0] else [mine])  # no earlier export's file
    assert main(argv) == 0  # and back to the earlier options: its units are still checkpointed, reused
    _same_table(out, reference_run)


def test_a_rerun_into_the_folder_of_another_run_leaves_none_of_its_outputs(trials_file, reference_run, tmp_path):
    """A run with more methods once left its methods figure, models and predictions beside the new run's; the
    checkpoints stay (to be reused), and so does a file reachirl never writes."""
    import shutil

    out = tmp_path / "out"
    shutil.copytree(reference_run, out)
    stale = [
        out / "figures" / "methods.png",
        out / "models" / "kkt-P2-s1.json",
        out / "predictions" / "kkt-P2-s1",
        out / "iscv_pairs.csv",
        out / "posture_transfer.csv",
    ]
    stale[0].write_bytes(b"old")
    a_model = json.loads(next((out / "models").glob("*.json")).read_text())
    stale[1].write_text(json.dumps({**a_model, "info": {**a_model["info"], "unit": "kkt-P2-s1"}}))
    stale[2].mkdir()
    (stale[2] / "index.csv").write_text("id,file,set\n")
    stale[3].write_text("old pairs\n")
    stale[4].write_text("old transfer\n")
    mine = [out / "figures" / "my_sketch.png", out / "units" / "kkt-P2-s1.json", out / "models" / "notes.json"]
    for f in mine:
        f.write_text("keep")
    # a model of the user's own (reachirl fit writes no info.unit) in the models folder is theirs, not the run's
    own = out / "models" / "my_fit.json"
    own.write_text(json.dumps({**a_model, "info": {k: v for k, v in a_model["info"].items() if k != "unit"}}))
    assert main(["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]) == 0
    assert not any(f.exists() for f in stale) and all(f.read_text() == "keep" for f in mine)
    models = [sorted(p.name for p in (d / "models").iterdir()) for d in (out, reference_run)]
    assert models[0] == sorted([*models[1], "my_fit.json", "notes.json"]) and own.is_file()


def test_local_processes_equal_in_process(trials_file, reference_run, tmp_path):
    out = tmp_path / "out"
    assert main(["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "2", *ARGS]) == 0
    _same_table(out, reference_run)


def test_report_compares_the_fits_predictions_with_the_true_weights(trials_file, reference_run):
    """Virtual subjects: results.json holds, per posture and set, how far the 8-section fit's predictions lie
    from the true weights' own; recomputed here from the unit's weights and the truth, DOC by DOC."""
    from reachirl import ReachingTask, solve_doc
    from reachirl.data.trial import load_trials

    res = json.loads((reference_run / "results.json").read_text())
    agree = res["truth_comparison"]["P2"]["predictions"]
    assert set(agree) == {"train", "cv", "iscv"}
    unit = next(u for u in res["units"] if u["unit"]["posture"] == "P2" and u["unit"]["sections"] == 8)
    truth = json.loads(trials_file.with_name("truth.json").read_text())
    w_true = np.array(truth["truth"]["nominal_weights"])
    by_id = {t.id: t for t in load_trials(trials_file)}
    n = unit["unit"]["n_nodes"]
    for name, got in agree.items():
        mine = []
        for e in unit["sets"][name]["trials"]:
            task = ReachingTask.from_trial(by_id[e["id"]], n)  # toy trials are DOC reaches: not cut, seen whole
            a, b = solve_doc(task, np.array(unit["weights"])).q, solve_doc(task, w_true).q
            mine.append(np.rad2deg(np.sqrt(np.mean((a - b) ** 2))))
        assert got["n"] == len(mine)
        assert got["learned_vs_true_deg"] == pytest.approx(np.mean(mine), abs=2e-3)
    assert "from the true weights' own" in (reference_run / "table.md").read_text()


def test_the_report_names_each_postures_onset_and_end_features_as_results_json_has_them(reference_run):
    """The report listed the dominant features at onset and end as one alphabetical set over every posture and
    both ends, so a truth of joint acceleration at onset and torque change at the end read the other way round;
    results.json gave the dominant features but not the true shares the intervals are set beside."""
    res = json.loads((reference_run / "results.json").read_text())
    report = (reference_run / "report.md").read_text()
    assert res["truth_comparison"]
    for p, m in res["truth_comparison"].items():
        ends = [m[k][i] for i in (0, -1) for k in ("true_dominant", "learned_dominant")]
        assert f"| {p} | " + " | ".join(ends) + " |" in report
        true, learned = np.array(m["true_shares"]), np.array(m["learned_shares"])
        assert true.shape == learned.shape == (m["sections"], 7)
        assert np.allclose(true.sum(axis=1), 1.0) and np.allclose(learned.sum(axis=1), 1.0)
        assert [FEATURES[j] for j in true.argmax(axis=1)] == m["true_dominant"]
        tv = np.mean(0.5 * np.abs(true - learned).sum(axis=1))
        assert tv == pytest.approx(m["mean_total_variation"], abs=1e-12)
    assert "| posture | onset: true | onset: learned | end: true | end: learned |" in report


def test_figure_captions_of_a_run_without_weight_samples_promise_no_hatching(trials_file, tmp_path):
    """`--uncertainty 0`: the captions of weights_vs_truth.png said "The hatching marks the learned shares whose
    95 % interval ..." and fig3's "the shares the 95 % intervals bracket", over figures with neither."""
    out = tmp_path / "out"
    args = ["--quick", "--sections", "8", "--postures", "P2", "--max-iter", "1", "--uncertainty", "0"]
    assert main(["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *args]) == 0
    figures = json.loads((out / "results.json").read_text())["figures"]
    truth, weights = figures["figures/weights_vs_truth.png"], figures["figures/fig3_weights.png"]
    assert "Nothing is hatched: the fits shown have no weight samples" in truth and "hatching marks" not in truth
    assert "intervals bracket" not in weights and "Nothing is hatched" in weights
    report = (out / "report.md").read_text()
    assert "hatching marks" not in report and "intervals bracket" not in report


def test_rollout_and_merit_model_options_reach_the_estimator(trials_file, reference_run, tmp_path):
    """``rollout = per_demo`` gives each demonstration its own training rollout: the fit's first iteration
    solves one DOC per training trial (one task's rollout, the default, solves one); the unit records it and the
    run file's ``[experimental]`` merit model."""
    out = tmp_path / "out"
    run = tmp_path / "run.toml"
    run.write_text('rollout = "per_demo"\ntol = 3e-4\n\n[experimental]\nmerit_model = "gauss-newton"\n')
    assert (
        main(
            [
                "reproduce",
                "--data",
                str(trials_file),
                "--out",
                str(out),
                "--workers",
                "1",
                *ARGS,
                "--sections",
                "1",
                "--postures",
                "P2",
                "--config",
                str(run),
            ]
        )
        == 0
    )
    (unit,) = json.loads((out / "results.json").read_text())["units"]
    ref = next(
        u
        for u in json.loads((reference_run / "results.json").read_text())["units"]
        if u["unit"]["posture"] == "P2" and u["unit"]["sections"] == 1
    )
    n_train = json.loads((out / "results.json").read_text())["split_sizes"]["train"]["P2"]
    assert n_train > 1
    assert ["rollout", "per_demo"] in unit["unit"]["estimator_options"]
    assert ["experimental", [["merit_model", "gauss-newton"]]] in unit["unit"]["estimator_options"]
    assert unit["unit"]["tol"] == 3e-4 and ref["unit"]["tol"] is None
    assert ["rollout", "per_task"] in ref["unit"]["estimator_options"]
    assert unit["history"][0]["doc_solves"] == n_train and ref["history"][0]["doc_solves"] == 1
    # the run's own run file keeps the table, and says the options it leaves out are at their defaults
    own = (out / "run.toml").read_text()
    assert tomllib.loads(own)["experimental"] == {"merit_model": "gauss-newton"}
    assert "[experimental]: every one not in its table at the method's default" in own


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--data", "{tmp}/missing.npz"], "no such file"),
        (["--data", "{tmp}/empty.npz"], "empty.npz"),
        # what the data cannot give the protocol names the data
        (["--data", "{trials}", "--postures", "P9"], "{trials}: unknown posture"),
        (["--data", "{trials}", "--train-subject", "S99"], "{trials}: unknown training subject"),
        (["--data", "{trials}", "--train-side", "left"], "{trials}: posture P2: no training trials of subject"),
        (["--data", "{trials}", "--method", "magic"], "unknown method"),
    ],
)
def test_bad_input_exits_2_with_one_line(trials_file, tmp_path, capsys, extra, message):
    (tmp_path / "empty.npz").write_bytes(b"")
    extra = [e.format(tmp=tmp_path, trials=trials_file) for e in extra]
    message = message.format(trials=trials_file.resolve())
    code = main(["reproduce", "--out", str(tmp_path / "out"), "--no-progress", *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1, err


def test_bad_usage_exits_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["reproduce", "--sections", "0"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "reachirl reproduce: error: argument --sections: expected an integer in [1, 1000], got 0" in err, err


@pytest.mark.slow
def test_quick_on_builtin_data(tmp_path):
    """`reproduce --quick` on the built-in virtual subjects (generates the cached data set on first use)."""
    out = tmp_path / "out"
    assert main(["reproduce", "--quick", "--out", str(out), "--no-progress"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["data"]["kind"] == "builtin" and res["protocol"]["postures_run"] == ["P2", "P4"]
    assert (out / "figures" / "weights_vs_truth.png").exists()


@pytest.mark.parametrize("tol", ["0.7", "0.5"])
def test_a_bad_tol_is_refused_before_any_work(tmp_path, capsys, tol):
    """0.5 is out too (the threshold must lie below 0.5), and the flag's message says so: it read [0, 0.5]."""
    with pytest.raises(SystemExit) as e:
        main(["reproduce", "--tol", tol, "--out", str(tmp_path / "o")])
    assert e.value.code == 2
    assert (
        capsys.readouterr().err
        == f"reachirl reproduce: error: argument --tol: expected a number in [0, 0.5), got {tol}\n"
    )
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "name", ["report.md", "table.csv", "run.toml", "figures/fig2_prediction.png", "models/moirl-P2-s1.json"]
)
def test_a_folder_of_the_users_own_is_not_cleared_as_an_earlier_run(trials_file, tmp_path, capsys, name):
    """--out of the user's own holding a file the run replaces or removes (report.md, a table, a run.toml no run
    wrote; a figure or model of the user's in the run's folders, which the run removed or replaced): refused before
    any work, the file left as it was. An earlier run's folder is still rerun into."""
    out = tmp_path / "mine"
    (out / name).parent.mkdir(parents=True)
    (out / name).write_text("my own notes\n")
    code = main(["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"{name}: --out: exists in a folder that holds no earlier `reachirl reproduce` run" in err[0]
    assert (out / name).read_text() == "my own notes\n"
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()) == [name]


@pytest.mark.parametrize("inside", ["units", "models/new", "predictions"])
def test_a_run_inside_another_runs_own_folders_is_refused(trials_file, reference_run, capsys, inside):
    """`reproduce --out RUN/units` nested a whole run among another run's checkpoints (plot and sensitivity refuse
    such an --out)."""
    out = reference_run / inside
    before = sorted(p.name for p in (reference_run / inside.split("/")[0]).iterdir())
    code = main(["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"--out is inside the run's own {inside.split('/')[0]}/ folder" in err[0], err
    assert sorted(p.name for p in (reference_run / inside.split("/")[0]).iterdir()) == before


def test_a_run_toml_given_as_config_is_not_taken_for_the_users_own_file(trials_file, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.toml").write_text(f'data = "{trials_file}"\n')
    code = main(["reproduce", "--config", str(out / "run.toml"), "--out", str(out), "--workers", "1", *ARGS])
    err = capsys.readouterr().err
    assert code == 2 and "--config is this run folder's own run.toml, and the options given change it" in err, err


@pytest.mark.parametrize("toml", ["removed", "header_edited_out"])
def test_an_earlier_runs_folder_is_rerun_into_without_its_run_toml_header(trials_file, reference_run, tmp_path, toml):
    """A run's folder whose run.toml is gone (a version that wrote none) or lost its comment lines to an edit is
    still an earlier run's (its results.json says so): rerunning into it (`make run`) is not refused."""
    import shutil

    out = tmp_path / "out"
    shutil.copytree(reference_run, out)
    run_toml = out / "run.toml"
    if toml == "removed":
        run_toml.unlink()
        argv = ["--data", str(trials_file), *ARGS]
    else:
        run_toml.write_text("".join(x for x in run_toml.read_text().splitlines(True) if not x.startswith("#")))
        argv = ["--config", str(run_toml), "--no-progress"]
    assert main(["reproduce", *argv, "--out", str(out), "--workers", "1"]) == 0
    _same_table(out, reference_run)


def test_a_units_checkpoint_has_its_models_info(trials_file, tmp_path, monkeypatch):
    """A checkpoint's model_info lacked the keys its models/<key>.json info has (backend, unit, run); now it has
    them all, with the same values, the run folder absolute though --out was given relative."""
    monkeypatch.chdir(tmp_path)
    argv = ["reproduce", "--data", str(trials_file), "--out", "out", "--workers", "1", "--quick"]
    assert main([*argv, "--sections", "1", "--max-iter", "1", "--no-progress"]) == 0
    out = (tmp_path / "out").resolve()
    keys = sorted(p.stem for p in (out / "units").glob("*.json"))
    assert keys
    for key in keys:
        kept = json.loads((out / "units" / f"{key}.json").read_text())["model_info"]
        info = json.loads((out / "models" / f"{key}.json").read_text())["info"]
        assert sorted(kept) == sorted(info), key
        assert kept["unit"] == info["unit"] == key
        assert kept["backend"] == info["backend"] == "casadi"
        assert kept["run"] == info["run"] == str(out)


def test_a_run_folder_moved_and_rerun_gives_its_models_the_folder_it_is_in_now(trials_file, tmp_path):
    """`mv RUN RUN2` then `reproduce --out RUN2`: the units are reused, and their models (and results.json) name
    RUN2 nowhere RUN; only the checkpoints keep the folder they were computed in, as outputs.md says."""
    argv = ["--data", str(trials_file), "--workers", "1", "--quick", "--sections", "1", "--max-iter", "1"]
    first, moved = tmp_path / "first", tmp_path / "moved"
    assert main(["reproduce", *argv, "--out", str(first), "--no-progress"]) == 0
    first.rename(moved)
    assert main(["reproduce", *argv, "--out", str(moved), "--no-progress"]) == 0
    res = json.loads((moved / "results.json").read_text())
    assert res["run"]["reused"] and not res["run"]["computed"]
    assert str(first) not in (moved / "results.json").read_text()
    for key in res["run"]["reused"]:
        assert json.loads((moved / "models" / f"{key}.json").read_text())["info"]["run"] == str(moved.resolve())
        assert json.loads((moved / "units" / f"{key}.json").read_text())["model_info"]["run"] == str(first.resolve())


def test_a_second_run_into_a_folder_in_use_is_refused_before_it_changes_anything(
    trials_file, reference_run, tmp_path, capsys
):
    """Two runs into one folder at once: the second is refused (exit 2) before it touches the folder (it removed
    the first one's temporaries and results and wrote its own run.toml beside the tables the first one then
    wrote); once the first has ended, even killed, the folder is free again."""
    import shutil

    from reachirl.errors import InputError

    out = tmp_path / "out"
    shutil.copytree(reference_run, out)
    (out / ".table.csv.abcd1234.tmp").write_text("being written by the run that holds the folder")
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    with held_elsewhere(out):  # another run holding the folder, as reproduce holds it
        argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", *ARGS]
        assert main([*argv, "--seed", "1"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [  # whichever command holds it (it said "another reachirl reproduce", whatever held it)
            f"reachirl reproduce: error: {out}: --out: another reachirl command is writing into this folder now; "
            "wait for it to end, or choose another --out"
        ]
        assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
        from reachirl.io import hold_folder

        with pytest.raises(InputError, match=r"--out: another reachirl command is writing into this folder now"):
            hold_folder(out)
    (out / ".table.csv.abcd1234.tmp").unlink()
    assert main(argv) == 0  # the killed holder's lock went with it
    _same_table(out, reference_run)


def test_virtual_subjects_without_the_truths_section_count_say_why_nothing_is_compared(trials_file, tmp_path):
    """`synth --truth cost.csv` of 4 rows, then `reproduce` at its default 1 6 8 sections: the report had no
    learned-vs-true section and no weights_vs_truth.png, and said nowhere why. Now it says which section count the
    comparison needs."""
    out = tmp_path / "out"
    argv = ["reproduce", "--data", str(trials_file), "--out", str(out), "--workers", "1", "--quick"]
    assert main([*argv, "--sections", "1", "--max-iter", "1", "--no-progress"]) == 0
    report = (out / "report.md").read_text()
    assert not (out / "figures" / "weights_vs_truth.png").exists()
    section = report.split("## Virtual subjects: learned vs true weights", 1)[1].split("\n## ", 1)[0]
    assert "the true cost (truth.json) has 8 windows and this run's section counts are 1" in section, section
    assert "`--sections 8`" in section


def test_the_weight_samples_time_is_said_as_part_of_the_fits(reference_run):
    """The weight samples take up to half a run's fit time; the timing said nothing of it, nor of how to skip them."""
    from reachirl.cli.reproduce import _timing_line

    timing = json.loads((reference_run / "results.json").read_text())["timing"]
    units = [json.loads(f.read_text()) for f in (reference_run / "units").glob("*.json")]
    own = [u["uncertainty"]["time_s"] for u in units]
    assert len(own) == 4 and all(0 < t < u["fit"]["time_s"] for t, u in zip(own, units, strict=True))
    assert timing["uncertainty_s_sum"] == pytest.approx(sum(own), rel=1e-9)
    assert 0 < timing["uncertainty_s_sum"] < timing["fit_s_sum"]
    line = _timing_line(timing)
    assert f"of which weight samples {timing['uncertainty_s_sum']:.1f} s;" in line
    assert line.endswith("; --uncertainty 0 draws no weight samples")
    assert "weight samples" not in _timing_line({**timing, "uncertainty_s_sum": 0.0})
