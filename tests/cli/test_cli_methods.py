"""Every advertised command × every IRL method, through the installed ``reachirl`` console script."""

import json

import numpy as np
import pytest

METHODS = ("moirl", "maxent", "bilevel", "kkt")


@pytest.fixture(scope="module")
def models(tiny_trials, tmp_path_factory, cli):
    """``reachirl fit --method M`` for every method; the test below checks each run."""
    d = tmp_path_factory.mktemp("models")
    runs = {}
    for m in METHODS:
        out = d / f"{m}.json"
        limit = [] if m == "kkt" else ["--max-iter", "3"]  # kkt solves once: it refuses --max-iter
        args = ["--sections", "2", "--nodes", "20", *limit, "--method", m, "--out", out]
        runs[m] = (cli("fit", tiny_trials, *args), out)
    return runs


@pytest.mark.parametrize("method", METHODS)
def test_fit_evaluate_simulate(method, models, tiny_trials, tmp_path, cli):
    proc, model = models[method]
    assert proc.returncode == 0, proc.stderr
    assert f"wrote {model}: {method}, 2 section(s)" in proc.stdout
    m = json.loads(model.read_text())
    assert m["method"] == method and np.array(m["weights"]).shape == (2, 7)
    assert m["info"]["n_trials"] == 6

    metrics = tmp_path / "metrics.json"
    proc = cli("evaluate", "--model", model, tiny_trials, "--out", metrics)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(metrics.read_text())
    assert out["summary"]["n_trials"] == 6 and len(out["trials"]) == 6
    assert all(np.isfinite(t["rmse_deg"]["q"]) for t in out["trials"])

    sim = tmp_path / "sim.json"
    proc = cli("simulate", "--model", model, tiny_trials, "--trial", "0", "--out", sim)
    assert proc.returncode == 0, proc.stderr
    assert "S1/P2/right/T0: DOC (casadi)" in proc.stdout
    assert len(json.loads(sim.read_text())["trials"]) == 1


def test_reproduce_every_method(tiny_trials, tmp_path, cli):
    out = tmp_path / "run"
    proc = cli(
        "reproduce",
        "--data",
        tiny_trials,
        "--method",
        *METHODS,
        "--sections",
        "1",
        "2",
        "--nodes",
        "20",
        "--max-iter",
        "3",
        "--n-train",
        "2",
        "--workers",
        "1",
        "--no-progress",
        "--out",
        out,
    )
    assert proc.returncode == 0, proc.stderr
    for m in METHODS:
        assert f"{m} (casadi DOC): RMSE of the joint angles" in proc.stdout
    res = json.loads((out / "results.json").read_text())
    assert sorted({u["unit"]["method"] for u in res["units"]}) == sorted(METHODS)
    assert len(res["units"]) == 2 * len(METHODS)
    # the report: the method run and its departures, the seed's numbers labelled as its own subjects'; one
    # posture gives no paired comparison of section counts (the postures are its samples, not the trials)
    report = (out / "report.md").read_text()
    assert "seed defaults otherwise" not in report and "departure(s) from the paper:" in report
    assert "- **kkt:** a baseline" in report
    assert "(seed's subjects, not comparable)" in report and "chosen at random (seed 0)" in report
    assert res["comparisons"] == {} and "What they show" not in report
    assert res["method"]["moirl"]["departures"] and res["method"]["kkt"] is None
    # each unit's stop reason as its model file gives it (null for KKT, which does not iterate)
    for u in res["units"]:
        model = json.loads((out / "models" / f"{u['key']}.json").read_text())
        assert u["stop_reason"] == model["info"]["stop_reason"], u["key"]
    assert {u["stop_reason"] for u in res["units"] if u["unit"]["method"] == "kkt"} == {None}
    # every trial of every set of every unit is exported (docs/outputs.md)
    for u in res["units"]:
        index = (out / "predictions" / u["key"] / "index.csv").read_text().splitlines()
        n = sum(len(u["sets"][s]["trials"]) for s in ("train", "cv", "iscv"))
        assert index[0] == "id,file,set,converged" and len(index) == 1 + n
        # a prediction whose DOC did not converge is listed with no file (docs/outputs.md)
        rows = [row.split(",") for row in index[1:]]
        assert all((out / "predictions" / u["key"] / f"{r[1]}.mot").is_file() for r in rows if r[3] == "true")
        assert all(r[1] == "" and r[3] == "false" for r in rows if r[3] != "true")

    # reachirl plot RUN_DIR draws the run's figures again, as PNG and PDF
    figs = tmp_path / "figs"
    proc = cli("plot", out, "--out", figs)
    assert proc.returncode == 0, proc.stderr
    for name in ("fig2_prediction", "fig3_weights", "fig4_iscv", "convergence", "methods"):
        assert (figs / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert (figs / f"{name}.pdf").read_bytes()[:5] == b"%PDF-"
        assert f"wrote {figs / name}.png" in proc.stdout


def test_plot_model(models, tiny_trials, tmp_path, cli):
    import matplotlib.image

    _, model = models["moirl"]
    proc = cli("plot", "--model", model, tiny_trials, "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    for name in ("prediction", "weights", "convergence"):
        img = matplotlib.image.imread(tmp_path / f"{name}.png")
        assert img.shape[0] > 300 and img.shape[1] > 300 and img[..., :3].std() > 0.05  # drawn, not blank
        assert (tmp_path / f"{name}.pdf").read_bytes()[:5] == b"%PDF-"
    # kkt has no merit history: no convergence figure, and no error
    _, kkt = models["kkt"]
    proc = cli("plot", "--model", kkt, tiny_trials, "--out", tmp_path / "kkt", "--no-pdf")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "kkt").iterdir()) == ["prediction.png", "weights.png"]


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (lambda d, t: ["plot", d, "--out", d / "o"], "no results.json"),
        (lambda d, t: ["plot", t, "--out", d / "o"], "expected a `reachirl reproduce` folder"),
        (lambda d, t: ["plot", "--model", d / "missing.json", t, "--out", d / "o"], "missing.json: file not found"),
    ],
)
def test_plot_bad_input(args, match, tiny_trials, tmp_path, cli):
    proc = cli(*args(tmp_path, tiny_trials))
    assert proc.returncode == 2 and match in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("option", [["--rollout", "per_demo"], ["--seed-form"], ["--uncertainty", "20"]])
@pytest.mark.parametrize("method", ["kkt", "bilevel"])
def test_moirl_options_are_refused_for_the_other_methods(method, option, tiny_trials, tmp_path, cli):
    """An option a method does not have is refused, not run and left out of its MODEL.json."""
    out = tmp_path / "m.json"
    proc = cli("fit", tiny_trials, "--sections", "2", "--nodes", "20", "--method", method, *option, "--out", out)
    assert proc.returncode == 2 and not out.exists()
    assert f"--seed-form, --uncertainty, --rollout and --config apply to moirl and maxent, not {method}" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_max_iter_limits_bilevel_and_is_refused_for_kkt(models, tiny_trials, tmp_path, cli):
    """--max-iter is the iterations of bilevel's direct search too (not silently ignored); kkt, which solves once,
    refuses it; reproduce refuses it when no method of the run iterates up to it (its max_iter is MO-IRL's)."""
    info = json.loads(models["bilevel"][1].read_text())["info"]
    assert info["parameters"]["max_iter"] == 3 and info["n_iter"] <= 3
    out = tmp_path / "m.json"
    proc = cli("fit", tiny_trials, "--sections", "2", "--method", "kkt", "--max-iter", "3", "--out", out)
    assert proc.returncode == 2 and not out.exists()
    assert (
        proc.stderr.strip()
        == "reachirl fit: error: --max-iter applies to moirl, maxent and bilevel, not kkt, which solves once"
    )
    args = ["reproduce", "--data", tiny_trials, "--sections", "1", "--nodes", "20", "--no-progress"]
    run_file = tmp_path / "run.toml"
    run_file.write_text('methods = ["bilevel", "kkt"]\nmax_iter = 5\n')
    for given, named in (
        (["--method", "kkt", "--max-iter", "5"], "--max-iter 5: --method kkt takes none"),
        (["--method", "bilevel", "--set", "max_iter=5"], "--set: max_iter=5: --method bilevel takes none"),
        (["--config", run_file], f"{run_file}: max_iter = 5: --method bilevel kkt takes none"),
    ):
        proc = cli(*args, *given, "--out", tmp_path / "r")
        assert proc.returncode == 2 and named in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
        assert "(moirl's and maxent's iterations at most;" in proc.stderr
    assert not (tmp_path / "r" / "units").exists()


def test_a_seed_form_changed_by_the_run_file_says_it_departs(tiny_trials, tmp_path, cli):
    run_file = tmp_path / "exp.toml"
    run_file.write_text('[experimental]\nmerit = "normalised"\n')
    out = tmp_path / "m.json"
    # one task (one subject, one posture): the seed form's one rollout, so the run file's merit is the one departure
    args = ["--sections", "2", "--nodes", "20", "--max-iter", "2", "--seed-form", "--subject", "S1"]
    proc = cli("fit", tiny_trials, *args, "--config", run_file, "--out", out)
    assert proc.returncode == 0, proc.stderr
    departures = json.loads(out.read_text())["info"]["departures"]
    assert departures == ["normalised merit: each state channel divided by the demonstrations' spread"]
    assert "moirl (seed form with 1 departure(s) from it: info.departures)" in proc.stdout
    proc = cli("fit", tiny_trials, *args, "--out", out)
    assert proc.returncode == 0 and "moirl (seed form), 2 section(s)" in proc.stdout
    assert json.loads(out.read_text())["info"]["departures"] == []


def test_uncertainty_asked_of_methods_without_samples_is_refused(tiny_trials, tmp_path, cli):
    """As fit --method kkt --uncertainty is: refused, not run with a note; the default (40 samples for the methods
    that draw them) asks nothing, and neither does a run's own run.toml, which records it."""
    args = ["--data", tiny_trials, "--sections", "1", "--nodes", "20", "--n-train", "2", "--workers", "1"]
    out = tmp_path / "k"
    proc = cli("reproduce", *args, "--method", "kkt", "--uncertainty", "40", "--no-progress", "--out", out)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert (
        "--uncertainty 40: --method kkt takes none (weight samples are drawn for moirl and maxent fits only)"
        in proc.stderr
    )
    assert not (out / "units").exists()
    proc = cli("reproduce", *args, "--method", "kkt", "--no-progress", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr and "takes none" not in proc.stderr
    run_toml = (out / "run.toml").read_text()  # what the run computed with: none of MO-IRL's keys (they were there)
    assert all(f"\n{key} =" not in run_toml for key in ("uncertainty", "max_iter", "tol", "seed_form", "rollout"))
    assert "[experimental]" not in run_toml and "tol:" not in run_toml  # nor said to be at its default
    report = (out / "report.md").read_text()
    assert "they are drawn for moirl and maxent fits only" in report
    proc = cli("reproduce", "--config", out / "run.toml", "--no-progress", "--out", out)  # resumed: every unit reused
    assert proc.returncode == 0, proc.stderr
    assert "1 unit(s) already done" in proc.stderr and "takes none" not in proc.stderr


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        (["--seed-form"], "--seed-form: --method kkt takes none (the paper's MO-IRL form)"),
        (["--rollout", "per_demo"], "--rollout per_demo: --method kkt takes none (MO-IRL's and MaxEnt's training"),
        (["--set", "rollout=mean"], "--set: rollout=mean: --method kkt takes none"),
        (["--tol", "0.01"], "--tol 0.01: --method kkt takes none (MO-IRL's and MaxEnt's stopping tolerance)"),
        (["--set", "tol=0"], "--set: tol=0: --method kkt takes none"),
        (["--set", 'experimental={merit = "state"}'], '--set: experimental={merit = "state"}: --method kkt takes none'),
        (["--set", "seed_form=true"], "--set: seed_form=true: --method kkt takes none"),
    ],
)
def test_moirl_options_asked_of_methods_without_them_are_refused(tiny_trials, tmp_path, cli, extra, said):
    """reproduce --method kkt --seed-form ran, and its run.toml recorded seed_form = true though nothing used it;
    fit --method kkt --seed-form refuses it."""
    args = ["--data", tiny_trials, "--sections", "1", "--nodes", "20", "--n-train", "2", "--workers", "1"]
    out = tmp_path / "k"
    proc = cli("reproduce", *args, "--method", "kkt", *extra, "--no-progress", "--out", out)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert said in proc.stderr
    assert not (out / "units").exists()


@pytest.mark.parametrize(
    ("lines", "said"),
    [
        ("tol = 0.01\n", "tol = 0.01: --method kkt takes none (MO-IRL's and MaxEnt's stopping tolerance)"),
        ("seed_form = true\n", "seed_form = true: --method kkt takes none (the paper's MO-IRL form)"),
        ('[experimental]\nmerit = "state"\nobserve = false\n', "[experimental] merit, observe: --method kkt takes"),
    ],
    ids=["tol", "seed_form", "experimental"],
)
def test_a_run_file_asking_moirl_options_of_kkt_alone_is_refused_in_its_own_words(
    tiny_trials, tmp_path, cli, lines, said
):
    """tol and an [experimental] table were taken by a kkt run (and written back into its run.toml), which uses
    neither, while fit --method kkt --config refused them; a value is said as the file wrote it (true, not True)."""
    run_file = tmp_path / "kkt.toml"
    run_file.write_text('methods = ["kkt"]\n' + lines)
    args = ["--data", tiny_trials, "--sections", "1", "--nodes", "20", "--n-train", "2", "--workers", "1"]
    proc = cli("reproduce", *args, "--config", run_file, "--no-progress", "--out", tmp_path / "k")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert f"{run_file}: {said}" in proc.stderr
    assert not (tmp_path / "k" / "units").exists()
