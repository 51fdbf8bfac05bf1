"""Fuzz: valid inputs of every kind (TRC, C3D, Vicon CSV, MOT, trials NPZ, MODEL.json, subject-info and manifest
CSV), mutated in seeded ways, through the real console script. Every run must end with exit 0 or 2, never a
traceback or an internal error, with a one-line error on exit 2, and leave no partial or temporary output file
and no NaN in what it wrote.

``make test`` runs one seeded case per input kind (a few seconds, two at a time); ``make test-slow`` runs them all.
"""

from __future__ import annotations

import json
import math
import os
import random
import shutil
import subprocess
import sys
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from reachirl.cli import main
from reachirl.irl.model import LearnedModel, save_model

REACHIRL = str(Path(sys.executable).with_name("reachirl"))
MARKERS = "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"
UE_ADL = Path(__file__).resolve().parents[2] / "src" / "reachirl" / "data" / "ue_adl_sample" / "ADL001"
SEED = 12


# ---------------------------------------------------------------------- valid inputs
@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("fuzz_base")
    for fmt in ("trc", "c3d", "mot"):
        assert (
            main(
                [
                    "synth",
                    "--out",
                    str(d / fmt),
                    "--subjects",
                    "1",
                    "--trials",
                    "1",
                    "--postures",
                    "P2",
                    "--format",
                    fmt,
                    "--workers",
                    "1",
                ]
            )
            == 0
        )
    assert (
        main(
            [
                "preprocess",
                str(d / "trc" / "S01_P2_T01.trc"),
                "--markers",
                MARKERS,
                "--subject-info",
                str(d / "trc" / "subjects.csv"),
                "--subject",
                "S01",
                "--posture",
                "P2",
                "--out",
                str(d / "trials.npz"),
            ]
        )
        == 0
    )
    save_model(d / "model.json", LearnedModel(weights=np.full((2, 7), 0.05), n_nodes=20))
    shutil.copytree(UE_ADL, d / "vicon")
    return d


# ---------------------------------------------------------------------- mutations
def _text_mutations(text: str, rng: random.Random) -> list[tuple[str, str]]:
    lines = text.splitlines()
    i = rng.randrange(len(lines))
    numbers = [k for k, ln in enumerate(lines) if any(c.isdigit() for c in ln)]
    j = rng.choice(numbers) if numbers else i

    def with_line(k, new):
        return "\n".join([*lines[:k], new, *lines[k + 1 :]]) + "\n"

    def replace_numbers(k, value):
        import re

        return with_line(k, re.sub(r"-?\d+(\.\d+)?(e-?\d+)?", value, lines[k], count=3))

    return [
        ("empty", ""),
        ("truncated", text[: rng.randrange(1, max(2, len(text)))]),
        ("line deleted", "\n".join(lines[:i] + lines[i + 1 :]) + "\n"),
        ("line doubled", "\n".join(lines[: i + 1] + lines[i:]) + "\n"),
        ("garbage line", with_line(i, '",,\r"x;\t' + "é" * 3)),
        ("nan", replace_numbers(j, "nan")),
        ("1e308", replace_numbers(j, "1e308")),
        ("-1e308", replace_numbers(j, "-1e308")),
        ("zero", replace_numbers(j, "0")),
        ("blank numbers", replace_numbers(j, "")),
        ("huge integer", replace_numbers(j, "9" * 5000)),
        ("bytes flipped", "".join(chr(ord(c) ^ 1) if rng.random() < 0.01 else c for c in text)),
        ("header only", "\n".join(lines[: max(1, len(lines) // 20)]) + "\n"),
    ]


def _binary_mutations(data: bytes, rng: random.Random) -> list[tuple[str, bytes]]:
    k = rng.randrange(len(data))
    flipped = bytearray(data)
    for _ in range(8):
        flipped[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    zeroed = bytearray(data)
    zeroed[k : k + 64] = bytes(min(64, len(data) - k))
    return [
        ("empty", b""),
        ("truncated", data[: rng.randrange(1, len(data))]),
        ("bits flipped", bytes(flipped)),
        ("zeroed block", bytes(zeroed)),
        ("garbage appended", data + bytes(rng.randrange(256) for _ in range(200))),
        ("text", b"time,q1\n1,2\n"),
    ]


def _json_mutations(model: dict) -> list[tuple[str, str]]:
    def m(**kw):
        return json.dumps({**model, **kw})

    return [
        ("features int", m(features=3)),
        ("features null", m(features=None)),
        ("weights zero", m(weights=[[0] * 7] * 2)),
        ("weights negative", m(weights=[[-1] * 7] * 2)),
        ("weights ragged", m(weights=[[1] * 7, [1]])),
        ("windows > intervals", m(n_nodes=4, weights=[[0.1] * 7] * 6)),
        ("n_nodes 0", m(n_nodes=0)),
        ("n_nodes 3", m(n_nodes=3)),
        ("n_nodes 1e308", m(n_nodes=1e308)),
        ("n_nodes string", m(n_nodes="many")),
        ("weights tiny", m(weights=[[1e-300] * 7] * 2)),
        ("weights huge", m(weights=[[1e300] * 7] * 2)),
        ("n_nodes Infinity", m().replace('"n_nodes": 20', '"n_nodes": Infinity')),
        ("deep", "[" * 100000 + "]" * 100000),
        ("list", "[1, 2]"),
    ]


def _npz_meta_mutations(path: Path) -> list[tuple[str, bytes]]:
    import io

    with zipfile.ZipFile(path) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    meta = json.loads(bytes(np.load(io.BytesIO(entries["meta.json.npy"]))).decode())

    def with_meta(new) -> bytes:
        b = io.BytesIO()
        np.save(b, np.frombuffer(json.dumps(new).encode(), dtype=np.uint8))
        return _zip({**entries, "meta.json.npy": b.getvalue()})

    def with_trial(**kw) -> bytes:
        return with_meta({**meta, "trials": [{**t, **kw} for t in meta["trials"]]})

    def with_array(name, f) -> bytes:
        a = np.load(io.BytesIO(entries[name]))
        b = io.BytesIO()
        np.save(b, f(a))
        return _zip({**entries, name: b.getvalue()})

    arm = meta["trials"][0]["arm"]
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (200000000000, 2), }"
    header = header + " " * (118 - len(header)) + "\n"
    huge = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + bytes(64)
    return [
        ("meta list", with_meta([meta])),
        ("trials dict", with_meta({**meta, "trials": {"a": 1}})),
        ("subject list", with_trial(subject=[1])),
        ("arm list", with_trial(arm=[1])),
        ("arm 250 km", with_trial(arm={**arm, "l1": 250e3})),
        ("target string", with_trial(target_x="far")),
        ("q0 outside limits", with_array("0/x0.npy", lambda a: np.array([3.0, 3.0, 0.0, 0.0]))),
        ("duration 1 us", with_array("0/t.npy", lambda a: a * 1e-6)),
        ("q NaN", with_array("0/q.npy", lambda a: a * np.nan)),
        ("declared shape 2e11", _zip({**entries, "0/q.npy": huge})),
    ]


def _zip(entries: dict[str, bytes]) -> bytes:
    import io

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for n, b in entries.items():
            z.writestr(n, b)
    return buf.getvalue()


# ---------------------------------------------------------------------- cases
KINDS = ("trc", "c3d", "mot", "vicon-csv", "subject-info", "manifest", "trials-npz", "model-json")


def cases(base: Path) -> list[tuple[str, str, object]]:
    """``(kind, mutation, content)`` for every kind, seeded."""
    rng = random.Random(SEED)
    out = []
    for kind, src in (
        ("trc", base / "trc" / "S01_P2_T01.trc"),
        ("mot", base / "mot" / "S01_P2_T01.mot"),
        ("vicon-csv", base / "vicon" / "ADL001FL1.csv"),
        ("subject-info", base / "trc" / "subjects.csv"),
        ("manifest", base / "trc" / "manifest.csv"),
    ):
        out += [(kind, name, c) for name, c in _text_mutations(src.read_text(encoding="utf-8"), rng)]
    out += [("c3d", name, c) for name, c in _binary_mutations((base / "c3d" / "S01_P2_T01.c3d").read_bytes(), rng)]
    npz = base / "trials.npz"
    out += [("trials-npz", name, c) for name, c in _binary_mutations(npz.read_bytes(), rng)]
    out += [("trials-npz", name, c) for name, c in _npz_meta_mutations(npz)]
    model = json.loads((base / "model.json").read_text())
    out += [("model-json", name, c) for name, c in _json_mutations(model)]
    out += [("model-json", name, c) for name, c in _text_mutations((base / "model.json").read_text(), rng)]
    return out


def _command(kind: str, base: Path, work: Path, content) -> tuple[list[str], Path]:
    """Write the mutated input into ``work`` and return the command and its output file."""
    out = work / "out" / ("result.json" if kind in ("trials-npz", "model-json") else "trials.npz")
    (work / "out").mkdir(parents=True)
    name = {
        "trc": "S01_P2_T01.trc",
        "mot": "S01_P2_T01.mot",
        "c3d": "S01_P2_T01.c3d",
        "vicon-csv": "ADL001FL1.csv",
        "subject-info": "subjects.csv",
        "manifest": "manifest.csv",
        "trials-npz": "trials.npz",
        "model-json": "model.json",
    }[kind]
    if kind == "vicon-csv":
        shutil.copytree(base / "vicon", work / "in")
    elif kind in ("subject-info", "manifest"):
        shutil.copytree(base / "trc", work / "in")
    else:
        (work / "in").mkdir()
    target = work / "in" / name
    target.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8", "surrogatepass"))
    trc = base / "trc" / "S01_P2_T01.trc"
    pre = [REACHIRL, "preprocess"]
    if kind in ("trc", "c3d"):
        cmd = [*pre, str(target), "--markers", MARKERS]
    elif kind == "mot":
        cmd = [*pre, str(target)]
    elif kind == "vicon-csv":
        cmd = [*pre, str(target), "--markerset", "ue-adl", "--subject-info", str(UE_ADL.parent / "subjects.csv")]
    elif kind == "subject-info":
        cmd = [*pre, str(trc), "--markers", MARKERS, "--subject-info", str(target), "--subject", "S01"]
    elif kind == "manifest":
        cmd = [*pre, "--manifest", str(target), "--markers", MARKERS]
    elif kind == "trials-npz":
        cmd = [REACHIRL, "evaluate", "--model", str(base / "model.json"), str(target)]
    else:
        cmd = [REACHIRL, "evaluate", "--model", str(target), str(base / "trials.npz")]
    return [*cmd, "--out", str(out)], out


def _bad_numbers(obj, path="") -> list[str]:
    """NaN or infinity anywhere, and ``null`` where a number is expected without a ``no_data`` reason."""
    bad = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            if v is None and k in ("mean", "std", "q", "q1", "q2", "summary") and "no_data" not in obj:
                bad.append(f"{path}/{k}")
            bad += _bad_numbers(v, f"{path}/{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            bad += _bad_numbers(v, f"{path}/{i}")
    elif isinstance(obj, float) and not math.isfinite(obj):
        bad.append(path)
    return bad


def check_result_files(folder: Path) -> None:
    """Every result file under ``folder`` is complete and free of NaN; no temporary file is left."""
    for f in folder.rglob("*"):
        assert not f.name.startswith("."), f"temporary file left: {f}"
        if f.suffix == ".json":
            assert not _bad_numbers(json.loads(f.read_text(), parse_constant=lambda c: float(c))), f
        elif f.suffix in (".csv", ".md"):
            import re

            assert not re.search(r"(?<![A-Za-z])(nan|NaN|inf|Infinity)(?![A-Za-z])", f.read_text()), f
        elif f.suffix == ".npz":
            with np.load(f, allow_pickle=False) as z:
                for k in z.files:
                    a = z[k]
                    assert a.dtype.kind not in "fc" or np.all(np.isfinite(a)), (f, k)


def run_case(base: Path, work: Path, kind: str, mutation: str, content) -> None:
    cmd, out = _command(kind, base, work, content)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "COLUMNS": "200"}
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=60, env=env, cwd=work)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{kind} / {mutation}: no answer within 60 s (a hang)")
    what = f"{kind} / {mutation}: exit {p.returncode}\n{p.stderr[-2000:]}"
    assert p.returncode in (0, 2), what
    assert "Traceback" not in p.stderr and "internal error" not in p.stderr, what
    if p.returncode == 2:
        lines = [ln for ln in p.stderr.splitlines() if ": error:" in ln]
        assert len(lines) == 1 and p.stderr.strip().splitlines()[-1] == lines[0], what
        assert not out.exists(), f"{what}\npartial output {out}"
    else:
        assert out.is_file(), what
    check_result_files(work / "out")


def _run_all(base, tmp_path, chosen):
    def one(item):
        i, (kind, mutation, content) = item
        try:
            run_case(base, tmp_path / f"case{i}", kind, mutation, content)
        except AssertionError as e:
            return f"{kind} / {mutation}: {e}"
        except pytest.fail.Exception as e:
            return str(e)
        return None

    with ThreadPoolExecutor(max_workers=2) as ex:
        failures = [f for f in ex.map(one, enumerate(chosen)) if f]
    assert not failures, f"{len(failures)} of {len(chosen)} cases failed:\n" + "\n\n".join(failures)


def test_fuzz_sample(base, tmp_path):
    """One seeded mutation per input kind (make test)."""
    rng = random.Random(SEED)
    all_cases = cases(base)
    chosen = [rng.choice([c for c in all_cases if c[0] == kind]) for kind in KINDS]
    _run_all(base, tmp_path, chosen)


@pytest.mark.slow
def test_fuzz_all(base, tmp_path):
    """Every mutation of every input kind (make test-slow)."""
    _run_all(base, tmp_path, cases(base))
