"""Every input and option validated at the door: one-line input errors (exit 2) naming the file, the field and
what was expected, in seconds, before any work; never an internal error, a hang or a silent wrong answer."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import time
import zipfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.data.readers import AngleData, read_c3d
from reachirl.data.trial import load_trials, save_trials, trial_from_solution
from reachirl.doc import check_weights
from reachirl.errors import InputError
from reachirl.experiments.protocol import ProtocolConfig
from reachirl.io import read_json, read_text
from reachirl.irl.model import LearnedModel, load_model, save_model
from reachirl.irl.options import resolve_options
from reachirl.validation import check_output_dir, check_output_file

REACHIRL = str(Path(sys.executable).with_name("reachirl"))


@pytest.fixture(scope="module")
def files(tmp_path_factory, arm) -> Path:
    d = tmp_path_factory.mktemp("validation")
    w = np.full((1, 7), 0.05)
    trials = []
    for i in range(2):
        task = ReachingTask(arm, np.deg2rad([-20.0 + 5 * i, 90.0]), 0.9 * arm.length, 0.7, n_nodes=20)
        trials.append(
            trial_from_solution(solve_doc(task, w), arm, task.target_x, subject="S1", posture="P2", trial_id=str(i))
        )
    save_trials(d / "trials.npz", trials)
    save_model(d / "model.json", LearnedModel(weights=np.full((2, 7), 0.05), n_nodes=20))
    (d / "afile").write_text("x")
    (d / "adir").mkdir()
    return d


def _npz_entries(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as z:
        return {n: z.read(n) for n in z.namelist()}


def _write_npz(path: Path, entries: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for n, b in entries.items():
            z.writestr(n, b)
    return path


def _with_meta(files: Path, name: str, change) -> Path:
    e = _npz_entries(files / "trials.npz")
    meta = json.loads(bytes(np.load(io.BytesIO(e["meta.json.npy"]))).decode())
    b = io.BytesIO()
    np.save(b, np.frombuffer(json.dumps(change(meta)).encode(), dtype=np.uint8))
    return _write_npz(files / name, {**e, "meta.json.npy": b.getvalue()})


def _with_array(files: Path, name: str, key: str, value) -> Path:
    e = _npz_entries(files / "trials.npz")
    b = io.BytesIO()
    np.save(b, value(np.load(io.BytesIO(e[key]))))
    return _write_npz(files / name, {**e, key: b.getvalue()})


# ---------------------------------------------------------------------- the trials file
def test_trials_file_damage_is_an_input_error(files):
    data = bytearray((files / "trials.npz").read_bytes())
    data[len(data) // 3] ^= 0x10
    (files / "flipped.npz").write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"flipped\.npz: not a readable NPZ file \(Bad CRC-32"):
        load_trials(files / "flipped.npz")

    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (200000000000, 2), }"
    header = header + " " * (118 - len(header)) + "\n"
    huge = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + bytes(64)
    _write_npz(files / "huge.npz", {**_npz_entries(files / "trials.npz"), "0/q.npy": huge})
    t0 = time.monotonic()
    with pytest.raises(InputError, match=r"huge\.npz: entry 0/q\.npy declares shape \(200000000000, 2\)"):
        load_trials(files / "huge.npz")
    assert time.monotonic() - t0 < 2.0


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda m: [m], r"unsupported format 'list'"),
        (lambda m: {**m, "trials": {"a": 1}}, r"meta\.json: field 'trials' must be a list"),
        (
            lambda m: {**m, "trials": [{**t, "subject": [1]} for t in m["trials"]]},
            r"trial 0: field 'subject' must be a string, found \[1\]",
        ),
        (
            lambda m: {**m, "trials": [{**t, "arm": [1]} for t in m["trials"]]},
            r"trial 0: field 'arm' must be an object",
        ),
        (
            lambda m: {**m, "trials": [{**t, "target_x": "far"} for t in m["trials"]]},
            r"trial 0: field 'target_x' must be a finite number \(m\), found 'far'",
        ),
        (
            lambda m: {**m, "trials": [{**t, "arm": {**t["arm"], "l1": 250e3}} for t in m["trials"]]},
            r"trial 0 \(S1/P2/right/0\): ArmModel\.l1 must be in metres, got 250000: longer than any arm segment "
            r"\(3 m; millimetres\?\)$",
        ),
    ],
)
def test_trials_metadata_is_checked_field_by_field(files, change, match):
    with pytest.raises(InputError, match=r"bad\.npz: " + match):
        load_trials(_with_meta(files, "bad.npz", change))


def test_a_start_outside_the_joint_limits_names_the_trial(files):
    path = _with_array(files, "q0.npz", "1/x0.npy", lambda a: np.array([3.0, 3.0, 0.0, 0.0]))
    with pytest.raises(
        InputError,
        match=r"q0\.npz: trial 1 \(S1/P2/right/1\): the start q0 = \(171\.9°, 171\.9°\) "
        r"lies outside the joint limits",
    ):
        load_trials(path)


@pytest.mark.parametrize(
    ("entry", "change", "match"),
    [
        (
            "1/x0.npy",
            lambda a: a + np.array([0.5, 0.0, 0.0, 0.0]),
            r"trial 1 \(S1/P2/right/1\): the start state x0 lies 28\.6° from the trial's first sample q\[0\]",
        ),
        (
            "0/q.npy",
            lambda a: np.where(np.arange(a.shape[0])[:, None] == a.shape[0] // 2, a + np.array([0.0, 4.0]), a),
            r"trial 0 \(S1/P2/right/0\): the reach leaves the joint limits q1 in \[.*\] at sample \d+ \(q = ",
        ),
    ],
)
def test_a_trial_edited_since_preprocessing_is_refused(files, entry, change, match):
    # a trial whose q had been converted to degrees, or x0 moved, was predicted as a reach ("converged", 3732°)
    with pytest.raises(InputError, match=r"edited\.npz: " + match):
        load_trials(_with_array(files, "edited.npz", entry, change))


def test_a_hyperextended_elbow_in_a_trials_file_is_named_as_such(files):
    # an elbow 3° past the model's -5° limit read "angles in degrees, or an edited file?"
    def hyperextend(a):
        a = a.copy()
        a[-3:, 1] = np.radians(-8.0)
        return a

    with pytest.raises(
        InputError,
        match=r"h\.npz: trial 0 \(S1/P2/right/0\): the elbow is hyperextended to -8\.0°, 3\.0° beyond the model's "
        r"limit of -5\.0°, at samples \d+-\d+ of the reach .* cannot reproduce it",
    ):
        load_trials(_with_array(files, "h.npz", "0/q.npy", hyperextend))


def test_two_trials_with_one_id_are_refused(files):
    def same_id(m):
        t = m["trials"]
        return {**m, "trials": [t[0], {**t[1], "trial_id": t[0]["trial_id"]}, *t[2:]]}

    match = r"dup\.npz: trial 1 has the id 'S1/P2/right/0' of trial 0; ids must be unique"
    with pytest.raises(InputError, match=match):
        load_trials(_with_meta(files, "dup.npz", same_id))


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"trial_id": "0"}, r"trial 1 has the id 'S1/P2/right/0' of trial 0; ids must be unique"),
        ({"target_x": -0.1}, r"trial 0 \(S1/P2/right/0\): field 'target_x' = -0\.1 m is outside the arm's reach"),
        ({"degrees": True}, r"trial S1/P2/0: q must be in radians, got 90 at most: beyond any joint's 2 turns"),
    ],
)
def test_save_trials_refuses_what_load_trials_would(files, tmp_path, change, match):
    # a file saved is a file that loads: trial_from_solution's default ids, a target behind the shoulder or angles
    # in degrees were written, and refused only when the file was read back (degrees are now refused as the trial
    # is made: the start q0 = (-1145.9°, 5156.6°) was the refusal here)
    from dataclasses import replace

    trials = load_trials(files / "trials.npz")
    if change.pop("degrees", False):
        with pytest.raises(InputError, match=match):
            replace(trials[0], q=np.rad2deg(trials[0].q), x0=None)
        return
    trials = [replace(t, **change) for t in trials]
    with pytest.raises(InputError, match=r"out\.npz: " + match):
        save_trials(tmp_path / "out.npz", trials)
    assert not (tmp_path / "out.npz").exists()
    with pytest.raises(TypeError, match="save_trials takes a sequence of Trial, got a dict"):
        save_trials(tmp_path / "out.npz", [{"q": trials[0].q}])


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"target_x": None}, r"target_x must be a number \(m\), got None$"),
        ({"target_x": np.array([0.5, 0.1])}, r"target_x must be a number \(m\), got array\(\[0\.5, 0\.1\]\)$"),
        ({"q": [[0.0, 1.0]] * 5 + [[1.0]]}, r"q must be an array of numbers, got \[\[0\.0, 1\.0\]"),
        ({"t": "0.7 s"}, r"t must be an array of numbers, got '0\.7 s'$"),
    ],
)
def test_a_trial_of_non_numbers_names_the_field(files, change, match):
    # numpy's own words named no field ("ufunc 'isfinite' not supported for the input types", "setting an array
    # element with a sequence")
    from dataclasses import replace

    with pytest.raises(InputError, match=r"^trial S1/P2/0: " + match):
        replace(load_trials(files / "trials.npz")[0], **change)


@pytest.mark.parametrize(
    ("field", "change", "match"),
    [
        ("q", lambda a: a + 1e-3j, r"q must be an array of real numbers, got complex numbers \(dtype complex128\)$"),
        ("t", lambda a: a.astype(complex), r"t must be an array of real numbers, got complex numbers"),
        ("x0", lambda a: a > 0, r"x0 must be an array of real numbers, got booleans \(dtype bool\)$"),
    ],
)
def test_a_trial_of_complex_or_boolean_arrays_names_the_field(files, field, change, match):
    # a cast to float dropped the imaginary part (numpy only warned) and read booleans as 0 and 1 rad
    from dataclasses import replace

    trial = load_trials(files / "trials.npz")[0]
    with pytest.raises(InputError, match=r"^trial S1/P2/0: " + match):
        replace(trial, **{field: change(getattr(trial, field))})


_ROW = [0.1] * 6
#: each door a list of numbers (or a number) comes through, given a boolean where a number belongs: how to build
#: it from a trial ``tr``, the exception type and what it must say
BOOLEAN_CASES = [
    pytest.param(
        lambda tr: LearnedModel(weights=[[True, *_ROW]], n_nodes=20),
        ValueError,
        r"^weights must be real numbers, got a boolean \(true\) among the numbers, at \[0\]\[0\]$",
        id="model weights",
    ),
    pytest.param(
        lambda tr: check_weights([[*_ROW, 0.1], [*_ROW, False]]),
        ValueError,
        r"^weights must be real numbers, got a boolean \(false\) among the numbers, at \[1\]\[6\]$",
        id="doc weights",
    ),
    pytest.param(
        lambda tr: replace(tr, q=[list(r) for r in tr.q[:-1]] + [[tr.q[-1][0], True]]),
        InputError,
        r"^trial S1/P2/0: q must be an array of real numbers, got a boolean \(true\) among the numbers, at "
        r"\[\d+\]\[1\]$",
        id="trial q",
    ),
    pytest.param(
        lambda tr: ReachingTask(tr.arm, [True, 1.5], 0.5, 0.7),
        ValueError,
        r"^q0 must be 2 real numbers, got a boolean \(true\) among the numbers, at \[0\]$",
        id="task q0",
    ),
    pytest.param(
        lambda tr: ReachingTask(tr.arm, [0.0, 1.5], 0.5, True),
        ValueError,
        r"^duration must be a number \(s\)",
        id="task duration",
    ),
    pytest.param(
        lambda tr: replace(tr, target_x=True),
        InputError,
        r"target_x must be a number \(m\), got True$",
        id="trial target_x",
    ),
    pytest.param(
        lambda tr: ArmModel(**{**tr.arm.to_dict(), "m1": True}),
        ValueError,
        r"ArmModel\.m1 must be a number",
        id="arm field",
    ),
    pytest.param(
        lambda tr: resolve_options(experimental={"frozen_windows": [True, 0]}),
        ValueError,
        r"^frozen_windows must be a list of window indices \(integers\), got a boolean \(true\) among the "
        r"numbers, at \[0\]$",
        id="frozen_windows bool",
    ),
    pytest.param(
        lambda tr: resolve_options(experimental={"frozen_windows": [0.5]}),
        ValueError,
        r"frozen_windows must be a list of window indices \(integers\), got \[0\.5\]$",
        id="frozen_windows fraction",
    ),
    pytest.param(
        lambda tr: resolve_options(experimental={"beta": True}),
        ValueError,
        r"^beta must be a number, not a boolean \(got True\)$",
        id="beta",
    ),
    pytest.param(
        lambda tr: resolve_options(experimental={"max_tries": True}),
        ValueError,
        r"^max_tries must be an integer",
        id="max_tries",
    ),
    pytest.param(
        lambda tr: ProtocolConfig(sections=(True, 6)),
        InputError,
        r"^--sections must be positive integers, got a boolean \(true\) among the numbers, at \[0\]$",
        id="protocol sections",
    ),
    pytest.param(
        lambda tr: ProtocolConfig(n_train=True),
        InputError,
        r"^n_train must be a number, got True$",
        id="protocol n_train",
    ),
]


@pytest.mark.parametrize(("build", "kind", "match"), BOOLEAN_CASES)
def test_a_boolean_is_never_read_as_a_number(files, build, kind, match):
    # [[true, 0.1, ...]] of a JSON or TOML file is a Python list mixing bool and float, which np.asarray casts to
    # [[1.0, 0.1, ...]] (only arrays of booleans were refused); frozen_windows = [true] froze window 1
    trial = load_trials(files / "trials.npz")[0]
    with pytest.raises(kind, match=match):
        build(trial)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"subject": "S1/left"}, r"subject 'S1/left' must not contain '/' \(it separates the parts of a trial's id\)"),
        ({"trial_id": "T1\nT2"}, r"trial_id 'T1\\nT2' must not contain '/' .* or a control character"),
        ({"posture": "P\t2"}, r"posture 'P\\t2' must not contain"),
    ],
)
def test_a_name_that_would_break_the_trials_id_is_refused(files, change, match):
    # "S1/left" made the id S1/left/P2/right/0, read back as another subject's; a line break split CSV rows
    from dataclasses import replace

    trial = load_trials(files / "trials.npz")[0]
    with pytest.raises(InputError, match=match):
        replace(trial, **change)


def test_a_duration_outside_a_reach_is_refused(files):
    path = _with_array(files, "dur.npz", "0/t.npy", lambda a: a * 1e-6)
    with pytest.raises(InputError, match=r"trial 0 .*: duration 7e-07 s is outside the range of a reach"):
        load_trials(path)


# ---------------------------------------------------------------------- the model file
@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"features": 3}, r"field 'features': expected a list of the 7 feature names, found 3"),
        ({"features": None}, r"field 'features': expected a list"),
        ({"weights": [[0] * 7] * 2}, r"field 'weights': all weights are zero"),
        (
            {"n_nodes": 4, "weights": [[0.1] * 7] * 6, "n_windows": 6},
            r"field 'weights': 6 windows do not fit in n_nodes = 4 intervals",
        ),
        ({"n_nodes": 0}, r"field 'n_nodes' must be an integer in \[4, 1000\], got 0"),
        ({"n_nodes": 1e308}, r"field 'n_nodes' must be an integer in \[4, 1000\], got 1e\+308"),
        (
            {"weights": [[-1] * 7] * 2},
            r"field 'weights', row 0, cartesian_velocity: expected a finite number >= 0, found -1",
        ),
        ({"weights": [[1] * 7, [1]]}, r"field 'weights', row 1: expected 7 numbers, found \[1\]"),
        ({"info": [1]}, r"field 'info': expected an object"),
        ({"weights": [[True] + [0.1] * 6]}, r"field 'weights', row 0: expected 7 numbers, found \[True, 0\.1"),
        ({"weights": [[0.1] * 7], "n_windows": True}, r"field 'n_windows' = True but 'weights' has 1 rows"),
    ],
)
def test_model_fields_are_checked(files, change, match):
    d = json.loads((files / "model.json").read_text())
    (files / "m.json").write_text(json.dumps({**d, **change}))
    with pytest.raises(InputError, match=r"m\.json: " + match):
        load_model(files / "m.json")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[" * 100000 + "]" * 100000, r"JSON nested too deeply"),
        ('{"n": ' + "9" * 5000 + "}", r"invalid JSON \(Exceeds the limit"),
        ("[" * 100 + "]" * 100, r"JSON nested more than 64 levels deep"),
    ],
)
def test_pathological_json_is_an_input_error(tmp_path, text, match):
    (tmp_path / "x.json").write_text(text)
    with pytest.raises(InputError, match=r"x\.json: " + match):
        read_json(tmp_path / "x.json")


def test_reading_a_device_ends_at_once():
    t0 = time.monotonic()
    with pytest.raises(InputError, match=r"/dev/zero: is not a regular file \(a FIFO, device or socket\)"):
        read_text("/dev/zero")
    assert time.monotonic() - t0 < 2.0


def test_utf16_text_with_its_byte_order_mark_is_read_and_binary_still_refused(tmp_path):
    """A Windows export in UTF-16 was refused as "a binary file (it holds NUL bytes)"."""
    text = "PathFileType\t4\t(X/Y/Z)\tr.trc\nµ line\n"
    for enc in ("utf-16", "utf-16-le", "utf-16-be"):
        data = text.encode(enc)
        if enc != "utf-16":  # the BOM the plain codec writes, by hand for the others
            data = ("\ufeff" + text).encode(enc)
        (tmp_path / "u.trc").write_bytes(data)
        assert read_text(tmp_path / "u.trc") == text
    (tmp_path / "b.trc").write_bytes(b"\xff\xfe" + b"\x00\xd8" + b"a\x00")  # a lone surrogate: not UTF-16
    with pytest.raises(InputError, match=r"b\.trc: begins as UTF-16 text \(its byte-order mark\) but does not decode"):
        read_text(tmp_path / "b.trc")
    (tmp_path / "n.trc").write_bytes(b"abc\x00def")
    with pytest.raises(InputError, match=r"n\.trc: is a binary file \(it holds NUL bytes\), expected text"):
        read_text(tmp_path / "n.trc")


# ---------------------------------------------------------------------- output paths
def test_output_paths_are_checked_before_any_work(files):
    with pytest.raises(InputError, match=r"--out: is a folder, expected a file path"):
        check_output_file(files / "adir")
    with pytest.raises(InputError, match=r"afile: --out: .*afile is a file, not a folder"):
        check_output_file(files / "afile" / "x.json")
    with pytest.raises(InputError, match=r"--out: the file name is 300 bytes long, too long here"):
        check_output_file(files / ("x" * 295 + ".json"))
    with pytest.raises(InputError, match=r"--out: exists and is not a folder"):
        check_output_dir(files / "afile")
    with pytest.raises(InputError, match=r"--out: the name x{20}\.\.\. is 300 bytes long"):
        check_output_dir(files / ("x" * 300) / "sub")
    assert check_output_file(files / "new" / "deeper" / "x.json") == files / "new" / "deeper" / "x.json"
    assert not (files / "new").exists()  # checking creates nothing
    # `--out newm/` (a folder meant) wrote a file named newm
    with pytest.raises(InputError, match=r"newm/: --out: ends with '/', a folder; expected a file path \(e\.g\. "):
        check_output_file(f"{files}/newm/")
    assert not (files / "newm").exists()
    if os.geteuid() != 0:  # root writes anywhere
        ro = files / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        with pytest.raises(InputError, match=r"--out: cannot write in .*ro \(Permission denied\)"):
            check_output_file(ro / "x.json")


# ---------------------------------------------------------------------- motion-capture files
def test_a_truncated_c3d_is_refused(tmp_path):
    from reachirl.data.writers import write_c3d

    t = np.arange(100) / 100.0
    markers = {n: np.c_[t * 100 + k, np.zeros(100), np.ones(100) * k] for k, n in enumerate(("A", "B"))}
    write_c3d(tmp_path / "ok.c3d", t, markers)
    data = (tmp_path / "ok.c3d").read_bytes()
    assert read_c3d(tmp_path / "ok.c3d").n_frames == 100
    (tmp_path / "cut.c3d").write_bytes(data[: int(len(data) * 0.8)])
    with pytest.raises(
        InputError,
        match=r"cut\.c3d: truncated C3D file: the header declares 100 frames, the "
        r"file holds \d+",
    ):
        read_c3d(tmp_path / "cut.c3d")


def test_a_truncated_long_c3d_is_refused(tmp_path):
    """Past 65535 frames the header's 16-bit last frame saturates: it still declares at least that many."""
    from reachirl.data.writers import write_c3d

    n = 70000
    t = np.arange(n) / 1000.0
    write_c3d(tmp_path / "long.c3d", t, {"A": np.c_[t, np.zeros(n), np.ones(n)]})
    data = (tmp_path / "long.c3d").read_bytes()
    assert data[8:10] == b"\xff\xff"  # saturated
    (tmp_path / "cut.c3d").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"cut\.c3d: truncated C3D file: the header declares \d+ frames"):
        read_c3d(tmp_path / "cut.c3d")


def test_angles_that_wrap_are_unwrapped_and_glitches_refused():
    t = np.arange(50) / 100.0
    q = np.c_[np.linspace(-1.5, -0.5, 50), np.linspace(0.2, 1.2, 50)]
    wrapped = q.copy()
    wrapped[20, 0] += 2 * np.pi  # 359° away: the same angle
    np.testing.assert_allclose(AngleData(t, wrapped, "w.mot").q, q, atol=1e-12)
    glitch = q.copy()
    glitch[20, 0] += np.deg2rad(100.0)
    with pytest.raises(InputError, match=r"g\.mot: sample 21: q1 jumps by 10\d° in one sample"):
        AngleData(t, glitch, "g.mot")


# ---------------------------------------------------------------------- the console script
CLI_CASES = [
    (
        ["fit", "{T}", "--sections", "1", "--nodes", "3", "--out", "{D}/fit_out.json"],
        r"argument --nodes: expected an integer in \[4, 1000\], got 3",
    ),
    (
        ["fit", "{T}", "--sections", "1", "--max-iter", "0", "--out", "{D}/fit_out.json"],
        r"argument --max-iter: expected an integer in \[1, 10000\], got 0",
    ),
    (["fit", "{T}", "--sections", "1", "--out", "{D}/adir"], r"adir: --out: is a folder, expected a file path"),
    (
        ["preprocess", "x.trc", "--cutoff", "nan", "--out", "{D}/p.npz"],
        r"argument --cutoff: expected a number in \[0, 1000\], got nan",
    ),
    (
        ["preprocess", "x.trc", "--filter-order", "0", "--out", "{D}/p.npz"],
        r"argument --filter-order: expected an integer in \[1, 8\], got 0",
    ),
    (["preprocess", "/dev/zero", "--format", "trc", "--out", "{D}/p.npz"], r"/dev/zero: is not a regular file"),
    (["simulate", "--model", "{M}", "{T}", "--fps", "0"], r"argument --fps: expected a number in \[1, 120\]"),
    (["simulate", "--model", "{M}", "{T}", "--size", "100000"], r"argument --size: expected an integer in "),
    (["simulate", "--model", "{M}", "{T}", "--mode", "pd", "--kp", "inf"], r"argument --kp: expected a number"),
    (
        ["evaluate", "--model", "{D}/huge_nodes.json", "{T}", "--out", "{D}/x.json"],
        r"huge_nodes\.json: field 'n_nodes' must be an integer in \[4, 1000\], got 1e\+308",
    ),
    (["evaluate", "--model", "{M}", "{T}", "--out", "{D}/afile/x.json"], r"afile is a file, not a folder"),
    (["reproduce", "--data", "{T}", "--out", "{D}/afile/o"], r"afile is a file, not a folder"),
    (
        ["reproduce", "--data", "{T}", "--nodes", "100000000", "--out", "{D}/o"],
        r"argument --nodes: expected an integer in \[4, 1000\]",
    ),
    (
        ["reproduce", "--data", "{T}", "--scheduler", "foo://bar:1", "--out", "{D}/o"],
        r"--scheduler 'foo://bar:1': expected an address like tcp://HOST:PORT \(protocols: tcp, tls, ws, wss, ucx\)",
    ),
    (
        ["reproduce", "--data", "{T}", "--scheduler", "inproc://bar:1", "--out", "{D}/o"],
        r"--scheduler 'inproc://bar:1': expected an address like tcp://HOST:PORT",
    ),
    (["reproduce", "--data", "{T}", "--method", "bogus", "--out", "{D}/o"], r"unknown method 'bogus'"),
]


# a sample in make test (each run of the console script costs about a second), all of them in make test-slow
FAST = (0, 2, 5, 9, 13)


@pytest.mark.parametrize(
    "cases",
    [
        pytest.param([CLI_CASES[i] for i in FAST], id="sample"),
        pytest.param(CLI_CASES, id="all", marks=pytest.mark.slow),
    ],
)
def test_the_console_script_answers_bad_options_and_paths_in_one_line(files, cases):
    d = json.loads((files / "model.json").read_text())
    (files / "huge_nodes.json").write_text(json.dumps({**d, "n_nodes": 1e308}))
    sub = {"{T}": str(files / "trials.npz"), "{M}": str(files / "model.json"), "{D}": str(files)}

    def run(case):
        argv, match = case
        for key, value in sub.items():
            argv = [a.replace(key, value) for a in argv]
        t0 = time.monotonic()
        p = subprocess.run([REACHIRL, *argv], capture_output=True, text=True, timeout=60)
        return argv, p, time.monotonic() - t0, match

    with ThreadPoolExecutor(max_workers=2) as ex:
        results = list(ex.map(run, cases))
    import re

    for argv, p, elapsed, match in results:
        lines = p.stderr.strip().splitlines()
        errors = [ln for ln in lines if ": error:" in ln]
        assert p.returncode == 2, (argv, p.stderr)
        assert errors == lines[-1:] and re.search(match, lines[-1]), (argv, p.stderr)  # warnings may precede
        assert "Traceback" not in p.stderr
        assert elapsed < 20, (argv, elapsed)
    assert not (files / "o").exists() and not (files / "fit_out.json").exists()


def test_help_states_the_limits():
    p = subprocess.run([REACHIRL, "fit", "--help"], capture_output=True, text=True, timeout=60)
    assert "DOC knots N, 4 to 1000" in p.stdout and "1 to 10000" in p.stdout


def test_select_trials_takes_a_single_name_as_that_name(tiny_trials):
    # subjects="S1" was read letter by letter ("no trial of subject S, 1"), postures=[2] failed in str.join
    from reachirl.data.trial import select_trials

    trials = load_trials(tiny_trials)
    assert [t.subject for t in select_trials(trials, subjects="S1")] == ["S1"] * 3
    with pytest.raises(InputError, match=r"^no trial of posture 2; they have posture P2$"):
        select_trials(trials, postures=[2])


def test_equal_trials_compare_equal_and_can_be_set_members(tiny_trials):
    # dataclass equality compared the arrays with ==: a file loaded twice raised "The truth value of an array with
    # more than one element is ambiguous" in `t in trials`, and set(trials) "unhashable type: 'numpy.ndarray'"
    from dataclasses import replace

    a, b = load_trials(tiny_trials), load_trials(tiny_trials)
    assert a[0] == b[0] and a[0] in b and a[1] != b[0]
    assert replace(a[0], q=a[0].q + 1e-3) != a[0]
    assert len(set(a) | set(b)) == len(a)
