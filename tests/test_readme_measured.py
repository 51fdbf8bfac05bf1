"""The measured numbers cannot drift: docs/benchmarks.md's Measured section is generated from docs/measured.json
(written by `make measured` from the outputs of `make run` and `make bench`), the snapshot must hold what the
current `make run` output holds, and the README quotes no measured number of its own."""

import importlib.util
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _measured():
    spec = importlib.util.spec_from_file_location("measured", ROOT / "benchmarks" / "measured.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _section(text: str, heading: str) -> str:
    start = text.index(f"\n## {heading}\n")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else None]


def test_measured_block_is_the_snapshot_rendered():
    m = _measured()
    snap = json.loads((ROOT / "docs" / "measured.json").read_text(encoding="utf-8"))
    page = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    assert m.measured_block(page) == m.render(snap), (
        "docs/benchmarks.md's Measured section was edited by hand "
        "or is stale: run `make docs` (re-render docs/measured.json) or `make measured` (new numbers)"
    )


def test_no_number_in_the_measured_section_outside_the_generated_block():
    m = _measured()
    page = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    rest = _section(page, "Measured").replace(m.measured_block(page), "")
    rest = re.sub(r"`[^`]*`", "", rest)  # commands may hold numbers (options)
    assert not re.findall(r"\d+(?:\.\d+)?\s*(?:°|%|ms|s\b|×)", rest), "quote measured numbers only in the block"


def test_snapshot_matches_the_current_make_run_output():
    """After `make run`, results/results.json must hold the numbers docs/benchmarks.md quotes."""
    path = ROOT / "results" / "results.json"
    if not path.is_file():
        pytest.skip("no results/results.json (run `make run` first)")
    res = json.loads(path.read_text(encoding="utf-8"))
    p = res["protocol"]
    if (p["sections"], p["n_train"], p["n_nodes"], p["methods"], res["data"]["kind"]) != (
        [1, 6, 8],
        10,
        100,
        ["moirl"],
        "builtin",
    ):
        pytest.skip("results/ holds another run than `make run`'s")
    m = _measured()
    snap = json.loads((ROOT / "docs" / "measured.json").read_text(encoding="utf-8"))
    assert m.protocol_numbers(res)["all_q_rmse_deg"] == snap["protocol"]["all_q_rmse_deg"], (
        "docs/benchmarks.md's protocol table differs from results/results.json: run `make measured`"
    )


def test_render_quotes_the_snapshot_numbers():
    m = _measured()
    snap = {
        "protocol": {
            "method": "moirl",
            "postures": ["P1"],
            "n_nodes": 100,
            "split_sizes": {"train": {"P1": 10}, "cv": {"P1": 10}, "iscv": {"P1": 20}},
            "all_q_rmse_deg": {"1": {"train": 3.41, "cv": 3.4, "iscv": 3.45}},
        },
        "run_wall_s": {"a 2-core box": [100.0, 163.0]},
    }
    text = m.render(snap)
    assert "| 1 | 3.41° | 3.40° | 3.45° |" in text and "1.7 min–2.7 min over 2 run(s) on a 2-core box" in text


def test_the_readme_has_no_measured_block():
    m = _measured()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert m.BEGIN not in readme and m.END not in readme, "the Measured section lives in docs/benchmarks.md"
