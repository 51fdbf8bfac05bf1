"""docs/outputs.md lists exactly the fields the code writes: each ``<!-- schema: NAME -->`` table is compared
with the keys (JSON), entries (NPZ) or columns (CSV, MOT) of a file written by the real commands."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "outputs.md"


def documented() -> dict[str, list[str]]:
    """``{schema name: [field, ...]}`` from the tables of docs/outputs.md."""
    out: dict[str, list[str]] = {}
    name = None
    for line in DOC.read_text(encoding="utf-8").splitlines():
        m = re.match(r"<!-- schema: (.+?) -->", line)
        if m:
            name = m.group(1)
            out[name] = []
            continue
        if name is None:
            continue
        if line.startswith("|"):
            cell = line.split("|")[1].strip()
            f = re.fullmatch(r"`([^`]+)`", cell)
            if f:
                out[name].append(f.group(1))
        elif out[name]:
            name = None  # the table ended
    return out


@pytest.fixture(scope="module")
def written(tiny_trials, tmp_path_factory, cli):
    d = tmp_path_factory.mktemp("outputs")
    model = d / "model.json"
    proc = cli(
        "fit", tiny_trials, "--sections", "2", "--nodes", "20", "--max-iter", "2", "--uncertainty", "20", "--out", model
    )
    assert proc.returncode == 0, proc.stderr
    proc = cli("evaluate", "--model", model, tiny_trials, "--out", d / "metrics.json", "--predictions", d / "pred")
    assert proc.returncode == 0, proc.stderr
    proc = cli(
        "reproduce",
        "--data",
        tiny_trials,
        "--sections",
        "1",
        "2",
        "--nodes",
        "20",
        "--max-iter",
        "2",
        "--n-train",
        "2",
        "--workers",
        "1",
        "--no-progress",
        "--iscv",
        "all-pairs",
        "--out",
        d / "run",
    )
    assert proc.returncode == 0, proc.stderr
    proc = cli("sensitivity", d / "run", "--no-occlusion", "--workers", "1", "--no-progress", "--out", d / "sens")
    assert proc.returncode == 0, proc.stderr
    proc = cli("simulate", "--model", model, tiny_trials, "--trial", "0", "--out", d / "sim.json")
    assert proc.returncode == 0, proc.stderr
    return d


def _csv_header(path: Path) -> list[str]:
    return path.read_text().splitlines()[0].split(",")


def actual(d: Path) -> dict[str, list[str]]:
    model = json.loads((d / "model.json").read_text())
    metrics = json.loads((d / "metrics.json").read_text())
    res = json.loads((d / "run" / "results.json").read_text())
    unit = res["units"][0]
    with np.load(d / "run" / "units" / f"{unit['key']}.npz", allow_pickle=False) as z:
        npz = sorted({re.sub(r"^(train|cv|iscv)/", "<set>/", k) for k in z.files})
    with np.load(_tiny(d), allow_pickle=False) as z:
        trials = sorted({re.sub(r"^\d+/", "<i>/", k) for k in z.files})
        meta = json.loads(bytes(z["meta.json"]).decode())["trials"][0]
    mot = (d / "pred" / "S1_P2_right_T0.mot").read_text().splitlines()
    return {
        "MODEL.json": list(model),
        "MODEL.json info": list(model["info"]),
        "MODEL.json uncertainty": list(model["uncertainty"]),
        "MODEL.json info.history[] moirl": list(dict.fromkeys(k for h in model["info"]["history"] for k in h)),
        "METRICS.json": list(metrics),
        "METRICS.json summary": list(metrics["summary"]),
        "METRICS.json trials[]": list(metrics["trials"][0]),
        "prediction.csv": _csv_header(d / "pred" / "S1_P2_right_T0.csv"),
        "prediction.mot": mot[mot.index("endheader") + 1].split("\t"),
        "index.csv": _csv_header(d / "pred" / "index.csv"),
        "trials.npz": trials,
        "trials.npz meta.json trials[]": list(meta),
        "results.json": list(res),
        "results.json units[]": list(unit),
        "unit.npz": npz,
        "SIM.json": list(json.loads((d / "sim.json").read_text())),
        "iscv_pairs.csv": _csv_header(d / "run" / "iscv_pairs.csv"),
        "sensitivity.csv": _csv_header(d / "sens" / "sensitivity.csv"),
        "identifiability.json": list(json.loads((d / "sens" / "identifiability.json").read_text())),
    }


def _tiny(d: Path) -> Path:
    return Path(json.loads((d / "model.json").read_text())["info"]["trials"])


#: schema tables checked against the files of a slower test's run
CHECKED_ELSEWHERE = {"posture_transfer.csv": "tests/cli/test_one_tool.py (posture transfer)"}


def test_docs_list_exactly_the_written_fields(written):
    doc, got = documented(), actual(written)
    doc = {name: fields for name, fields in doc.items() if name not in CHECKED_ELSEWHERE}
    assert sorted(doc) == sorted(got), "a schema table is missing from docs/outputs.md or from this test"
    for name in doc:
        assert sorted(doc[name]) == sorted(got[name]), f"docs/outputs.md '{name}' differs from the written file"


def test_a_runs_models_keep_the_fits_whole_history(written):
    """reproduce's models/<unit>.json keep the history `reachirl fit` keeps (each step's weights and sub-problem
    iterations), not results.json's short one."""
    fit_keys = set(json.loads((written / "model.json").read_text())["info"]["history"][-1])
    for path in sorted((written / "run" / "models").glob("*.json")):
        history = json.loads(path.read_text())["info"]["history"]
        assert history, path.name
        assert {"weights", "subproblem_iterations"} <= set(history[-1]) <= fit_keys, path.name
