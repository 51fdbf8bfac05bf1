"""Virtual subjects: postures, population, truth, recordings, determinism, the cached built-in set, CLI."""

import csv
import json
import time

import numpy as np
import pytest

from reachirl import FEATURES, ArmModel
from reachirl import virtual as synth
from reachirl.cli import main
from reachirl.data.writers import read_mot_simple, read_trc_simple
from reachirl.errors import InputError
from reachirl.virtual import (
    BERRET_POSTURES_DEG,
    MARKERS,
    POSTURES,
    RELATIVE_IMPORTANCE,
    SynthConfig,
    berret_to_model,
    draw_subject,
    files,
    generate,
    nominal_weights,
    posture_q,
    recording,
)

SMALL = {"n_subjects": 1, "n_trials": 2, "postures": ("P2", "P5"), "workers": 1}


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth")
    return generate(out, SynthConfig(**SMALL))


# ---------------------------------------------------------------------- postures and population
def test_berret_postures_start_short_of_the_bar(arm):
    for p in POSTURES:
        q = posture_q(p)
        tip = arm.fk(q)
        assert tip[0] < 0.85 * arm.length - 0.1, p  # well short of Berret's bar, let alone the seed's
        assert 0.0 <= q[1] <= np.deg2rad(125), p  # the elbow is flexed, never hyper-extended
    np.testing.assert_allclose(np.rad2deg(posture_q("P1")), [-90.0, 0.0], atol=1e-12)  # arm hangs down
    np.testing.assert_allclose(arm.fk(posture_q("P1")), [0.0, -arm.length], atol=1e-12)
    np.testing.assert_allclose(np.rad2deg(berret_to_model(-90.0, 90.0)), [-90.0, 90.0])  # P2: 90° elbow
    assert set(BERRET_POSTURES_DEG) == set(POSTURES)


def test_subjects_are_deterministic_and_plausible():
    subs = [draw_subject(3, i) for i in range(40)]
    assert draw_subject(3, 5) == subs[5]
    assert draw_subject(4, 5) != subs[5]
    h = np.array([s.height_m for s in subs])
    m = np.array([s.mass_kg for s in subs])
    assert 1.70 < h.mean() < 1.82 and 0.03 < h.std() < 0.09
    assert 63 < m.mean() < 77
    assert 0.6 < np.mean([s.sex == "M" for s in subs]) < 0.97
    for s in subs:
        arm = s.arm
        assert 0.62 < arm.length < 0.85
        assert 1.0 <= s.noise_mm <= 2.0 and 2.0 <= abs(s.plane_rotation_deg) <= 5.0


def test_truth_profile_shape_and_spirit():
    w = nominal_weights()
    assert w.shape == (8, len(FEATURES)) and np.all(w >= 0)
    j = FEATURES.index("joint_acceleration")
    for s in (0, 7):  # joint acceleration dominates onset and termination
        assert np.argmax(RELATIVE_IMPORTANCE[s]) == j
    mid = RELATIVE_IMPORTANCE[3:5]
    others = [FEATURES.index(f) for f in ("energy", "geodesic", "torque_change", "joint_torque")]
    assert mid[:, others].sum() > mid[:, j].sum()


@pytest.mark.slow
def test_feature_scale_matches_its_recipe():
    # A pure joint-acceleration reach is nearly indifferent to where it lands on the bar, so its features
    # move with the solver tolerance; FEATURE_SCALE is a fixed, documented constant that must stay typical.
    np.testing.assert_allclose(synth.typical_feature_scales(), synth.FEATURE_SCALE, rtol=0.25)


# ---------------------------------------------------------------------- a small data set
def test_files_manifest_subjects_truth(small):
    out = small.out_dir
    files = sorted(p.name for p in out.glob("*.trc"))
    assert files == [f"S01_{p}_T0{k}.trc" for p in ("P2", "P5") for k in (1, 2)]
    with open(out / "manifest.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["file", "subject", "posture", "side"]
    assert [r["file"] for r in rows] == files and {r["side"] for r in rows} == {"right"}
    with open(out / "subjects.csv") as f:
        subj = list(csv.DictReader(f))
    assert list(subj[0]) == ["subject", "sex", "height_m", "mass_kg", "upper_arm_m", "forearm_m", "hand_m"]
    truth = json.loads((out / "truth.json").read_text())
    assert truth["features"] == list(FEATURES) and truth["n_windows"] == 8
    np.testing.assert_allclose(truth["truth"]["nominal_weights"], nominal_weights())
    trials = truth["subjects"]["S01"]["trials"]
    assert set(trials) == {"P2", "P5"} and len(trials["P2"]) == 2
    w = np.array(trials["P2"][0]["weights"])
    assert w.shape == (8, 7) and np.all(w >= 0)
    ratio = w[nominal_weights() > 0] / nominal_weights()[nominal_weights() > 0]
    assert 0.3 < ratio.min() and ratio.max() < 3.0 and ratio.std() > 0.05  # log-normal jitter
    assert truth["doc_failures"] == small.doc_failures == 0


def test_markers_follow_the_arm(small):
    s = small.subjects[0]
    arm = s.arm
    tr = small.trials[0]
    t, m, hdr = read_trc_simple(small.out_dir / "S01_P2_T01.trc")
    assert hdr["Units"] == "mm" and float(hdr["DataRate"]) == 100.0 and list(m) == list(MARKERS)
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-9)
    # TRC is Y up (OpenSim): the shoulder is ~1 m up, the hanging elbow below it
    assert 900 < m["SHO"][:, 1].mean() < 1200 and m["ELB"][0, 1] < m["SHO"][0, 1] - 200
    seg = {
        ("SHO", "ELB"): s.upper_arm_m,
        ("ELB", "WRI"): s.forearm_m,
        ("ELB", "FTP"): arm.l2,
    }
    for (a, b), length in seg.items():
        d = np.linalg.norm(m[b] - m[a], axis=1) / 1000.0
        assert abs(np.median(d) - length) < 0.003, (a, b)
    # rest before and after: the fingertip is still (noise only) for the first and last 0.25 s
    for sl in (slice(0, 25), slice(-25, None)):
        assert m["FTP"][sl].std(axis=0).max() < 3 * s.noise_mm
    assert tr.onset_s >= 0.3 and tr.time[-1] - tr.onset_s - tr.horizon_s >= 0.29
    # the movement plane: markers lie in a vertical plane a few degrees off the lab's X axis
    ftp = m["FTP"]
    horiz = ftp[:, [0, 2]] - ftp[0, [0, 2]]
    k = np.argmax(np.linalg.norm(horiz, axis=1))
    angle = np.degrees(np.arctan2(-horiz[k, 1], horiz[k, 0]))
    assert abs(angle - s.plane_rotation_deg) < 1.0
    # the reach ends on the bar
    x_end = np.dot(ftp[-20:].mean(axis=0) - m["SHO"][-20:].mean(axis=0), [1, 0, 0]) / 1000.0
    assert abs(x_end / np.cos(np.radians(s.plane_rotation_deg)) - tr.target_x) < 0.01


def test_human_likeness_close_to_berret(small):
    rows = {r["posture"]: r for r in small.human_likeness}
    assert set(rows) == {"P2", "P5", "ALL"}
    assert 1.7 < rows["ALL"]["peak_to_mean_speed"] < 2.2
    assert 0.35 < rows["ALL"]["time_to_peak"] < 0.5
    assert 0.55 < rows["ALL"]["duration_s"] < 0.9
    header, cells = synth.format_human_likeness(small.human_likeness)
    assert len(cells) == 3 and len(header) == len(cells[0])


def _bytes(d):
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())}


@pytest.mark.parametrize("fmt", ["trc", "mot"])
def test_same_seed_same_bytes_different_seed_different(tmp_path, fmt):
    cfg = {**SMALL, "postures": ("P4", "P2"), "n_trials": 1, "fmt": fmt}
    a = _bytes(generate(tmp_path / "a", SynthConfig(**cfg)).out_dir)
    b = _bytes(generate(tmp_path / "b", SynthConfig(**{**cfg, "workers": 2})).out_dir)
    c = _bytes(generate(tmp_path / "c", SynthConfig(**{**cfg, "seed": 1})).out_dir)
    assert a == b  # also across 1 vs 2 worker processes
    assert a.keys() == c.keys()
    for name in a:
        if name.endswith(fmt):
            assert a[name] != c[name]


def test_a_posture_named_twice_is_recorded_once(tmp_path):
    # --postures P2 P2 listed each recording twice in manifest.csv and truth.json, which preprocess then refused
    cfg = {**SMALL, "postures": ("P2",), "n_trials": 1}
    twice = generate(tmp_path / "twice", SynthConfig(**{**cfg, "postures": ("P2", "P2")}))
    assert twice.config.postures == ("P2",) and len(twice.trials) == 1
    rows = list(csv.DictReader(open(tmp_path / "twice" / "manifest.csv")))
    assert [r["file"] for r in rows] == ["S01_P2_T01.trc"]
    assert len(json.loads((tmp_path / "twice" / "truth.json").read_text())["subjects"]["S01"]["trials"]["P2"]) == 1
    assert _bytes(twice.out_dir) == _bytes(generate(tmp_path / "once", SynthConfig(**cfg)).out_dir)


def test_mot_output(tmp_path):
    res = generate(tmp_path, SynthConfig(**{**SMALL, "postures": ("P3",), "n_trials": 1, "fmt": "mot"}))
    _, cols, hdr = read_mot_simple(tmp_path / "S01_P3_T01.mot")
    assert hdr["inDegrees"] == "yes" and list(cols) == ["q1", "q2"]
    q0 = np.rad2deg(res.trials[0].q0)
    assert abs(cols["q1"][:10].mean() - q0[0]) < 0.5 and abs(cols["q2"][:10].mean() - q0[1]) < 0.5


def test_c3d_output(tmp_path):
    import ezc3d

    generate(tmp_path, SynthConfig(**{**SMALL, "postures": ("P1",), "n_trials": 1, "fmt": "c3d"}))
    c = ezc3d.c3d(str(tmp_path / "S01_P1_T01.c3d"))
    assert list(c["parameters"]["POINT"]["LABELS"]["value"]) == list(MARKERS)
    pts = c["data"]["points"]
    assert pts[2, 0].mean() > 900  # lab Z up: the shoulder is ~1 m high


def test_doc_failure_is_redrawn_and_counted(tmp_path, monkeypatch):
    from reachirl.doc import solve_doc as real_solve

    calls = {"n": 0}

    def flaky(task, weights, **kw):
        sol = real_solve(task, weights, **kw)
        if not np.allclose(weights, nominal_weights()):
            calls["n"] += 1
            if calls["n"] <= 1:  # the first draw fails
                return type(sol)(**{**sol.__dict__, "converged": False, "status": "forced failure"})
        return sol

    monkeypatch.setattr(recording, "solve_doc", flaky)
    res = generate(tmp_path, SynthConfig(**{**SMALL, "postures": ("P2",), "n_trials": 1}))
    assert res.doc_failures == 1 and res.trials[0].doc_retries == 1
    assert json.loads((tmp_path / "truth.json").read_text())["doc_failures"] == 1


def test_config_validation():
    with pytest.raises(ValueError, match="format"):
        SynthConfig(fmt="csv")
    with pytest.raises(ValueError, match="posture"):
        SynthConfig(postures=("P9",))
    with pytest.raises(ValueError, match="target_fraction"):
        SynthConfig(target_fraction=1.2)


def test_a_bar_behind_or_at_the_start_is_refused(arm):
    """A bar the start's fingertip already reaches (P2 and P4 start 0.62 and 0.64 arm lengths forward) would make
    reaches that go backwards, which preprocessing then reads as a mirrored recording."""
    assert recording.start_fraction("P4") == pytest.approx(arm.fk(posture_q("P4"))[0] / arm.length, abs=0.01)
    with pytest.raises(ValueError, match=r"\(P2 at 0\.62, P4 at 0\.64 of the arm's length\).*at least 0\.74"):
        SynthConfig(target_fraction=0.6)
    SynthConfig(target_fraction=0.6, postures=("P1", "P3", "P5"))  # those start far enough back
    # the bounds synth --help gives: 0.72 or more with P2, 0.74 or more with P4
    SynthConfig(target_fraction=0.72, postures=("P2",))
    SynthConfig(target_fraction=0.74, postures=("P4",))
    for fraction, posture in ((0.71, "P2"), (0.73, "P4")):
        with pytest.raises(ValueError, match="puts the bar behind"):
            SynthConfig(target_fraction=fraction, postures=(posture,))


def test_the_nearest_bar_allowed_still_makes_a_forward_reach(tmp_path):
    near = recording.start_fraction("P4") + recording.MIN_REACH_FRACTION + 0.005
    res = generate(tmp_path, SynthConfig(n_subjects=1, n_trials=1, postures=("P4",), target_fraction=near, workers=1))
    (trial,) = res.trials
    arm = res.subjects[0].arm
    x = arm.fk(trial.q_knots)[:, 0]
    assert x[-1] - x[0] > 0.08 * arm.length  # forward, by about the margin
    assert np.all(np.diff(x) > -1e-3 * arm.length)  # never backwards along the way


# ---------------------------------------------------------------------- built-in data set (cache)
def test_builtin_dataset_is_cached_atomically(tmp_path, monkeypatch):
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path / "cache"))
    small_cfg = SynthConfig(**{**SMALL, "postures": ("P2",), "n_trials": 1})
    monkeypatch.setattr(files, "_builtin_config", lambda seed: SynthConfig(**{**small_cfg.__dict__, "seed": seed}))
    d = synth.builtin_dataset_dir(seed=0)
    assert d.parent == tmp_path / "cache" and d.name.startswith(f"synth-v{synth.GENERATOR_VERSION}-seed0-")
    for name in ("manifest.csv", "subjects.csv", "truth.json", "S01_P2_T01.trc"):
        assert (d / name).is_file()
    mtime = (d / "truth.json").stat().st_mtime_ns
    assert synth.builtin_dataset_dir(seed=0) == d and (d / "truth.json").stat().st_mtime_ns == mtime
    assert synth.builtin_dataset_dir(seed=1) != d
    assert not [p for p in (tmp_path / "cache").iterdir() if p.name.startswith(".")]  # no temp folder left


def test_builtin_dataset_cache_is_renamed_into_place_durably(tmp_path, monkeypatch):
    # the cache folder was renamed into place without syncing its parent: a crash of the system could leave the
    # rename unwritten while a later write was (a half-visible cache)
    import os

    from reachirl.io import atomic_write_json

    root = tmp_path / "cache"
    monkeypatch.setenv("REACHIRL_CACHE", str(root))
    monkeypatch.setattr(files, "generate", lambda out, config: atomic_write_json(out / "truth.json", {}))
    synced, fsync = [], os.fsync

    def recorded(fd):
        synced.append((os.fstat(fd).st_ino, any(p.name.startswith("synth-") for p in root.iterdir())))
        return fsync(fd)

    monkeypatch.setattr(os, "fsync", recorded)
    d = synth.builtin_dataset_dir(seed=0)
    assert (d / "truth.json").is_file()
    assert synced[-1] == (root.stat().st_ino, True)  # the cache's folder, synced once the cache is in it


def test_builtin_ignores_half_written_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    small_cfg = SynthConfig(**{**SMALL, "postures": ("P4",), "n_trials": 1})
    monkeypatch.setattr(files, "_builtin_config", lambda seed: small_cfg)
    (tmp_path / ".tmp-synth-crashed").mkdir()  # a crashed generation's leftover is never picked up
    d = synth.builtin_dataset_dir()
    assert d.name != ".tmp-synth-crashed" and (d / "truth.json").is_file()


def test_cache_root_env(monkeypatch, tmp_path):
    monkeypatch.delenv("REACHIRL_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert synth.cache_root() == tmp_path / "reachirl"
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path / "x"))
    assert synth.cache_root() == tmp_path / "x"


# ---------------------------------------------------------------------- command line
def test_cli_synth(tmp_path, capsys):
    out = tmp_path / "o"
    rc = main(["synth", "--out", str(out), "--subjects", "1", "--trials", "1", "--postures", "P4", "--workers", "1"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "wrote 1 TRC trials" in text and "peak/mean" in text
    assert (out / "S01_P4_T01.trc").is_file() and (out / "truth.json").is_file()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--trials", "0"], "argument --trials: expected an integer in [1, 1000], got 0"),
        (["--seed", "-1"], "argument --seed: expected an integer >= 0, got -1"),
        (["--format", "xls"], "argument --format: invalid choice: 'xls'"),
        (["--target-fraction", "1.5"], "argument --target-fraction: expected a number in [0.5, 1.0), got 1.5"),
        ([], "the following arguments are required: --out"),
    ],
)
def test_cli_synth_bad_usage(tmp_path, capsys, args, message):
    argv = ["synth", *args] if args == [] else ["synth", "--out", str(tmp_path / "o"), *args]
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"reachirl synth: error: {message}" in err, err
    assert not (tmp_path / "o").exists()


def test_cli_synth_refuses_a_bar_at_the_start(tmp_path, capsys):
    assert main(["synth", "--out", str(tmp_path / "o"), "--target-fraction", "0.55"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "use at least 0.74, or leave those postures out" in err[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("theirs", ["subjects.csv", "manifest.csv", "S01_P4_T01.trc"])
def test_cli_synth_never_writes_over_a_folder_it_did_not_make(tmp_path, capsys, theirs):
    """A folder of the user's own (UE-ADL's subjects.csv, a lab's manifest or recordings named as synth names
    them) is refused before any work and left as it was; an earlier synth set is replaced."""
    out = tmp_path / "o"
    out.mkdir()
    (out / theirs).write_text("the user's own\n")
    argv = ["synth", "--out", str(out), "--subjects", "1", "--trials", "1", "--postures", "P4", "--workers", "1"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--out holds {theirs} and is not a synth data set" in err[0]
    assert (out / theirs).read_text() == "the user's own\n" and sorted(p.name for p in out.iterdir()) == [theirs]
    (out / theirs).unlink()
    assert main(argv) == 0 and main([*argv, "--seed", "1"]) == 0  # into its own earlier set
    assert json.loads((out / "truth.json").read_text())["config"]["seed"] == 1


def test_an_interrupted_synth_never_leaves_new_recordings_under_the_earlier_truth(tmp_path, monkeypatch):
    """Ctrl-C while the recordings are written: the earlier set's truth.json and manifest are gone, so the folder
    cannot be read as the earlier set with some of its recordings replaced; synth rerun into it finishes it."""
    out = tmp_path / "o"
    cfg = {**SMALL, "postures": ("P4",), "n_trials": 2}
    generate(out, SynthConfig(**cfg))
    written = []

    def interrupted(path, *args, **kwargs):
        if written:
            raise KeyboardInterrupt
        written.append(path)
        return real(path, *args, **kwargs)

    real = files.write_trc
    monkeypatch.setattr(files, "write_trc", interrupted)
    with pytest.raises(KeyboardInterrupt):
        generate(out, SynthConfig(**{**cfg, "seed": 1}))
    assert not any((out / n).exists() for n in ("truth.json", "manifest.csv", "subjects.csv"))
    assert (out / files.INCOMPLETE).is_file() and files.synth_folder_clash(out) is None  # synth's own, unfinished
    from reachirl.experiments.datasets import preprocess_folder

    with pytest.raises(InputError, match=r"an unfinished synth data set \(synth-incomplete\.json"):
        preprocess_folder(out, marker_map="shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP")  # never read as a set
    argv = ["preprocess", str(out), "--markers", "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"]
    assert main([*argv, "--out", str(tmp_path / "t.npz")]) == 2 and not (tmp_path / "t.npz").exists()
    # nor its recordings given one by one (they were read: a mix of two seeds' reaches)
    argv[1:2] = [str(p) for p in sorted(out.glob("*.trc"))]
    assert (
        main([*argv, "--subject", "S01", "--out", str(tmp_path / "t.npz")]) == 2 and not (tmp_path / "t.npz").exists()
    )
    monkeypatch.undo()
    done = generate(out, SynthConfig(**{**cfg, "seed": 1, "n_trials": 1}))  # a smaller set finishes it
    listed = [r["file"] for r in csv.DictReader(open(out / "manifest.csv"))]
    assert listed == ["S01_P4_T01.trc"] and len(done.trials) == 1
    assert sorted(p.name for p in out.iterdir()) == sorted([*listed, *files.SYNTH_FILES])  # no earlier T02
    assert json.loads((out / "truth.json").read_text())["config"]["seed"] == 1


def test_synth_workers_die_with_a_sigkilled_parent(tmp_path):
    """The generation workers end with their parent, even one ended by SIGKILL: a forked worker left behind waited
    for its next group forever."""
    import contextlib
    import os
    import signal
    import subprocess
    import sys

    import psutil

    argv = [sys.executable, "-m", "reachirl", "synth", "--out", str(tmp_path / "o"), "--trials", "50", "--workers", "2"]
    p = psutil.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env={**os.environ})
    workers = []
    try:
        t0 = time.monotonic()
        while len(workers) < 2 and p.poll() is None and time.monotonic() - t0 < 60:
            workers = p.children()
            time.sleep(0.1)
        assert len(workers) == 2, "the workers never started"
        time.sleep(1.0)  # past their set-up
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=10)
        _, alive = psutil.wait_procs(workers, timeout=10)
        assert not alive, "workers left running after their parent was killed"
    finally:  # nothing of the test left running, whatever it found
        for proc in [p, *workers]:
            with contextlib.suppress(psutil.NoSuchProcess):
                proc.kill()


# ---------------------------------------------------------------------- slow: the full built-in data set
@pytest.mark.slow
def test_builtin_dataset_full(tmp_path, monkeypatch):
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    t0 = time.perf_counter()
    d = synth.builtin_dataset_dir(seed=0)
    elapsed = time.perf_counter() - t0
    assert elapsed < 90.0  # target: < 30 s on 2 idle cores; slack for a machine shared with other jobs
    assert len(list(d.glob("*.trc"))) == 200
    truth = json.loads((d / "truth.json").read_text())
    assert truth["doc_failures"] <= 5
    hl = {r["posture"]: r for r in truth["human_likeness"]}
    assert 1.8 < hl["ALL"]["peak_to_mean_speed"] < 2.1
    assert 0.40 < hl["ALL"]["time_to_peak"] < 0.50
    for p in POSTURES:
        assert abs(hl[p]["duration_s"] - hl[p]["berret_duration_s"]) < 0.06, p
    arm = ArmModel.from_dict(truth["subjects"]["S01"]["arm"])
    assert arm.length > 0.6


def test_a_data_set_written_over_an_earlier_one_leaves_no_orphan_recording(tmp_path):
    """The folder holds what its manifest lists: the earlier set's other recordings go, a user's files stay."""
    generate(tmp_path, SynthConfig(**{**SMALL, "postures": ("P2",), "n_trials": 2, "fmt": "mot"}))
    (tmp_path / "notes.txt").write_text("mine")
    generate(tmp_path, SynthConfig(**{**SMALL, "postures": ("P2",), "n_trials": 1, "fmt": "mot"}))
    recordings = sorted(p.name for p in tmp_path.glob("*.mot"))
    listed = sorted(line.split(",")[0] for line in (tmp_path / "manifest.csv").read_text().splitlines()[1:])
    assert recordings == listed == [f"S{k:02d}_P2_T01.mot" for k in range(1, SMALL["n_subjects"] + 1)]
    assert (tmp_path / "notes.txt").read_text() == "mine"


# ---------------------------------------------------------------------- a true cost of the user's choosing
def _truth_csv(path, rows, header=None):
    header = header or ["window", *FEATURES]
    lines = [",".join(header)] + [",".join(str(v) for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_truth_of_the_user_s_generates_the_reaches_and_is_what_truth_json_says(tmp_path, capsys):
    """One window where torque dominates: truth.json holds it, the trial's weights are jittered around it,
    and the recorded reach is the DOC's solution under those weights (not under the paper's pattern)."""
    from reachirl.doc import ReachingTask, solve_doc
    from reachirl.virtual.population import FEATURE_SCALE

    ri = [[0.05, 0.0, 0.1, 0.05, 0.0, 0.0, 0.8]]
    csv_path = _truth_csv(tmp_path / "truth.csv", [[1, *ri[0]]])
    out = tmp_path / "o"
    argv = ["synth", "--out", str(out), "--subjects", "1", "--trials", "1", "--postures", "P2", "--workers", "1"]
    assert main([*argv, "--truth", str(csv_path)]) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["n_windows"] == 1
    np.testing.assert_allclose(truth["truth"]["relative_importance"], ri)
    np.testing.assert_allclose(truth["truth"]["nominal_weights"], np.array(ri) / FEATURE_SCALE)
    rec = truth["subjects"]["S01"]["trials"]["P2"][0]
    w = np.array(rec["weights"])
    assert w.shape == (1, 7) and np.all(w[np.array(ri) == 0] == 0)
    arm = ArmModel.from_dict(truth["subjects"]["S01"]["arm"])
    task = ReachingTask(arm, np.deg2rad(rec["q0_deg"]), truth["subjects"]["S01"]["target_x_m"], rec["horizon_s"])
    sol = solve_doc(task, w)
    default = solve_doc(task, nominal_weights())
    res = synth.generate(tmp_path / "again", synth.SynthConfig(1, 1, postures=("P2",), relative_importance=ri))
    np.testing.assert_array_equal(res.trials[0].weights, w)  # the command's reach, made again in Python
    q = res.trials[0].q_knots
    assert np.max(np.abs(q - sol.q)) < 1e-6
    assert np.max(np.abs(q - default.q)) > np.deg2rad(1.0)  # the paper's pattern makes another reach


@pytest.mark.parametrize(
    ("rows", "header", "message"),
    [
        ([[1, 1, 0, 0, 0, 0, 0, 0]], ["window", *FEATURES[:-1], "torque"], "header: unknown column 'torque'"),
        ([[1, 0, 0, 0, 0, 0, 0]], list(FEATURES[:-1]), "header: no column 'joint_torque'"),
        ([[1, 0, 0, 0, 0, 0, "x"]], list(FEATURES), "row 2: expected numbers"),
        ([[1, 0, 0, 0, 0, 0]], list(FEATURES), "row 2: 6 cells where the header has 7"),
        ([[1, 0, 0, 0, 0, 0, -1]], list(FEATURES), "must be finite and >= 0"),
        ([[1, 0, 0, 0, 0, 0, 0], [0] * 7], list(FEATURES), "window 2 weighs no feature"),
        ([], list(FEATURES), r"1 to 20 windows × 7 features, got shape \(0, 7\)"),
        ([[1] * 7] * 21, list(FEATURES), r"got shape \(21, 7\)"),
        # the window column was ignored: window 2's row first made it window 1's cost, silently
        ([[2, 0, 0, 0, 1, 0, 0, 0], [1, 1, 0, 0, 0, 0, 0, 0]], None, "row 2: window '2' where 1 was expected"),
        ([[0, 0, 0, 0, 1, 0, 0, 0]], None, "row 2: window '0' where 1 was expected"),
        ([["one", 0, 0, 0, 1, 0, 0, 0]], None, "row 2: window 'one' where 1 was expected"),
        ([[1, 0, 0, 0, 1, 0, 0, 0], [3, 1, 0, 0, 0, 0, 0, 0]], None, "row 3: window '3' where 2 was expected"),
    ],
)
def test_a_truth_file_that_is_not_a_cost_is_refused_naming_it(tmp_path, capsys, rows, header, message):
    from reachirl.virtual.files import read_relative_importance

    path = _truth_csv(tmp_path / "t.csv", rows, header)
    with pytest.raises(InputError, match=message):
        read_relative_importance(path)
    assert main(["synth", "--out", str(tmp_path / "o"), "--truth", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "t.csv" in err[0], err
    assert not (tmp_path / "o").exists()


def test_a_missing_truth_file_is_refused_naming_it(tmp_path, capsys):
    assert main(["synth", "--out", str(tmp_path / "o"), "--truth", str(tmp_path / "none.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "none.csv" in err[0] and "no such file" in err[0], err


@pytest.mark.parametrize("name", ["manifest.csv", "human_likeness.csv", "my_cost.csv"])
def test_a_truth_file_inside_the_out_folder_is_refused_and_kept(tmp_path, capsys, name):
    """`synth --truth st/human_likeness.csv --out st` replaced the user's cost with the human-likeness table."""
    out = tmp_path / "st"
    out.mkdir()
    path = _truth_csv(out / name, [[1, 1, 1, 1, 1, 1, 1]], None)
    text = path.read_text()
    assert main(["synth", "--out", str(out), "--truth", str(path), "--subjects", "1", "--trials", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(
        f"{path}: --truth lies in --out, whose files synth replaces (a truth "
        "named manifest.csv or human_likeness.csv was overwritten): keep it outside the folder"
    ), err
    assert path.read_text() == text and sorted(p.name for p in out.iterdir()) == [name]


def test_the_paper_s_pattern_keeps_its_cached_data_set():
    """A config without a truth of its own is the paper's pattern: the same cache key (and so the same cached
    built-in data) as one that names RELATIVE_IMPORTANCE, and a key of its own for any other cost."""
    from reachirl.virtual.files import _cache_key

    base = synth.SynthConfig(seed=3)
    same = synth.SynthConfig(seed=3, relative_importance=synth.RELATIVE_IMPORTANCE)
    other = synth.SynthConfig(seed=3, relative_importance=synth.RELATIVE_IMPORTANCE[::-1])
    assert _cache_key(base) == _cache_key(same) != _cache_key(other)


def test_a_truth_file_with_its_windows_numbered_in_order_is_read_in_that_order(tmp_path):
    from reachirl.virtual.files import read_relative_importance

    rows = [[1.0, 1, 0, 0, 0, 0, 0, 0], ["2", 0, 0, 0, 1, 0, 0, 0]]
    ri = read_relative_importance(_truth_csv(tmp_path / "t.csv", rows))
    assert np.argmax(ri[0]) == 0 and np.argmax(ri[1]) == FEATURES.index("joint_acceleration")


@pytest.mark.parametrize(("value", "shown"), [(-1.0, "-1"), (float("nan"), "nan"), (float("inf"), "inf")])
def test_a_truth_with_a_negative_or_non_finite_importance_names_its_window_and_feature(value, shown):
    from reachirl.virtual.recording import check_relative_importance

    ri = np.ones((3, 7))
    ri[1, 1] = value  # window 2, energy (FEATURES order); said without where before
    said = rf"^relative importance must be finite and >= 0: window 2, energy, is {shown}$"
    with pytest.raises(ValueError, match=said):
        check_relative_importance(ri)
