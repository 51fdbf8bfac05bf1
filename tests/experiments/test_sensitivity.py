"""``reachirl sensitivity`` and its parts: masked MO-IRL refits, weight sensitivity, identifiability."""

import csv
import json

import numpy as np
import pytest

from folder_locks import held_elsewhere, is_free
from reachirl.errors import InputError
from reachirl.experiments import datasets
from reachirl.experiments.protocol import ProtocolConfig, make_units, split_trials
from reachirl.experiments.sensitivity import (
    COLUMNS,
    SETS,
    SensitivityConfig,
    occlusion_job,
    run_sensitivity,
    sensitivity_job,
)
from reachirl.features import FEATURES
from worker_deaths import killed


@pytest.fixture(scope="module")
def toy():
    return datasets.toy(n_subjects=2, postures=("P2",), n_trials=4, n_nodes=20, seed=5)


def test_masked_refit_holds_the_occluded_weights(toy):
    config = ProtocolConfig(sections=(2,), n_train=3, n_nodes=20, max_iter=3)
    split = split_trials(toy.trials, "P2", config)
    unit = make_units(["P2"], config)[0]
    removed = occlusion_job(unit, split, (3,), ())
    w = np.asarray(removed["weights"])
    assert np.all(w[:, 3] == 0) and np.all(w[:, [0, 1, 2, 4, 5, 6]] > 0)
    assert set(removed["rmse"]) == {"train", "cv", "iscv"} and len(removed["rmse"]["iscv"]) == 4
    frozen = occlusion_job(unit, split, (), (0,))
    wf = np.asarray(frozen["weights"])
    from reachirl.irl.objective import feature_scale

    phi = np.stack([t.features(20, 2) for t in split.train])
    np.testing.assert_allclose(wf[0], 0.05 / feature_scale(phi)[0], rtol=1e-12)  # window 1 kept ω₀
    if frozen["flag"] != "w0":
        assert not np.allclose(wf[1], 0.05 / feature_scale(phi)[1])  # window 2 learned


def test_sensitivity_grows_with_the_change(toy):
    trials = [t for t in toy.trials if t.subject == "S01"][:2]
    w = np.array([[0.05, 0.5, 0.05, 3.0, 0.2, 0.05, 0.5]]) / np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])
    small = sensitivity_job(w, trials, 20, "casadi", 0, 2.0)
    big = sensitivity_job(w, trials, 20, "casadi", 0, 20.0)
    j = FEATURES.index("joint_acceleration")
    s = np.mean(small["features"][j]["path_plus"])
    b = np.mean(big["features"][j]["path_plus"])
    assert 0 < s < b and 4 < b / s < 16  # roughly linear in the change


@pytest.fixture(scope="module")
def small_run(recorded, tmp_path_factory, cli):
    """A reproduce run on recorded trials (cut at a speed threshold, as real recordings are)."""
    d = tmp_path_factory.mktemp("sens")
    proc = cli(
        "reproduce",
        "--data",
        recorded / "trials.npz",
        "--sections",
        "1",
        "2",
        "--postures",
        "P2",
        "--nodes",
        "40",
        "--max-iter",
        "3",
        "--n-train",
        "3",
        "--workers",
        "1",
        "--no-progress",
        "--out",
        d / "run",
    )
    assert proc.returncode == 0, proc.stderr
    return d / "run"


def test_cli_writes_one_row_per_feature_and_window(small_run, tmp_path, cli):
    out = tmp_path / "sens"
    proc = cli("sensitivity", small_run, "--out", out, "--workers", "1", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    with open(out / "sensitivity.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(COLUMNS)
    kinds = [r["analysis"] for r in rows]
    assert kinds.count("occlude_feature") == 7 and kinds.count("freeze_window") == 2
    assert kinds.count("sensitivity") == 14
    assert {r["sections"] for r in rows} == {"2"}
    for r in rows:
        if r["analysis"] != "sensitivity":
            # 3 training, 1 CV and 4 ISCV trials: a mean change each, and no set large enough for an interval
            assert all(r[f"{s}_delta_deg"] != "" and r[f"{s}_ci_lo"] == r[f"{s}_ci_hi"] == "" for s in SETS)
            assert r["verdict"] == "too few trials (fewer than 5 in every set)"
        else:
            assert float(r["path_change_deg"]) >= 0
    # each share says whether the fit's weight samples determine it, as the run's intervals do
    unit = next(u for u in json.loads((small_run / "results.json").read_text())["units"] if u["key"] == "moirl-P2-s2")
    determined = unit["uncertainty"]["share_intervals"]["determined"]
    for r in rows:
        if r["analysis"] == "sensitivity":
            want = determined[int(r["window"]) - 1][FEATURES.index(r["feature"])]
            assert r["cost_share_determined"] == str(want)
        elif r["analysis"] == "occlude_feature":
            want = all(row[FEATURES.index(r["feature"])] for row in determined)
            assert r["cost_share_determined"] == str(want)
        else:
            assert r["cost_share_determined"] == ""
    assert (out / "identifiability.json").is_file() and (out / "figures" / "sensitivity_P2.png").is_file()
    ident = json.loads((out / "identifiability.json").read_text())["postures"]["P2"]
    assert ident["determination"]["n_directions"] == 14  # what the training trials determine, not fixed weights
    md = (out / "sensitivity.md").read_text()
    assert "Which costs the data needs" in md and "weight directions determined" in md
    assert "bootstrap" not in md and "fixed" not in md and "nan" not in md and "[too few trials]" in md
    if not all(all(row) for row in determined):
        assert "(undetermined)" in md  # a share the data does not determine is never printed bare


def test_without_occlusion_the_figure_has_the_sensitivity_panel_alone():
    from reachirl.experiments.sensitivity_outputs import plot_sensitivity

    rows = [
        {"posture": "P2", "analysis": "sensitivity", "window": str(w), "feature": f, "path_change_deg": 0.1 * w}
        for w in (1, 2)
        for f in FEATURES
    ]
    fig = plot_sensitivity(rows, "P2")
    titles = [ax.get_title() for ax in fig.axes]
    assert len(titles) == 2 and titles[0].startswith("sensitivity")  # the panel and its colour bar; no blank half


def test_a_posture_named_twice_is_analysed_once():
    """--postures P2 P2 listed P2 twice in sensitivity.md's header (and ran its jobs under one key twice)."""
    assert SensitivityConfig(postures=("P2", "P4", "P2")).postures == ("P2", "P4")


def test_bad_options(small_run, tmp_path, cli):
    with pytest.raises(InputError, match="--percent must be in"):
        SensitivityConfig(percent=0)
    # it said "nothing to do", though the analysis also says what the training trials determine
    with pytest.raises(
        InputError, match=r"leaves only what the training trials determine: that is in the run's models"
    ):
        SensitivityConfig(occlusion=False, sensitivity=False)
    proc = cli("sensitivity", tmp_path, "--out", tmp_path / "o")
    assert proc.returncode == 2 and "no results.json" in proc.stderr
    # each refusal names the run's results.json it read (`reachirl sensitivity RUN --postures P9` named no file)
    with pytest.raises(InputError, match=r"results\.json: --sections 5 was not run"):
        run_sensitivity(small_run, SensitivityConfig(sections=5))
    with pytest.raises(InputError, match=r"results\.json: posture\(s\) P9 were not run"):
        run_sensitivity(small_run, SensitivityConfig(postures=("P9",)))
    with pytest.raises(InputError, match=r"results\.json: --method 'maxent' was not run"):
        run_sensitivity(small_run, SensitivityConfig(method="maxent"))


def test_a_verdict_needs_five_paired_trials_in_a_set():
    from reachirl.experiments.sensitivity import _verdict, paired_interval

    assert np.isnan(paired_interval([0.3, 0.4])[1])  # two of the same sign are no 95 % finding
    m, lo, hi = paired_interval([0.3, 0.4, 0.35, 0.5, 0.45])
    assert m == pytest.approx(0.4) and 0.3 <= lo < m < hi <= 0.5
    row = {}
    for s, d in (("cv", [0.3, 0.4]), ("iscv", [0.3, 0.4, 0.35, 0.5, 0.45]), ("train", [-0.1] * 6)):
        row[f"{s}_delta_deg"], row[f"{s}_ci_lo"], row[f"{s}_ci_hi"] = paired_interval(d)
    assert _verdict(row) == "needed (iscv)"  # the CV set is passed over, not read as a finding
    row["iscv_ci_lo"] = row["iscv_ci_hi"] = row["train_ci_lo"] = row["train_ci_hi"] = float("nan")
    assert _verdict(row) == "too few trials (fewer than 5 in every set)"


def test_effect_collinearity_finds_weights_that_move_the_path_alike():
    from reachirl.experiments.sensitivity import _effect_collinearity

    base = np.linspace(0, 1, 10)
    feats = [{"displacement": np.sin(k * base + k)} for k in range(7)]
    feats[4] = {"displacement": -2.0 * feats[3]["displacement"]}  # opposite direction, other magnitude
    found = _effect_collinearity({("P2", "sensitivity", 0): {"features": feats}}, "P2", 1)
    pair = [e for e in found if e["features"] == ["joint_acceleration", "torque_change"]]
    assert pair and pair[0]["cos"] == pytest.approx(-1.0) and pair[0]["window"] == 1


def test_the_path_change_is_the_compared_predictions_so_it_bounds_the_rmse_change(recorded):
    """Trials cut at a speed threshold are compared as recorded, between the prediction's own crossings of it.
    The path change was measured on the whole DOC, while the RMSE is taken on the part seen: a 10 % weight change
    moved the DOC by 0.03° and the compared prediction by 3° (its offset where the speed lingers near the
    threshold), so the table showed an RMSE change of 0.75° beside a path change of 0.03°. Measured on the same
    prediction, the path change bounds each trial's RMSE change (the triangle inequality)."""
    from reachirl.data.trial import load_trials, select_trials
    from reachirl.irl.moirl import MOIRL

    trials = select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])
    assert all(t.onset_threshold is not None for t in trials)  # cut, as recordings are
    w = MOIRL(8, n_nodes=40, max_iter=3).fit(trials[:3]).weights_
    out = sensitivity_job(w, trials[3:], 40, "casadi", 7, 10.0, observe=True)  # the last window: the offset
    base = np.array(out["base"])
    for rec in out["features"]:
        for name in ("plus", "minus"):
            change = np.abs(np.array(rec[name]) - base)
            assert np.all(change <= np.array(rec[f"path_{name}"]) + 1e-9), (change, rec[f"path_{name}"])


def test_a_failed_non_finite_prediction_moves_no_path_and_keeps_nan_out_of_effect_collinearity(monkeypatch):
    """A +x % prediction whose DOC failed with a non-finite path: its trial's displacement is zeros (times 0 it
    would be NaN, which makes the feature's norm NaN and drops it from every collinear pair), the others' as
    solved."""
    from types import SimpleNamespace

    from reachirl.experiments import sensitivity
    from reachirl.experiments.sensitivity import _effect_collinearity

    j, tc = FEATURES.index("joint_acceleration"), FEATURES.index("torque_change")
    rng = np.random.default_rng(0)
    patterns = rng.normal(size=(2, 7, 21, 2))  # per trial and feature: how a weight's change moves the path
    patterns[:, tc] = -2.0 * patterns[:, j]  # torque change moves it against joint acceleration

    def per_trial(weights, trials, n_nodes, backend, warm=None, observe=False):
        sols = [SimpleNamespace(q=np.einsum("j,jkl->kl", weights[0], patterns[i]), converged=True) for i in range(2)]
        if warm is not None and max(weights[0, j], weights[0, tc]) > 1:  # their +x %: trial 1's DOC fails
            sols[1] = SimpleNamespace(q=np.full((21, 2), np.nan), converged=False)
        ok = np.array([s.converged for s in sols])
        return np.zeros(2), sols, sols, ok

    monkeypatch.setattr(sensitivity, "_per_trial", per_trial)
    out = sensitivity_job(np.ones((1, 7)), [None, None], 20, "casadi", 0, 5.0)
    assert out["features"][j]["plus_converged"] == [True, False]
    disp = out["features"][j]["displacement"]
    np.testing.assert_allclose(disp, np.r_[0.05 * patterns[0, j].ravel(), np.zeros(42)], atol=1e-12)
    for k, rec in enumerate(out["features"]):  # the others' +x %: every trial's path moved
        if k not in (j, tc):
            np.testing.assert_allclose(rec["displacement"], 0.05 * patterns[:, k].ravel(), atol=1e-12)
    found = _effect_collinearity({("P2", "sensitivity", 0): out}, "P2", 1)
    pair = [e for e in found if e["features"] == ["joint_acceleration", "torque_change"]]
    assert pair and pair[0]["cos"] == pytest.approx(-1.0)  # on trial 0, the one both moved


def test_an_interrupted_analysis_resumes_where_it_stopped(small_run, tmp_path):
    from reachirl.experiments.sensitivity import job_path
    from reachirl.experiments.sensitivity_outputs import to_csv

    cfg = SensitivityConfig(percent=5.0, occlusion=False)  # the refits are checkpointed alike (the CLI's test)
    whole = run_sensitivity(small_run, cfg, checkpoint_dir=tmp_path / "a")

    seen = []

    def stop_after_two(label, reused):
        seen.append((label, reused))
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sensitivity(small_run, cfg, checkpoint_dir=tmp_path / "b", on_done=stop_after_two)
    assert len(list((tmp_path / "b").glob("*.json"))) == 2
    counts, labels = [], []

    def count(n, reused):
        counts.append((n, reused))

    resumed = run_sensitivity(
        small_run,
        cfg,
        checkpoint_dir=tmp_path / "b",
        on_start=count,
        on_done=lambda label, reused: labels.append((label, reused)),
    )
    n_jobs = 1 + 2  # the determination, and a ±5 % job per window
    assert counts == [(n_jobs, 2)]
    assert [label for label, reused in labels if reused] == [label for label, _ in seen]
    assert to_csv(resumed["rows"]) == to_csv(whole["rows"])  # the same numbers as the run never stopped
    assert resumed["identifiability"] == whole["identifiability"]

    # an edited checkpoint is run again; another --percent reruns the ±X % jobs alone
    path = job_path(tmp_path / "a", "moirl-P2-s2", ("P2", "sensitivity", 0))
    body = json.loads(path.read_text())
    body["result"]["base"][0] += 1.0
    path.write_text(json.dumps(body))
    counts.clear()
    again = run_sensitivity(small_run, cfg, checkpoint_dir=tmp_path / "a", on_start=count)
    assert counts == [(n_jobs, n_jobs - 1)] and to_csv(again["rows"]) == to_csv(whole["rows"])
    run_sensitivity(
        small_run, SensitivityConfig(percent=7.0, occlusion=False), checkpoint_dir=tmp_path / "a", on_start=count
    )
    assert counts[-1] == (n_jobs, 1)  # the determination's


def test_an_interrupted_cli_run_leaves_no_earlier_results(small_run, tmp_path, monkeypatch, capsys):
    from reachirl.cli import main
    from reachirl.experiments import sensitivity

    out = tmp_path / "sens"
    assert main(["sensitivity", str(small_run), "--out", str(out), "--workers", "1", "--no-occlusion"]) == 0
    assert (out / "sensitivity.csv").is_file() and (out / "figures" / "sensitivity_P2.png").is_file()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(sensitivity, "occlusion_job", interrupted)
    assert main(["sensitivity", str(small_run), "--out", str(out), "--workers", "1", "--no-progress"]) == 130
    # the earlier analysis (without occlusion) is gone, not left to pass for this one; its jobs are kept
    assert not (out / "sensitivity.csv").exists() and not (out / "sensitivity.md").exists()
    assert not (out / "figures" / "sensitivity_P2.png").exists()
    assert len(list((out / "checkpoints").glob("moirl-P2-s2-sensitivity-*.json"))) == 2
    monkeypatch.undo()
    capsys.readouterr()
    assert main(["sensitivity", str(small_run), "--out", str(out), "--workers", "1", "--no-occlusion"]) == 0
    assert "3 of 3 jobs reused" in capsys.readouterr().err and (out / "sensitivity.csv").is_file()


def test_a_checkpoint_fingerprint_covers_the_modules_the_jobs_compute_with():
    # a job's checkpoint is reused while these files are unchanged: every DOC/IRL module that MO-IRL, the
    # determination or the DOC backend imports must be among them, else an edit there is never seen
    import ast
    from pathlib import Path

    import reachirl
    from reachirl.experiments.protocol import _UNIT_ENTRIES, source_closure
    from reachirl.experiments.sensitivity import _ANALYSIS_CODE

    root = Path(reachirl.__file__).parent
    covered = {*source_closure(_UNIT_ENTRIES), *_ANALYSIS_CODE}
    needed = set()
    for name in ("irl/moirl.py", "irl/uncertainty.py", "doc/casadi.py", "doc/observation.py"):
        package = Path(name).parent
        for node in ast.walk(ast.parse((root / name).read_text())):
            if isinstance(node, ast.ImportFrom) and node.level and node.module:
                base = package if node.level == 1 else package.parent
                path = (base / node.module.replace(".", "/")).with_suffix(".py").as_posix()
                if path.split("/")[0] in ("doc", "irl") and (root / path).is_file():
                    needed.add(path)
    assert needed and needed - covered == set()


@pytest.mark.parametrize("name", ["checkpoints", "figures"])
def test_a_file_where_a_folder_of_the_analysis_goes_is_refused_before_any_work(tmp_path, capsys, name):
    from reachirl.cli import main

    out = tmp_path / "sens"
    out.mkdir()
    (out / name).write_text("not a folder")
    (out / "sensitivity.csv").write_text("an earlier analysis\n")
    assert main(["sensitivity", str(tmp_path / "no_run"), "--out", str(out), "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.endswith(
        f"{out / name}: exists and is not a folder; sensitivity writes into it (remove it)"
    ), err
    assert (out / "sensitivity.csv").read_text() == "an earlier analysis\n"


def test_a_pooled_verdict_is_shown_with_the_postures_own_and_says_what_its_interval_covers():
    from reachirl.experiments.sensitivity import ALL, _row
    from reachirl.experiments.sensitivity_outputs import _markdown

    shares = np.full((2, 7), 1 / 7)
    rows = []
    for posture, verdict in (
        ("P1", "needed (cv)"),
        ("P2", "not needed (cv)"),
        ("P3", "not needed (cv)"),
        (ALL, "needed (cv)"),
    ):
        row = _row("moirl", posture, 2, "occlude_feature", 0, shares)
        for s in SETS:
            row[f"{s}_delta_deg"], row[f"{s}_ci_lo"], row[f"{s}_ci_hi"] = 0.2, 0.1, 0.3
        row["verdict"] = verdict
        rows.append(row)
    out = {
        "config": {"method": "moirl", "sections": 2, "postures": ["P1", "P2", "P3"], "percent": 10.0},
        "rows": rows,
        "identifiability": {},
    }
    md = "\n".join(_markdown(out))
    (line,) = [x for x in md.splitlines() if x.startswith(f"| {FEATURES[0]} |")]
    assert line.endswith("| needed (cv); postures: not needed 2, needed 1 |")
    assert "given the two fits" in md and "not how uncertain their weights are" in md
    assert f"{ALL} pools every posture's trials" in md
    one = "\n".join(_markdown({**out, "rows": rows[:1], "config": {**out["config"], "postures": ["P1"]}}))
    assert "postures:" not in one and "pools every posture" not in one and "given the two fits" in one


def test_a_verdict_taken_on_few_cv_trials_shows_where_the_iscv_trials_read_otherwise():
    # UE-ADL's recipe has 5 CV trials against 70 ISCV ones: "needed (cv)" alone hid an ISCV interval across 0
    from reachirl.experiments.sensitivity import _row, _verdict
    from reachirl.experiments.sensitivity_outputs import _markdown

    shares = np.full((2, 7), 1 / 7)
    rows = []
    for j, (cv, iscv) in enumerate((((0.1, 0.3), (-0.1, 0.2)), ((0.1, 0.3), (0.05, 0.2)), ((-0.3, -0.1), (0.1, 0.2)))):
        row = _row("moirl", "P1", 2, "occlude_feature", j, shares)
        row["train_delta_deg"], row["train_ci_lo"], row["train_ci_hi"] = 0.0, -0.1, 0.1
        for s, (lo, hi) in (("cv", cv), ("iscv", iscv)):
            row[f"{s}_delta_deg"], row[f"{s}_ci_lo"], row[f"{s}_ci_hi"] = (lo + hi) / 2, lo, hi
        row["verdict"] = _verdict(row)
        rows.append(row)
    out = {"config": {"method": "moirl", "sections": 2, "postures": ["P1"], "percent": 10.0}, "rows": rows}
    md = "\n".join(_markdown({**out, "identifiability": {}}))
    line = {j: next(x for x in md.splitlines() if x.startswith(f"| {FEATURES[j]} |")) for j in range(3)}
    assert line[0].endswith("| needed (cv); iscv: not needed |")
    assert line[1].endswith("| needed (cv) |")  # both sets agree: nothing added
    assert line[2].endswith("| better without (cv); iscv: needed |")


@pytest.mark.parametrize("name", ["identifiability.json", "sensitivity.md", "sensitivity.csv"])
def test_a_folder_of_the_users_own_is_not_cleared_as_an_earlier_analysis(small_run, tmp_path, capsys, name):
    """--out of the user's own holding a file the analysis removes at its start: refused before any work, the file
    left as it was (an earlier analysis's folder is still rerun into: test_an_interrupted_cli_run_...)."""
    from reachirl.cli import main

    out = tmp_path / "mine"
    out.mkdir()
    (out / name).write_text('{"my": "notes"}\n')
    assert main(["sensitivity", str(small_run), "--out", str(out), "--workers", "1", "--no-occlusion"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{name}: --out: exists in a folder that holds no earlier `reachirl sensitivity`" in err[0]
    assert (out / name).read_text() == '{"my": "notes"}\n' and sorted(p.name for p in out.iterdir()) == [name]


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (
            lambda d: d["protocol"].update(sections="abc"),
            r"field 'protocol\.sections': expected a non-empty list of integers",
        ),
        (
            lambda d: d["protocol"].update(methods=[]),
            r"field 'protocol\.methods': expected a non-empty list of strings",
        ),
        (
            lambda d: d["protocol"].update(postures=[], postures_run=[]),
            r"field 'protocol\.postures': expected a non-empty list of strings",
        ),
        (lambda d: d.update(protocol=[1]), r"field 'protocol': expected an object, found list"),
        (lambda d: d.update(data=[1]), r"field 'data': expected an object, found list"),
        (lambda d: d["units"][0].pop("key"), r"field 'units', unit 0: expected a list of objects with a 'key'"),
        # the run was recorded as "None" and analysed
        (
            lambda d: d["protocol"].update(train_subject=None),
            r"field 'protocol': train_subject must name the run's training subject, got None$",
        ),
        # the data moved away: named by the run's record of it, not only by the missing path
        (
            lambda d: d["data"].update(source="/nonexistent/trials.npz"),
            r"the run's data cannot be loaded again \(/nonexistent/trials\.npz: ",
        ),
    ],
)
def test_a_damaged_results_file_is_named_not_an_internal_error(small_run, tmp_path, capsys, change, match):
    import re
    import shutil

    from reachirl.cli import main

    run = tmp_path / "run"
    shutil.copytree(small_run, run)
    d = json.loads((run / "results.json").read_text())
    change(d)
    (run / "results.json").write_text(json.dumps(d))
    out = tmp_path / "sens"
    assert main(["sensitivity", str(run), "--out", str(out), "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(re.escape(f"{run / 'results.json'}: ") + match, err[0]), err
    assert not out.exists()


def test_an_out_folder_below_a_file_is_refused_before_any_work(small_run, tmp_path, capsys):
    """--out FILE/sub: one line saying FILE is a file, before the run is loaded (not an OSError from the first
    write, after the jobs were counted)."""
    from reachirl.cli import main

    (tmp_path / "notes.txt").write_text("mine\n")
    out = tmp_path / "notes.txt" / "sens"
    assert main(["sensitivity", str(small_run), "--out", str(out), "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(f"{out}: --out: {tmp_path / 'notes.txt'} is a file, not a folder"), err
    assert (tmp_path / "notes.txt").read_text() == "mine\n"


@pytest.mark.parametrize("inside", ["units", "figures/analysis"])
def test_an_out_folder_inside_the_runs_own_folders_is_refused(small_run, capsys, inside):
    """--out RUN/units or RUN/figures/x mixed the analysis into the run's checkpoints or figures."""
    from reachirl.cli import main

    before = sorted(p.name for p in (small_run / "units").iterdir())
    out = small_run / inside
    assert main(["sensitivity", str(small_run), "--out", str(out), "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    name = inside.split("/")[0]
    assert len(err) == 1 and err[0].endswith(
        f"{out}: --out is inside the run's own {name}/ folder, which "
        "`reachirl reproduce` writes and reads back; choose another --out for the analysis "
        f"(e.g. {small_run.resolve() / 'sensitivity'})"
    ), err
    assert sorted(p.name for p in (small_run / "units").iterdir()) == before
    assert not (small_run / "figures" / "analysis").exists()


def _drop(path):
    path.unlink()


def _edit(path):
    d = json.loads(path.read_text())
    d["weights"][0][0] *= 2
    path.write_text(json.dumps(d))


@pytest.mark.parametrize(
    ("name", "damage", "match"),
    [
        ("moirl-P2-s2.json", _drop, "missing: the checkpoint of the run's unit moirl-P2-s2"),
        ("moirl-P2-s2.json", _edit, r"its content does not match its checksum \(edited or damaged\): the checkpoint"),
        ("moirl-P2-s2.npz", _drop, "missing: the checkpoint of the run's unit moirl-P2-s2"),
    ],
)
def test_a_damaged_unit_checkpoint_is_named_in_one_line(small_run, tmp_path, capsys, name, damage, match):
    """The analysed unit's checkpoint missing or edited: exit 2 naming that file, and no warning that the unit is
    being recomputed (sensitivity recomputes no unit); a damaged checkpoint of a unit not analysed is no matter."""
    import re
    import shutil

    from reachirl.cli import main

    run = tmp_path / "run"
    shutil.copytree(small_run, run)
    damage(run / "units" / name)
    (run / "units" / "moirl-P2-s1.json").write_text("damaged")  # not analysed: passed over in silence
    out = tmp_path / "sens"
    assert main(["sensitivity", str(run), "--out", str(out), "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(re.escape(f"{run / 'units' / name}: ") + match, err[0]), err
    assert f"rerun `reachirl reproduce` into {run} to recompute it" in err[0]
    assert not out.exists()


def test_a_method_without_determination_still_reports_its_weight_changes_effects():
    """A fit without rollouts (KKT) has no determination, but its ±x % changes ran: the report says which part is
    missing, not that the method has no sensitivity, and lists the effects' collinearity found."""
    from reachirl.experiments.sensitivity_outputs import _markdown

    pair = {"window": 2, "features": ["geodesic", "joint_velocity"], "cos": 0.97}
    out = {
        "config": {"method": "kkt", "sections": 2, "postures": ["P2"], "percent": 10.0},
        "rows": [],
        "identifiability": {
            "P2": {"determination": None, "effect_collinearity": [pair], "key": "kkt-P2-s2", "flag": None}
        },
    }
    (line,) = [x for x in _markdown(out) if x.startswith("- **P2**")]
    assert "no sensitivity" not in line and "not computed for this method" in line
    assert "geodesic–joint_velocity (window 2)" in line  # one window: singular
    out["identifiability"]["P2"]["effect_collinearity"] = [pair, {**pair, "window": 1}]
    (line,) = [x for x in _markdown(out) if x.startswith("- **P2**")]
    assert "geodesic–joint_velocity (windows 2, 1)" in line


def test_a_failed_prediction_is_counted_not_averaged_in(small_run, tmp_path, monkeypatch):
    """A trial whose prediction's DOC failed (a huge RMSE, converged false) is left out of every paired difference
    it is in, and counted (``<set>_doc_failures``, the report); the others' differences are as before."""
    from dataclasses import replace

    from reachirl.doc import observation
    from reachirl.experiments.sensitivity import job_path
    from reachirl.experiments.sensitivity_outputs import _markdown

    unit = json.loads((small_run / "units" / "moirl-P2-s2.json").read_text())
    train = unit["sets"]["train"]["trials"]
    bad = train[0]["id"]
    real = observation.predict

    def failing(trial, weights, n_nodes, threshold, backend="casadi", warm_start=None, path=None):
        sol, seen = real(trial, weights, n_nodes, threshold, backend, warm_start, path)
        if trial.id == bad and warm_start is None:  # a refit's prediction, and the full fit's again (±x % base)
            return replace(sol, converged=False), replace(seen, q=seen.q + 1.0, converged=False)
        return sol, seen

    monkeypatch.setattr(observation, "predict", failing)
    out = run_sensitivity(small_run, SensitivityConfig(percent=5.0), checkpoint_dir=tmp_path)
    base = np.array([e["rmse_deg"]["q"] for e in train])
    rows = [r for r in out["rows"] if r["posture"] == "P2"]
    assert {r["analysis"] for r in rows} == {"occlude_feature", "freeze_window", "sensitivity"}
    for r in rows:
        if r["analysis"] == "sensitivity":
            res = json.loads(job_path(tmp_path, "moirl-P2-s2", ("P2", "sensitivity", int(r["window"]) - 1)).read_text())
            res = res["result"]
            rec = res["features"][FEATURES.index(r["feature"])]
            b = np.asarray(res["base"])
            assert abs(r["plus_delta_deg"]) < 10  # the failed base's ~57° would dominate it
            assert r["plus_delta_deg"] == pytest.approx(np.mean(np.asarray(rec["plus"])[1:] - b[1:]))
            assert r["minus_delta_deg"] == pytest.approx(np.mean(np.asarray(rec["minus"])[1:] - b[1:]))
            assert r["train_doc_failures"] == 1 and r["cv_doc_failures"] is None
            assert res["base_converged"] == [False, True, True]
            continue
        i = FEATURES.index(r["feature"]) if r["analysis"] == "occlude_feature" else int(r["window"]) - 1
        res = json.loads(job_path(tmp_path, "moirl-P2-s2", ("P2", r["analysis"], i)).read_text())["result"]
        assert abs(r["train_delta_deg"]) < 10  # the failed trial's ~57° would dominate it
        assert r["train_delta_deg"] == pytest.approx(np.mean(np.asarray(res["rmse"]["train"])[1:] - base[1:]))
        assert (r["train_doc_failures"], r["cv_doc_failures"], r["iscv_doc_failures"]) == (1, 0, 0)
        assert res["converged"]["train"] == [False, True, True] and all(res["converged"]["iscv"])
        iscv = np.array([e["rmse_deg"]["q"] for e in unit["sets"]["iscv"]["trials"]])
        assert r["iscv_delta_deg"] == pytest.approx(np.mean(np.asarray(res["rmse"]["iscv"]) - iscv))
    md = "\n".join(_markdown(out))
    assert "(1 DOC failure left out)" in md and "nan" not in md


def test_a_set_whose_predictions_all_failed_has_no_delta_and_says_how_many():
    from reachirl.experiments.sensitivity import _converged_pairs, _interval_cells, _row
    from reachirl.experiments.sensitivity_outputs import _ci, to_csv

    d, failed = _converged_pairs([50.0, 60.0, 70.0], [False, True, False], [1.0, 2.0, 3.0], [True, False, True])
    assert d.size == 0 and failed == 3
    row = _row("moirl", "P2", 1, "occlude_feature", 0, np.full((1, 7), 1 / 7))
    row["train_delta_deg"], row["train_ci_lo"], row["train_ci_hi"] = _interval_cells(d, 100, 0)
    row["train_doc_failures"] = failed
    assert (row["train_delta_deg"], row["train_ci_lo"], row["train_ci_hi"]) == (None, None, None)
    assert _ci(row, "train") == "— (3 DOC failures left out)"
    line = dict(zip(COLUMNS, to_csv([row]).splitlines()[1].split(","), strict=True))
    assert line["train_delta_deg"] == "" and line["train_doc_failures"] == "3"
    d, failed = _converged_pairs([5.0, 6.0], None, [1.0, 2.0], [True, True])  # no flags recorded: all converged
    assert d.tolist() == [4.0, 4.0] and failed == 0


def test_a_second_analysis_into_a_folder_in_use_is_refused_before_it_changes_anything(small_run, tmp_path, capsys):
    """Two analyses into one --out at once: the second is refused (exit 2) before it touches the folder (it would
    remove the first one's outputs at its start and mix their checkpoints); once the first has ended, even killed,
    the folder is free again."""

    from reachirl.cli import main

    out = tmp_path / "analysis"
    (out / "checkpoints").mkdir(parents=True)
    (out / "checkpoints" / ".job.abcd1234.tmp").write_text("being written by the analysis that holds the folder")
    argv = ["sensitivity", str(small_run), "--out", str(out), "--workers", "1", "--no-occlusion", "--no-progress"]
    with held_elsewhere(out):  # another analysis holding the folder, as sensitivity holds it
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [  # whichever command holds it (it said "another reachirl sensitivity", whatever held it)
            f"reachirl sensitivity: error: {out}: --out: another reachirl command is writing into this folder now; "
            "wait for it to end, or choose another --out"
        ]
        assert sorted(p.name for p in out.rglob("*")) == [".job.abcd1234.tmp", "checkpoints"]  # untouched
    assert main(argv) == 0  # the killed holder's lock went with it
    assert (out / "identifiability.json").is_file()
    # and this analysis's went at its end (it stayed held until the process ended: a second call in one process,
    # or another process, was refused)
    assert is_free(out)


def test_an_analysis_of_a_run_being_written_is_refused_before_it_changes_anything(small_run, tmp_path, capsys):
    """sensitivity RUN_DIR while a reproduce rewrites RUN_DIR read a run in the middle of its rewriting; it is
    refused (exit 2) before it writes anything, and runs once the writer has ended."""

    from reachirl.cli import main

    out = tmp_path / "analysis"
    argv = ["sensitivity", str(small_run), "--out", str(out), "--workers", "1", "--no-occlusion", "--no-progress"]
    with held_elsewhere(small_run):  # a reproduce running into the run's folder, as it holds it
        assert main(argv) == 2
        assert capsys.readouterr().err.strip().splitlines() == [
            f"reachirl sensitivity: error: {small_run}: another reachirl command is writing into this folder now; "
            "wait for it to end"
        ]
        assert not any(p.is_file() for p in out.rglob("*"))
    assert main(argv) == 0
    assert (out / "identifiability.json").is_file()


def test_a_killed_job_worker_is_named_with_its_job_and_a_rerun_resumes(small_run, tmp_path, monkeypatch, capsys):
    """It was an internal error (exit 1, 'BrokenProcessPool: A process in the process pool was terminated
    abruptly'): a killed worker is the analysis's circumstance, not a bug."""
    import re

    from reachirl.cli import main
    from reachirl.experiments import sensitivity

    monkeypatch.setattr(sensitivity, "sensitivity_job", killed)  # what the (spawned) workers are given to run
    out = tmp_path / "analysis"
    argv = ["sensitivity", str(small_run), "--out", str(out), "--workers", "2", "--no-occlusion", "--no-progress"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.fullmatch(
        rf"reachirl sensitivity: error: {re.escape(str(out / 'checkpoints'))}: a worker process died \(killed, or "
        r"out of memory\) while running job P2 (determination|sensitivity [12]); finished jobs are kept \(rerun to "
        r"resume\)",
        err[0],
    ), err
    monkeypatch.undo()
    assert main(argv) == 0
    assert (out / "sensitivity.csv").is_file()


def test_a_run_on_a_folder_read_with_markers_is_loaded_again_with_them(tmp_path):
    """A run on a folder of recordings whose marker names needed `reproduce --markers` could not be analysed: the
    data were loaded again without the marker map ('marker shoulder not found'). The map is the run's run.toml's."""
    from reachirl.cli import main
    from reachirl.experiments.sensitivity import load_run
    from recordings import MARKERS, synth

    folder = synth(tmp_path / "rec", ("P2",), subjects=2, trials=2)
    (folder / "truth.json").unlink()  # its marker names are then the --markers given
    run = tmp_path / "run"
    argv = ["reproduce", "--data", str(folder), "--markers", MARKERS, "--sections", "1", "--nodes", "20"]
    argv += ["--max-iter", "1", "--n-train", "1", "--uncertainty", "0", "--workers", "1", "--no-progress"]
    assert main([*argv, "--out", str(run)]) == 0
    dataset, _, units, subject = load_run(run)
    assert len(dataset.trials) == 4 and subject == "S01" and list(units) == ["moirl-P2-s1"]
    (run / "run.toml").write_text((run / "run.toml").read_text().replace(f'markers = "{MARKERS}"\n', ""))
    with pytest.raises(InputError, match=r"the run's data cannot be loaded again .*marker 'shoulder'"):
        load_run(run)


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--no-sensitivity", "--percent", "5"], r"--percent sets the sensitivity analysis, which --no-sensitivity"),
        (["--no-occlusion", "--seed", "3"], r"--seed sets the occlusion analysis, which --no-occlusion skips"),
    ],
)
def test_an_option_of_a_skipped_analysis_is_refused_not_ignored(extra, match):
    from reachirl.cli import build_parser
    from reachirl.cli.sensitivity import _check_analysis_options

    parse = build_parser().parse_args
    with pytest.raises(InputError, match=match):
        _check_analysis_options(parse(["sensitivity", "run", "--out", "o", *extra]))
    args = parse(["sensitivity", "run", "--out", "o", extra[0]])
    _check_analysis_options(args)
    assert (args.percent, args.seed) == (10.0, 0)


def test_the_collinear_pairs_say_when_they_are_the_first_few_of_more():
    """sensitivity.md listed the 4 pairs of nearly collinear effects found in most windows as if they were all of
    them (16 pair-windows, 12 pairs in identifiability.json on the quick run's P2). Now it says how many there are
    and where; a list that is whole says nothing more."""
    from reachirl.experiments.sensitivity_outputs import _effects

    pairs = [("a", "b"), ("a", "c"), ("b", "c"), ("c", "d"), ("d", "e"), ("e", "f")]
    items = [{"window": w, "features": list(f), "cos": 0.95} for f in pairs for w in (1, 2)]
    said = _effects(items)
    assert said.count("–") == 4
    assert "these are the 4 in most windows of 6 such pairs (12 with their windows" in said, said
    assert "identifiability.json" in said
    whole = _effects(items[:4])
    assert whole == "a–b (windows 1, 2), a–c (windows 1, 2)", whole


def test_the_sensitivity_figure_names_its_percentage_and_says_when_it_has_no_intervals():
    """sensitivity_<posture>.png titled its panel "path change under ±x % of each weight" (the x never given),
    and its occlusion bars had no whiskers with fewer than 5 trials per set, as if the intervals were too narrow
    to draw (the quick run's 3/3/3 trials)."""
    from reachirl.experiments.sensitivity_outputs import plot_sensitivity

    none = {f"{s}_{k}": None for s in ("train", "cv", "iscv") for k in ("ci_lo", "ci_hi")}
    rows = [
        {"posture": "P2", "analysis": "sensitivity", "window": str(w), "feature": f, "path_change_deg": 0.1 * w}
        for w in (1, 2)
        for f in FEATURES
    ] + [
        {"posture": "P2", "analysis": "occlude_feature", "feature": f, "window": "all", **none}
        | {"train_delta_deg": 0.1, "cv_delta_deg": 0.2, "iscv_delta_deg": -0.1}
        for f in FEATURES
    ]
    fig = plot_sensitivity(rows, "P2", percent=10.0)
    titles = [ax.get_title() for ax in fig.axes]
    assert "sensitivity: path change under ±10 % of each weight (deg)" in titles, titles
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert "no 95 % intervals: fewer than 5 trials in every set" in texts, texts
    with_ci = [r | {"cv_ci_lo": 0.1, "cv_ci_hi": 0.3} if r["analysis"] == "occlude_feature" else r for r in rows]
    assert not [t for ax in plot_sensitivity(with_ci, "P2").axes for t in ax.texts]


def test_occlusion_of_another_method_names_the_method_analysed(small_run, monkeypatch):
    # of a run of moirl and kkt, --method kkt was refused as "the run's method is 'kkt'"
    import dataclasses

    import reachirl.experiments.sensitivity as sens

    real = sens.load_run

    def both(run_dir):
        dataset, config, units, subject = real(run_dir)
        return dataset, dataclasses.replace(config, methods=("moirl", "kkt")), units, subject

    monkeypatch.setattr(sens, "load_run", both)
    with pytest.raises(
        InputError,
        match=r"results\.json: occlusion refits need MO-IRL; the method analysed \(--method\) is 'kkt' \(use "
        r"--no-occlusion, or --method moirl\)$",
    ):
        run_sensitivity(small_run, SensitivityConfig(method="kkt"))
