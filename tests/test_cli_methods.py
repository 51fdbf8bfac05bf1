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
        runs[m] = (cli("fit", tiny_trials, "--sections", "2", "--nodes", "20", "--max-iter", "3",
                                "--method", m, "--out", out), out)
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
    proc = cli("reproduce", "--data", tiny_trials, "--method", *METHODS, "--sections", "1", "2",
                        "--nodes", "20", "--max-iter", "3", "--n-train", "2", "--workers", "1", "--no-progress",
                        "--out", out)
    assert proc.returncode == 0, proc.stderr
    for m in METHODS:
        assert f"{m}: RMSE of the joint angles" in proc.stdout
    res = json.loads((out / "results.json").read_text())
    assert sorted({u["unit"]["method"] for u in res["units"]}) == sorted(METHODS)
    assert len(res["units"]) == 2 * len(METHODS)
