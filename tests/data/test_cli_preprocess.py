"""`reachirl preprocess` end to end: the shipped UE-ADL sample, synthetic files, and every bad-input case
(exit code 2, one line naming the file and the problem, no traceback, nothing written)."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from reachirl.arm import ArmModel
from reachirl.cli import main
from reachirl.data.trial import load_trials


def _run(argv, capsys):
    code = main(["preprocess", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_ue_adl_sample_folder(tmp_path, synth, capsys):
    out = tmp_path / "adl.npz"
    code, stdout, err = _run(
        [synth.SAMPLE / "ADL001", "--subject-info", synth.SAMPLE / "subjects.csv", "--out", out], capsys
    )
    assert code == 0, err
    trials = load_trials(out)
    assert [t.id for t in trials] == [
        "ADL001/forward/left/FL1",
        "ADL001/forward/left/FL2",
        "ADL001/forward/right/FR1",
        "ADL001/forward/right/FR2",
    ]
    for tr in trials:
        assert 0.8 < tr.duration < 1.5 and 0.4 < tr.target_x < 0.7
        assert tr.arm.m1 == pytest.approx(0.022 * 96.0)  # female, 96 kg (Dumas: 2.2 % of body mass)
    assert re.search(r"ADL001/forward/right/FR1: 1\.\d\d s, peak fingertip speed 0\.\d\d m/s, q1 -9\d\.\.-4\d°", stdout)
    assert "wrote 4 trial(s)" in stdout


def test_a_folder_of_vicon_c3d_files_reads_as_its_csv_export(tmp_path, synth, capsys):
    """UE-ADL's reach and static trial as Vicon writes C3D (labels "ADL001:RSHO1", ...): the folder's static trial
    is found beside the reach (and not taken for a reach), and the trial is the CSV's."""
    from reachirl.data.readers import read_vicon_csv
    from reachirl.data.writers import write_c3d

    folder = tmp_path / "c3d"
    for name in ("ADL001FR1", "ADL001_static"):
        md = read_vicon_csv(synth.SAMPLE / "ADL001" / f"{name}.csv")
        markers = {f"ADL001:{m}": 1000.0 * md[m] for m in md.names}
        write_c3d(folder / f"{name}.c3d", md.t, markers, units="mm", rate=md.rate)
    info = ["--subject-info", synth.SAMPLE / "subjects.csv"]
    code, _, err = _run([folder, *info, "--out", tmp_path / "c3d.npz"], capsys)
    assert code == 0, err
    code, _, err = _run([synth.SAMPLE / "ADL001" / "ADL001FR1.csv", *info, "--out", tmp_path / "csv.npz"], capsys)
    assert code == 0, err
    (c3d,), (csv,) = load_trials(tmp_path / "c3d.npz"), load_trials(tmp_path / "csv.npz")
    assert c3d.id == csv.id and c3d.q.shape == csv.q.shape
    np.testing.assert_allclose(c3d.q, csv.q, atol=1e-6)


def test_a_static_trial_of_another_subject_is_refused(tmp_path, synth, capsys):
    # another subject's calibration moved the joint centres and the reach without a word
    other = tmp_path / "ADL003_static.csv"
    other.write_text((synth.SAMPLE / "ADL001" / "ADL001_static.csv").read_text().replace("ADL001:", "ADL003:"))
    reach = synth.SAMPLE / "ADL001" / "ADL001FR1.csv"
    info = ["--subject-info", synth.SAMPLE / "subjects.csv"]
    code, _, err = _run([reach, "--static", other, *info, "--out", tmp_path / "o.npz"], capsys)
    assert code == 2 and not (tmp_path / "o.npz").exists()
    assert err.strip() == (
        f"reachirl preprocess: error: {reach}: the static trial {other} was recorded on ADL003, this reach on "
        f"ADL001 (the subject before the marker names): give the subject's own static trial"
    )


def test_manifest_with_static_column(tmp_path, synth, capsys):
    for f in ("ADL001FR1.csv", "ADL001_static.csv"):
        shutil.copy(synth.SAMPLE / "ADL001" / f, tmp_path / ("reach.csv" if "FR1" in f else "calib.csv"))
    (tmp_path / "info.csv").write_text("subject,sex,height_m,mass_kg\nP01,F,1.70,60\n")
    (tmp_path / "m.csv").write_text("file,subject,posture,side,static\nreach.csv,P01,seated,right,calib.csv\n")
    code, _, err = _run(
        [
            "--manifest",
            tmp_path / "m.csv",
            "--markerset",
            "ue-adl",
            "--subject-info",
            tmp_path / "info.csv",
            "--out",
            tmp_path / "o.npz",
            "--n-samples",
            "200",
        ],
        capsys,
    )
    assert code == 0, err
    (tr,) = load_trials(tmp_path / "o.npz")
    assert tr.id == "P01/seated/right/reach" and tr.q.shape == (200, 2)


def test_trc_with_marker_map_and_default_subject(tmp_path, reach, synth, capsys):
    (tmp_path / "r.trc").write_text(synth.trc_text(reach.markers, up="y"))
    code, _stdout, err = _run(
        [
            tmp_path / "r.trc",
            "--markers",
            synth.MAP,
            "--subject",
            "S9",
            "--posture",
            "P3",
            "--out",
            tmp_path / "o.npz",
        ],
        capsys,
    )
    assert code == 0, err
    assert "Berret 2011's mean subject" in err
    (tr,) = load_trials(tmp_path / "o.npz")
    # TRC is Y-up: the plane and angles must still come out right
    k = int(np.argmin(np.abs(reach.q[:, 0] - tr.q[0, 0])))
    np.testing.assert_allclose(
        np.degrees(tr.q[: len(tr.t) : 10]), np.degrees(reach.q[k : k + len(tr.t) : 10]), atol=0.1
    )


def test_mot_angles(tmp_path, reach, capsys):
    rows = "".join(f"{t:.3f}\t{a:.6f}\t{b:.6f}\n" for t, (a, b) in zip(reach.t, np.degrees(reach.q), strict=True))
    (tmp_path / "r.mot").write_text(f"r\nversion=1\ninDegrees=yes\nendheader\ntime\tq1\tq2\n{rows}")
    (tmp_path / "info.csv").write_text(
        "subject,sex,height_m,mass_kg,upper_arm_m,forearm_m,hand_m\nr,M,1.76,70,0.3,0.26,0.18\n"
    )
    code, _, err = _run(
        [tmp_path / "r.mot", "--subject-info", tmp_path / "info.csv", "--out", tmp_path / "o.npz"], capsys
    )
    assert code == 0, err
    (tr,) = load_trials(tmp_path / "o.npz")
    assert tr.arm == reach.arm and tr.subject == "r"
    # a 20° spike of one sample of the elbow: taken in before (a peak speed twice the reach's), now refused by the
    # path of the fingertip the angles place, as a marker's spike is
    spiked = np.degrees(reach.q)
    spiked[len(spiked) // 2, 1] += 20.0
    rows = "".join(f"{t:.3f}\t{a:.6f}\t{b:.6f}\n" for t, (a, b) in zip(reach.t, spiked, strict=True))
    (tmp_path / "r.mot").write_text(f"r\nversion=1\ninDegrees=yes\nendheader\ntime\tq1\tq2\n{rows}")
    code, _, err = _run(
        [tmp_path / "r.mot", "--subject-info", tmp_path / "info.csv", "--out", tmp_path / "p.npz"], capsys
    )
    assert code == 2 and re.search(
        r"r\.mot: frame \d+: the fingertip \(from the angles\) leaves its path by \d+ mm", err
    )
    # the time column in milliseconds: "no movement" alone did not say why
    rows = "".join(
        f"{1000 * t:.1f}\t{a:.6f}\t{b:.6f}\n" for t, (a, b) in zip(reach.t, np.degrees(reach.q), strict=True)
    )
    (tmp_path / "r.mot").write_text(f"r\nversion=1\ninDegrees=yes\nendheader\ntime\tq1\tq2\n{rows}")
    code, _, err = _run(
        [tmp_path / "r.mot", "--subject-info", tmp_path / "info.csv", "--out", tmp_path / "m.npz"], capsys
    )
    assert code == 2 and re.search(r"r\.mot: no movement detected: .*Hz: milliseconds, not seconds\?$", err.strip()), (
        err
    )


def test_angles_missing_samples_are_a_gap_refused_beyond_max_gap(tmp_path, reach, capsys):
    """An angle file's samples are resampled at their own times; rows left out are a gap, bridged as a marker's
    up to --max-gap samples and refused beyond it (a hole of 13 samples at the peak speed was bridged in silence)."""
    (tmp_path / "info.csv").write_text(
        "subject,sex,height_m,mass_kg,upper_arm_m,forearm_m,hand_m\nr,M,1.76,70,0.3,0.26,0.18\n"
    )
    peak = int(np.argmax(np.linalg.norm(np.gradient(reach.q, axis=0), axis=1)))
    for name, keep in (
        ("r", np.arange(len(reach.t)) != peak),
        ("r_long", np.abs(np.arange(len(reach.t)) - peak) > 6),
    ):
        rows = "".join(
            f"{t:.3f}\t{a:.6f}\t{b:.6f}\n" for t, (a, b) in zip(reach.t[keep], np.degrees(reach.q[keep]), strict=True)
        )
        (tmp_path / f"{name}.mot").write_text(f"r\nversion=1\ninDegrees=yes\nendheader\ntime\tq1\tq2\n{rows}")
    info = ["--subject-info", tmp_path / "info.csv"]
    code, _, err = _run([tmp_path / "r.mot", *info, "--out", tmp_path / "s.npz"], capsys)
    assert code == 0, err
    code, _, err = _run([tmp_path / "r_long.mot", *info, "--subject", "r", "--out", tmp_path / "l.npz"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert re.search(r"long\.mot: 13 samples are missing between samples \d+ and \d+ .*more than the 10 a gap may", err)
    assert not (tmp_path / "l.npz").exists()


# ---------------------------------------------------------------------- bad input → exit 2, one line
_VHEAD = "Trajectories\n100\n,,S:SH,,,S:EL,,,S:FT,,\nFrame,Sub Frame,X,Y,Z,X,Y,Z,X,Y,Z\n,,mm,mm,mm,mm,mm,mm,mm,mm,mm\n"


def _bad_files(tmp_path, reach, synth):
    """name → (file contents or a writer, extra args, regex of the message after the file name)."""
    good = reach.markers
    gap = {k: v.copy() for k, v in good.items()}
    gap["EL"][40:60] = np.nan
    still = {k: np.repeat(v[:1], len(v), axis=0) for k, v in good.items()}
    tiny = {k: v / 1000 for k, v in good.items()}
    rows = synth.vicon_text(good).splitlines()
    return {
        "empty": ("", [], r"file is empty"),
        "header_only": (_VHEAD, [], r"no data rows after the header"),
        "one_frame": ("\n".join(rows[:6]) + "\n", [], r"bad\.csv: only 1 frame, too few for a reach$"),
        "truncated_row": ("\n".join([*rows[:10], rows[10][:25]]) + "\n", [], r"line 11: truncated row"),
        "non_numeric": (
            "\n".join([*rows[:10], rows[10].replace(".", "x", 1)]) + "\n",
            [],
            r"line 11: non-numeric cell",
        ),
        "time_not_increasing": (
            "\n".join([*rows[:10], "3" + rows[10][rows[10].index(",") :]]) + "\n",
            [],
            r"line 11: frame numbers not increasing",
        ),
        "missing_marker": (
            synth.vicon_text(good),
            ["--markers", "shoulder=SH,elbow=ELB,fingertip=FT"],
            r"marker 'ELB' \(elbow\) not found",
        ),
        "bad_marker_map": (
            synth.vicon_text(good),
            ["--markers", "hip=SH"],
            r"--markers: unknown joint 'hip'",
        ),
        "gap_too_long": (synth.vicon_text(gap), [], r"marker EL is missing for 20 frames \(41-60\)"),
        "no_movement": (synth.vicon_text(still), [], r"no movement detected"),
        "units_wrong": (synth.vicon_text(tiny), [], r"units look wrong: .* absurdly small"),
        "unreachable": (
            synth.vicon_text(good),
            ["--subject-info", "SHORT"],
            r"subject-info upper_arm_m = 0\.150 m but the markers measure 0\.300 m",
        ),
        "unknown_subject": (
            synth.vicon_text(good),
            ["--subject-info", "OTHER"],
            r"subject 'bad' is not in the subject-info file",
        ),
    }


@pytest.mark.parametrize(
    "case",
    [
        "empty",
        "header_only",
        "one_frame",
        "truncated_row",
        "non_numeric",
        "time_not_increasing",
        "missing_marker",
        "bad_marker_map",
        "gap_too_long",
        "no_movement",
        "units_wrong",
        "unreachable",
        "unknown_subject",
    ],
)
def test_bad_input_exit_2(tmp_path, reach, synth, capsys, case):
    text, extra, pattern = _bad_files(tmp_path, reach, synth)[case]
    f = tmp_path / "bad.csv"
    f.write_text(text)
    (tmp_path / "short.csv").write_text(
        "subject,sex,height_m,mass_kg,upper_arm_m,forearm_m,hand_m\nbad,M,1.76,70,0.15,0.12,0.08\n"
    )
    (tmp_path / "other.csv").write_text("subject,sex,height_m,mass_kg\nsomeone,M,1.76,70\n")
    extra = [{"SHORT": tmp_path / "short.csv", "OTHER": tmp_path / "other.csv"}.get(a, a) for a in extra]
    if "--markers" not in extra:
        extra += ["--markers", synth.MAP.replace(",wrist=WR", "")]
    out = tmp_path / "out.npz"
    code, _, err = _run([f, "--format", "vicon-csv", "--out", out, *extra], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    if case != "bad_marker_map":  # option errors have no file to name
        assert re.search(r"^reachirl preprocess: error: \S*bad\.csv: ", err), err
    assert re.search(pattern, err), err
    assert not out.exists() and not list(tmp_path.glob(".out.npz*"))


@pytest.mark.parametrize(
    ("mass", "message"),
    [
        ("96000", "mass_kg 96000.0 is not a body mass in kg (10-300); in grams?"),
        (  # 96 kg in pounds
            "211.6",
            "mass_kg 211.6 and height_m 1.702 give a body-mass index of 73.0 kg/m², not a person's (12-60); mass_kg "
            "in pounds (96.0 kg)?",
        ),
    ],
)
def test_a_subject_info_with_a_mass_in_other_units_is_refused_in_one_line_naming_the_unit(
    tmp_path, synth, capsys, mass, message
):
    info = tmp_path / "subjects.csv"
    info.write_text(f"subject,sex,height_m,mass_kg\nADL001,F,1.702,{mass}\n")
    out = tmp_path / "o.npz"
    code, _, err = _run([synth.SAMPLE / "ADL001", "--subject-info", info, "--out", out], capsys)
    assert code == 2
    assert err.strip().splitlines() == [f"reachirl preprocess: error: {info}: line 2: subject ADL001: {message}"]
    assert not out.exists()


def test_a_left_arm_recording_read_as_the_right_is_refused_naming_the_arm_that_moves(tmp_path, synth, capsys):
    # "no movement detected" alone sent the user looking for a broken file
    out = tmp_path / "o.npz"
    code, _, err = _run([synth.SAMPLE / "ADL001" / "ADL001FL1.csv", "--side", "right", "--out", out], capsys)
    assert code == 2
    assert re.fullmatch(
        r"reachirl preprocess: error: \S+ADL001FL1\.csv: no movement detected: the fingertip's peak speed is 0\.0\d+ "
        r"m/s \(< 0\.05 m/s\); the left arm's fingertip \(LFTP\) moves \d{3} mm: a recording of the left arm "
        r"\(--side, or the manifest's side column\)\?",
        err.strip(),
    ), err
    assert not out.exists()


def test_a_hyperextended_elbow_is_named_as_such_and_a_mirrored_recording_still_as_mirrored(tmp_path, synth, capsys):
    """An elbow a few degrees past straight (a reach at arm's length) was refused as "a mirrored or backwards
    recording?": it is a real posture, which the DOC's elbow limit of -5° cannot reproduce, and is said so."""
    arm = ArmModel.from_anthropometrics(1.76, 70.0, "M", upper_arm_m=0.30, forearm_m=0.26, hand_m=0.18)
    argv = ["--markers", synth.MAP, "--out", tmp_path / "o.npz"]
    for name, q0, qf in (("hyper", (-1.4, 1.6), (-0.6, np.radians(-15.0))), ("mirror", (-1.4, -1.6), (-0.6, -0.5))):
        _, q = synth.min_jerk_q(q0, qf)
        (tmp_path / f"{name}.trc").write_text(synth.trc_text(synth.lab_markers(arm, q)))
    code, _, err = _run([tmp_path / "hyper.trc", *argv], capsys)
    assert code == 2 and not (tmp_path / "o.npz").exists()
    assert re.fullmatch(
        r"reachirl preprocess: error: \S+hyper\.trc: the elbow is hyperextended to -\d+\.\d°, \d+\.\d° beyond the "
        r"model's limit of -5\.0°, at samples \d+-\d+ of the reach \(0\.\d{3}-0\.\d{3} s after onset\): a real "
        r"posture, but the DOC's joint limits \(q1 in \[-150\.0°, 120\.0°\], q2 in \[-5\.0°, 160\.0°\]\) cannot "
        r"reproduce it; leave this trial out",
        err.strip(),
    ), err
    assert "mirrored" not in err
    code, _, err = _run([tmp_path / "mirror.trc", *argv], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert re.search(r"mirror\.trc: the start posture .* a mirrored or backwards recording\?", err), err


def test_a_manifest_naming_a_missing_file_is_refused_before_any_work_naming_both(tmp_path, synth, capsys, monkeypatch):
    import reachirl.cli.preprocess as cli_preprocess

    shutil.copytree(synth.SAMPLE / "ADL001", tmp_path / "ADL001")
    manifest = tmp_path / "ADL001" / "manifest.csv"
    manifest.write_text("file,subject,posture\nADL001FR1.csv,ADL001,forward\nADL001FR9.csv,ADL001,forward\n")
    done = []
    real = cli_preprocess.preprocess_entries
    monkeypatch.setattr(cli_preprocess, "preprocess_entries", lambda *a, **k: done.append(1) or real(*a, **k))
    out = tmp_path / "o.npz"
    code, _, err = _run(["--manifest", manifest, "--out", out], capsys)
    assert code == 2 and done == []
    assert err.strip().splitlines() == [
        f"reachirl preprocess: error: {manifest.parent / 'ADL001FR9.csv'}: listed in the manifest {manifest}: "
        "file not found"
    ]
    assert not out.exists()


@pytest.mark.parametrize(
    ("name", "hint"), [("x.csv", "; CSV or MOT files of each trial: --export FOLDER"), ("x.json", ""), ("x", "")]
)
def test_an_out_not_named_npz_is_refused_naming_the_suffix(tmp_path, synth, capsys, name, hint):
    # `--out x.csv` wrote an NPZ under a CSV's name, which a spreadsheet then failed to open
    out = tmp_path / name
    info = ["--subject-info", synth.SAMPLE / "subjects.csv"]
    code, _, err = _run([synth.SAMPLE / "ADL001", *info, "--out", out], capsys)
    assert code == 2 and not out.exists()
    assert err.strip().splitlines() == [
        f"reachirl preprocess: error: {out}: --out: a trials file is NPZ, its name must end in .npz{hint}"
    ]


def test_missing_static_and_bad_out(tmp_path, synth, capsys):
    shutil.copy(synth.SAMPLE / "ADL001" / "ADL001FR1.csv", tmp_path)
    code, _, err = _run([tmp_path / "ADL001FR1.csv", "--out", tmp_path / "o.npz"], capsys)
    assert code == 2 and re.search(r"ADL001FR1\.csv: marker set 'ue-adl' needs a static trial", err)
    code, _, err = _run([tmp_path / "nope.trc", "--out", tmp_path / "o.npz"], capsys)
    assert code == 2 and re.search(r"nope\.trc: file or folder not found", err)
    assert not (tmp_path / "o.npz").exists()


@pytest.mark.parametrize(
    ("name", "pattern"),
    [
        (
            "ADL001FR1angles.csv",
            r"ADL001FR1angles\.csv: the data authors' joint angles of ADL001FR1\.csv, not a recording",
        ),
        ("ADL001_static.csv", r"ADL001_static\.csv: a static calibration trial, not a reach"),
    ],
)
def test_a_glob_of_a_ue_adl_folder_names_the_file_that_is_not_a_reach(tmp_path, synth, capsys, name, pattern):
    # `preprocess ADL001/*.csv` names the authors' angles and the static trial beside the reaches
    reach = synth.SAMPLE / "ADL001" / "ADL001FR1.csv"
    out = tmp_path / "o.npz"
    info = ["--subject-info", synth.SAMPLE / "subjects.csv"]
    code, _, err = _run([reach, synth.SAMPLE / "ADL001" / name, *info, "--out", out], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert re.search(pattern, err), err
    assert not out.exists()


def test_a_real_recording_with_two_frames_swapped_is_refused(tmp_path, synth, capsys):
    """UE-ADL's ADL001FR1 with the markers of frames 111 and 112 swapped (the frame numbers left in order), at the
    reach's peak speed: the fingertip steps 5 mm back in one frame, which no hand does and the acceleration check
    let pass."""
    folder = tmp_path / "ADL001"
    folder.mkdir()
    shutil.copy(synth.SAMPLE / "ADL001" / "ADL001_static.csv", folder)
    lines = (synth.SAMPLE / "ADL001" / "ADL001FR1.csv").read_text(encoding="utf-8-sig").splitlines()
    rows = {ln.split(",", 1)[0]: i for i, ln in enumerate(lines)}
    a, b = rows["111"], rows["112"]
    lines[a], lines[b] = "111," + lines[b].split(",", 1)[1], "112," + lines[a].split(",", 1)[1]
    (folder / "ADL001FR1.csv").write_text("\n".join(lines) + "\n")
    out = tmp_path / "o.npz"
    code, _, err = _run(
        [folder / "ADL001FR1.csv", "--subject-info", synth.SAMPLE / "subjects.csv", "--out", out], capsys
    )
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert re.search(
        r"ADL001FR1\.csv: frame 112: the fingertip steps 5 mm back against its way of travel in one frame, .*: frames "
        r"out of order",
        err,
    ), err
    assert not out.exists()


@pytest.mark.parametrize(
    ("file", "marker"), [("ADL001FR1.csv", "RUAR3"), ("ADL001FR1.csv", "RSHO3"), ("ADL001_static.csv", "RGTH")]
)
def test_a_marker_exported_at_the_labs_origin_is_unseen_not_a_position(tmp_path, synth, capsys, file, marker):
    """Vicon's CSV (and TRC) marked a lost marker 0,0,0, which was read as a position: an elbow-cluster marker at
    the origin in every frame bent the elbow 8-14° where it bends 28-94°, a shoulder marker moved the target by 10
    cm; three such frames of a static trial shortened the upper arm by 3 cm. Now unseen, as in C3D: the cluster's
    other markers give the same trial."""
    folder = tmp_path / "ADL001"
    folder.mkdir()
    for name in ("ADL001FR1.csv", "ADL001_static.csv"):
        shutil.copy(synth.SAMPLE / "ADL001" / name, folder)
    lines = (folder / file).read_text(encoding="utf-8-sig").splitlines()
    col = [c.split(":")[-1] for c in lines[2].split(",")].index(marker)
    for i in range(5, len(lines) if file != "ADL001_static.csv" else 8):
        cells = lines[i].split(",")
        if lines[i].strip(", "):
            cells[col : col + 3] = ["0", "0", "0"]
            lines[i] = ",".join(cells)
    (folder / file).write_text("\n".join(lines) + "\n", encoding="utf-8")
    info = ["--subject-info", synth.SAMPLE / "subjects.csv"]
    assert _run([synth.SAMPLE / "ADL001" / "ADL001FR1.csv", *info, "--out", tmp_path / "a.npz"], capsys)[0] == 0
    code, _, err = _run([folder / "ADL001FR1.csv", *info, "--out", tmp_path / "b.npz"], capsys)
    assert code == 0, err
    (a,), (b,) = load_trials(tmp_path / "a.npz"), load_trials(tmp_path / "b.npz")
    assert abs(a.duration - b.duration) < 0.02 and abs(a.target_x - b.target_x) < 0.005
    assert np.rad2deg(np.abs(a.q_at(101) - b.q_at(101)).max()) < 1.0


def test_a_cluster_marker_the_export_left_out_is_unseen_as_one_left_empty(tmp_path, synth, capsys):
    """UE-ADL's reach with RUAR1 (an elbow-cluster marker) left out of the export's header was refused ("marker
    'RUAR1' (elbow cluster) not found") where the same marker exported empty gave the trial: a cluster needs 3 of
    its 4 markers. Two left out still leave too few, and the message names one."""
    folder = tmp_path / "ADL001"
    folder.mkdir()
    shutil.copy(synth.SAMPLE / "ADL001" / "ADL001_static.csv", folder)
    text = (synth.SAMPLE / "ADL001" / "ADL001FR1.csv").read_text(encoding="utf-8-sig").splitlines()
    info = ["--subject-info", synth.SAMPLE / "subjects.csv"]
    assert _run([synth.SAMPLE / "ADL001" / "ADL001FR1.csv", *info, "--out", tmp_path / "a.npz"], capsys)[0] == 0
    for drop, ok in ((("RUAR1",), True), (("RUAR1", "RUAR2"), False)):
        lines = list(text)
        for m in drop:
            lines[2] = lines[2].replace(f"ADL001:{m},", ",")
        (folder / "ADL001FR1.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
        code, _, err = _run([folder / "ADL001FR1.csv", *info, "--out", tmp_path / "b.npz"], capsys)
        if ok:
            assert code == 0, err
            (a,), (b,) = load_trials(tmp_path / "a.npz"), load_trials(tmp_path / "b.npz")
            assert np.rad2deg(np.abs(a.q_at(101) - b.q_at(101)).max()) < 1.0
        else:
            assert code == 2 and re.search(r"marker 'RUAR[12]' \(elbow cluster\) not found", err), err


def test_a_warned_recording_refused_by_its_up_axis_says_the_refusal_alone(tmp_path, synth, cli):
    """UE-ADL's ADL001FR1 under --threshold 0.001 is warned about (its noise is large beside the threshold's speed,
    and no rest is left before the movement); under the lab's forward axis given as up it is refused (by the joint
    limits, and now before them by the up axis check). The warnings came first: stderr now holds the refusal alone,
    one line. (The joint limits' refusal alone: test_a_refused_recording_is_not_first_warned_about.)"""
    reach, info = synth.SAMPLE / "ADL001" / "ADL001FR1.csv", synth.SAMPLE / "subjects.csv"
    args = ("preprocess", reach, "--subject-info", info, "--threshold", "0.001")
    ok = cli(*args, "--out", tmp_path / "ok.npz")
    assert ok.returncode == 0 and "WARNING" in ok.stderr and "is large beside the onset threshold" in ok.stderr
    refused = cli(*args, "--up-axis", "+y", "--out", tmp_path / "o.npz")
    assert refused.returncode == 2
    assert re.fullmatch(
        r"reachirl preprocess: error: \S*ADL001FR1\.csv: with up = \+y \(--up-axis\), the upper arm never hangs "
        r"within 45° of straight down before the reach .* Give --up-axis \+z, or leave --up-axis out\n",
        refused.stderr,
    ), refused.stderr
    assert not (tmp_path / "o.npz").exists()


def test_one_bad_file_writes_nothing(tmp_path, synth, reach, capsys):
    (tmp_path / "good.trc").write_text(synth.trc_text(reach.markers, up="y"))
    (tmp_path / "bad.trc").write_text("PathFileType\t4\n")
    out = tmp_path / "o.npz"
    code, _, err = _run([tmp_path / "good.trc", tmp_path / "bad.trc", "--markers", synth.MAP, "--out", out], capsys)
    assert code == 2 and "bad.trc" in err and not out.exists()


def test_inputs_with_manifest(tmp_path, reach, synth, capsys):
    (tmp_path / "a.trc").write_text(synth.trc_text(reach.markers, up="y"))
    (tmp_path / "b.trc").write_text(synth.trc_text(reach.markers, up="y"))
    (tmp_path / "m.csv").write_text("file,subject,posture,side\na.trc,S1,P4,left\n")
    args = ["--manifest", tmp_path / "m.csv", "--markers", synth.MAP, "--out", tmp_path / "o.npz"]
    code, _, err = _run([tmp_path / "a.trc", *args], capsys)
    assert code == 0, err
    assert [t.id for t in load_trials(tmp_path / "o.npz")] == ["S1/P4/left/a"]
    code, _, err = _run([tmp_path / "b.trc", *args], capsys)
    assert code == 2 and re.search(r"b\.trc: not listed in the manifest", err)
    # a static trial the manifest names must exist, even where the marker set needs none (it was ignored)
    (tmp_path / "m.csv").write_text("file,subject,posture,side,static\na.trc,S1,P4,left,calib.csv\n")
    code, _, err = _run([tmp_path / "a.trc", *args], capsys)
    assert code == 2 and err.strip().endswith("calib.csv: the manifest's 'static' of a.trc: file not found"), err


def test_the_same_recording_twice_is_refused_before_a_trials_file_is_written(tmp_path, capsys):
    """Two inputs that make one trial id would give a trials file every other command refuses."""
    import shutil

    from reachirl.cli import main
    from recordings import synth

    raw = synth(tmp_path / "raw", ("P2",), subjects=1, trials=1)
    (trc,) = sorted(raw.glob("*.trc"))
    (tmp_path / "b").mkdir()
    copy = shutil.copy(trc, tmp_path / "b" / trc.name)  # same name, another folder
    out = tmp_path / "t.npz"
    markers = ["--markers", "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"]
    capsys.readouterr()
    assert main(["preprocess", str(trc), str(copy), *markers, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{copy}: gives the trial id" in err and str(trc) in err, err
    assert not out.exists()


@pytest.mark.parametrize("start", [520, 600, 700, 1000])
def test_a_damaged_c3d_parameter_section_is_refused_not_a_crash(tmp_path, cli, start):
    """ezc3d dies with a segfault on some damaged parameter sections: the records are walked first (run as a
    separate process, so that a crash fails this test instead of ending the test run)."""
    from recordings import synth

    raw = synth(tmp_path / "raw", ("P2",), subjects=1, trials=1, fmt="c3d")
    (c3d,) = sorted(raw.glob("*.c3d"))
    data = bytearray(c3d.read_bytes())
    data[start : start + 100] = b"\xff" * 100
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(bytes(data))
    markers = "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"
    proc = cli("preprocess", bad, "--markers", markers, "--out", tmp_path / "t.npz")
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stderr.strip().startswith(f"reachirl preprocess: error: {bad}: not a readable C3D file (damaged")
    assert len(proc.stderr.strip().splitlines()) == 1 and not (tmp_path / "t.npz").exists()
    ok = cli("preprocess", c3d, "--markers", markers, "--out", tmp_path / "ok.npz")  # the undamaged file reads
    assert ok.returncode == 0, ok.stderr


def test_markers_and_a_markerset_together_are_refused(tmp_path, capsys):
    from reachirl.cli import main

    args = ["preprocess", str(tmp_path / "x.trc"), "--markers", "shoulder=A,elbow=B,wrist=C,fingertip=D"]
    assert main([*args, "--markerset", "ue-adl", "--out", str(tmp_path / "t.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "reachirl preprocess: error: give --markers or --markerset, not both (--markers would win and --markerset "
        "be ignored)"
    )


def test_a_trials_file_whose_count_disagrees_with_its_list_is_refused(tiny_trials, tmp_path):
    import io
    import json
    import zipfile

    from reachirl.data.trial import load_trials
    from reachirl.errors import InputError

    bad = tmp_path / "bad.npz"
    with zipfile.ZipFile(tiny_trials) as src, zipfile.ZipFile(bad, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "meta.json.npy":
                arr = np.load(io.BytesIO(data), allow_pickle=False)
                meta = json.loads(bytes(arr).decode())
                meta["n_trials"] += 1
                buf = io.BytesIO()
                np.save(buf, np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
                data = buf.getvalue()
            dst.writestr(info, data)
    with pytest.raises(InputError, match=r"meta.json: 'n_trials' is \d+ but 'trials' lists \d+"):
        load_trials(bad)


def test_a_file_that_is_not_a_trials_file_names_the_command_that_writes_one(tmp_path):
    """`synth` writes recordings, not a trials file: only `preprocess` is named."""
    from reachirl.data.trial import load_trials
    from reachirl.errors import InputError

    model = tmp_path / "model.json"
    model.write_text('{"format": "reachirl-model/1"}')
    expected = r"model\.json: not a trials file \(expected the NPZ written by `reachirl preprocess`\)$"
    with pytest.raises(InputError, match=expected):
        load_trials(model)


def test_a_file_this_user_cannot_read_says_so(tiny_trials, monkeypatch):
    """Not "not a trials file": the reason is the permission (root reads mode-000 files, so open is made to fail)."""
    import builtins

    from reachirl.data.trial import load_trials
    from reachirl.errors import InputError

    real_open = builtins.open

    def no_access(file, *args, **kwargs):
        if str(file) == str(tiny_trials):
            raise PermissionError(13, "Permission denied")
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", no_access)
    with pytest.raises(InputError, match="cannot read \\(Permission denied\\)"):
        load_trials(tiny_trials)


def test_an_export_into_the_data_folder_is_not_read_back_as_reaches(tmp_path, synth, capsys):
    data = tmp_path / "ADL001"
    shutil.copytree(synth.SAMPLE / "ADL001", data)
    info = ["--subject-info", synth.SAMPLE / "subjects.csv"]
    code, _, err = _run([data, *info, "--out", tmp_path / "a.npz", "--export", data / "processed"], capsys)
    assert code == 0, err
    assert (data / "processed" / "index.csv").is_file() and list((data / "processed").glob("*.mot"))
    code, _, err = _run([data, *info, "--out", tmp_path / "b.npz"], capsys)
    assert code == 0, err
    assert [t.id for t in load_trials(tmp_path / "b.npz")] == [t.id for t in load_trials(tmp_path / "a.npz")]
    # the export folder given itself is read (its angle files)
    code, _, err = _run([data / "processed", "--out", tmp_path / "c.npz", "--subject", "ADL001"], capsys)
    assert code == 0, err
    assert len(load_trials(tmp_path / "c.npz")) == len(load_trials(tmp_path / "a.npz"))


def test_an_input_that_does_not_exist_is_named(tmp_path, synth, capsys):
    missing = tmp_path / "ADL009"
    code, _, err = _run([missing, "--subject-info", synth.SAMPLE / "subjects.csv", "--out", tmp_path / "a.npz"], capsys)
    assert code == 2
    assert err.strip().splitlines() == [f"reachirl preprocess: error: {missing}: file or folder not found"]
    assert not (tmp_path / "a.npz").exists()


def test_a_y_up_c3d_that_says_so_reads_as_the_z_up_one(tmp_path, synth, capsys):
    """OptiTrack Motive writes Y-up C3D files with POINT:Y_SCREEN = +Y: that is the up axis, over the marker set's
    own (+Z for UE-ADL's Vicon files). Undeclared, the same file is refused with a hint naming --up-axis."""
    import ezc3d

    from reachirl.data.readers import read_vicon_csv
    from reachirl.data.writers import write_c3d

    info = ["--subject-info", synth.SAMPLE / "subjects.csv", "--markerset", "ue-adl"]
    for folder, declare in (("declared", True), ("silent", False)):
        for name in ("ADL001FR1", "ADL001_static"):
            md = read_vicon_csv(synth.SAMPLE / "ADL001" / f"{name}.csv")
            markers = {m: 1000.0 * md[m][:, [0, 2, 1]] * [1.0, 1.0, -1.0] for m in md.names}  # (x, z, -y)
            path = tmp_path / folder / f"{name}.c3d"
            write_c3d(path, md.t, markers, units="mm", rate=md.rate)
            if declare:
                c = ezc3d.c3d(str(path))
                c.add_parameter("POINT", "Y_SCREEN", ["+Y"])
                c.write(str(path))
    code, _, err = _run([tmp_path / "declared", *info, "--out", tmp_path / "y.npz"], capsys)
    assert code == 0, err
    code, _, err = _run([synth.SAMPLE / "ADL001" / "ADL001FR1.csv", *info, "--out", tmp_path / "z.npz"], capsys)
    assert code == 0, err
    (y,), (z,) = load_trials(tmp_path / "y.npz"), load_trials(tmp_path / "z.npz")
    np.testing.assert_allclose(y.q, z.q, atol=1e-6)
    code, _, err = _run([tmp_path / "silent", *info, "--out", tmp_path / "s.npz"], capsys)
    assert code == 2 and "check --markers, --up-axis and --forward-axis" in err


@pytest.mark.parametrize(
    "form", [["--up-axis", "-z"], ["--up-axis=-z"], ["--up-axis", "-Z", "--plane", "axes", "--forward-axis", "-y"]]
)
def test_a_negative_up_axis_is_taken_as_written(tmp_path, reach, synth, capsys, form):
    """``--up-axis -z`` (a lab whose z points down) was refused by argparse, 'expected one argument': a value
    starting with '-' read as an option. It now reads as --up-axis=-z."""
    down = {m: p * [1.0, 1.0, -1.0] for m, p in reach.markers.items()}  # the lab's z axis points down
    (tmp_path / "up.trc").write_text(synth.trc_text(reach.markers, up="y"))
    (tmp_path / "down.trc").write_text(synth.trc_text(down))
    args = ["--markers", synth.MAP, "--subject", "S9", "--posture", "P3"]
    plane = ["--plane", "axes"] if "axes" in form else []  # the same plane for both
    code, _, err = _run([tmp_path / "up.trc", *args, *plane, "--out", tmp_path / "up.npz"], capsys)
    assert code == 0, err
    code, _, err = _run([tmp_path / "down.trc", *args, *form, "--out", tmp_path / "down.npz"], capsys)
    assert code == 0, err
    (up,), (down,) = load_trials(tmp_path / "up.npz"), load_trials(tmp_path / "down.npz")
    np.testing.assert_allclose(down.q, up.q, atol=1e-6)


def test_a_file_cut_in_its_last_number_is_named_as_cut_short(tmp_path, reach, synth, capsys):
    """A file cut short inside its last row's last number has every field: the number cut off reads as a jump in
    the last frame, which was refused as 'a glitch in the markers?'. The last frame's jump now says the file may be
    cut short; a jump inside the record keeps its own words."""
    text = synth.trc_text(reach.markers, up="y").rstrip("\n")
    head, last = text.rsplit("\n", 1)
    cells = last.split("\t")
    cells[-1] = cells[-1][: cells[-1].index(".") - 2]  # "-604.262" cut to "-6": a hundred times shorter
    (tmp_path / "cut.trc").write_text(head + "\n" + "\t".join(cells))
    n = len(head.split("\n")) - 5
    code, _, err = _run([tmp_path / "cut.trc", "--markers", synth.MAP, "--out", tmp_path / "o.npz"], capsys)
    assert code == 2 and re.search(
        rf"cut\.trc: frame {n}: the \w+ (moves|jumps) \d+ mm in one frame .*: the record's last frame: a file cut "
        r"short in its last row\?$",
        err.strip(),
    ), err


def test_a_left_arms_angle_file_is_a_left_trial(tmp_path, capsys):
    """A MOT of the left arm's angles alone (reachirl's own export of a left trial) was read as a right-arm trial
    when no side was given: labelled right, built on the right arm, in the wrong set of --cv other-side. The arm
    its columns name is the trial's; a side given against them is refused; a file of both arms' stays the right's."""
    k = np.arange(150)
    s = np.clip((k - 40) / 60, 0, 1)
    mj = 10 * s**3 - 15 * s**4 + 6 * s**5
    elev, flex = 5 + 45 * mj, 85 - 40 * mj  # a reach: shoulder elevation up, elbow extending
    rows = "\n".join(f"{i / 100:.2f}\t{e:.4f}\t{f:.4f}" for i, e, f in zip(k, elev, flex, strict=True))
    head = f"nRows={k.size}\nnColumns=3\ninDegrees=yes\nendheader\n"
    (tmp_path / "l.mot").write_text(f"l\n{head}time\tl_shoulder_elev\tl_elbow_flex\n{rows}\n")
    code, _, err = _run([tmp_path / "l.mot", "--subject", "S1", "--out", tmp_path / "l.npz"], capsys)
    assert code == 0, err
    (tr,) = load_trials(tmp_path / "l.npz")
    assert tr.side == "left" and tr.id == "S1/default/left/l"
    code, _, err = _run([tmp_path / "l.mot", "--side", "right", "--out", tmp_path / "r.npz"], capsys)
    assert code == 2 and re.search(
        r"l\.mot: its angle columns are the left arm's, but the trial is given as the right arm's \(give --side left",
        err,
    ), err
    both = "\n".join(
        f"{i / 100:.2f}\t{e:.4f}\t{f:.4f}\t{e:.4f}\t{f:.4f}" for i, e, f in zip(k, elev, flex, strict=True)
    )
    (tmp_path / "b.mot").write_text(
        f"b\n{head.replace('nColumns=3', 'nColumns=5')}time\tr_shoulder_elev\tr_elbow_flex\tl_shoulder_elev\t"
        f"l_elbow_flex\n{both}\n"
    )
    code, _, err = _run([tmp_path / "b.mot", "--out", tmp_path / "b.npz"], capsys)
    assert code == 0, err
    assert load_trials(tmp_path / "b.npz")[0].side == "right"


def test_a_lateral_forward_axis_is_refused_not_projected_into_nonsense(tmp_path, reach, synth, capsys):
    """--plane axes with the lab's lateral axis as --forward-axis projected a forward reach into the frontal plane:
    it was written as a trial (peak fingertip speed 9.7 m/s, q2 to 153°). The forward axis the reach goes along
    (or the one found) still reads it."""
    (tmp_path / "r.trc").write_text(synth.trc_text(reach.markers, up="y"))  # here z is forward, x lateral
    args = [tmp_path / "r.trc", "--markers", synth.MAP, "--plane", "axes", "--out", tmp_path / "o.npz"]
    code, _, err = _run([*args, "--forward-axis", "x"], capsys)
    assert code == 2 and re.search(
        r"r\.trc: the fingertip moves \d+ mm across the plane of the up and forward axes \(--plane axes\) and \d+ mm "
        r"along its forward axis, from onset to offset: is the forward axis the lab's lateral one\?",
        err,
    ), err
    for ok in ([*args, "--forward-axis", "z"], args):
        code, _, err = _run(ok, capsys)
        assert code == 0, err


def test_a_forward_axis_without_plane_axes_is_refused_not_ignored(tmp_path, reach, synth, capsys):
    """--forward-axis is read by --plane axes only; with the default plane (pca) it was taken and left unused."""
    (tmp_path / "r.trc").write_text(synth.trc_text(reach.markers, up="y"))
    code, _, err = _run(
        [tmp_path / "r.trc", "--markers", synth.MAP, "--forward-axis", "z", "--out", tmp_path / "o.npz"], capsys
    )
    assert code == 2 and "--forward-axis is used with --plane axes only, not --plane pca" in err, err
    assert not (tmp_path / "o.npz").exists()


def test_a_distal_wrist_with_fingertip_ik_is_refused_not_ignored():
    """--distal chooses the segment the --ik segments angles read; --ik fingertip places the fingertip alone, so
    --distal wrist with it was taken and left unused (the trials identical to those without it)."""
    from reachirl.cli import build_parser
    from reachirl.cli.preprocess import _options
    from reachirl.errors import InputError

    args = build_parser().parse_args(
        ["preprocess", "r.trc", "--ik", "fingertip", "--distal", "wrist", "--out", "o.npz"]
    )
    with pytest.raises(InputError, match=r"--distal wrist is used with --ik segments only, not --ik fingertip"):
        _options(args)
    for ok in (["--distal", "wrist"], ["--ik", "fingertip"], ["--ik", "fingertip", "--distal", "fingertip"]):
        _options(build_parser().parse_args(["preprocess", "r.trc", *ok, "--out", "o.npz"]))


def test_a_static_trial_a_marker_map_never_reads_is_refused(tmp_path, reach, synth, capsys):
    """--static with a marker map (every joint from the file's own markers) was taken and left unread: the user
    believed the joint centres calibrated on it."""
    (tmp_path / "r.trc").write_text(synth.trc_text(reach.markers, up="y"))
    (tmp_path / "s.trc").write_text(synth.trc_text(reach.markers, up="y"))
    code, _, err = _run(
        [tmp_path / "r.trc", "--markers", synth.MAP, "--static", tmp_path / "s.trc", "--out", tmp_path / "o.npz"],
        capsys,
    )
    assert code == 2 and re.search(r"r\.trc: a static trial is given \(.*s\.trc\), but marker set 'custom'", err), err


@pytest.mark.parametrize(("name", "axis"), [("ADL001FL1", "+x"), ("ADL001FR1", "-x"), ("ADL001FR2", "-x")])
def test_a_lateral_up_axis_is_refused_not_projected_into_nonsense(tmp_path, synth, capsys, name, axis):
    """UE-ADL's lab has z up, y forward, x lateral. --up-axis with the lateral axis (and the default plane) was
    taken: the vertical plane of the reach turned horizontal, the arm was projected across it, and the trial was
    written (ADL001FL1 with +x: q1 -96..-6°, q2 11..109°, where the recording gives -95..-48° and 31..93°). It is
    refused: the arm then stands far out of the plane of the reach and never hangs. The lab's own up axis reads
    it."""
    reach = synth.SAMPLE / "ADL001" / f"{name}.csv"
    args = [reach, "--subject-info", synth.SAMPLE / "subjects.csv", "--markerset", "ue-adl"]
    code, _, err = _run([*args, f"--up-axis={axis}", "--out", tmp_path / "o.npz"], capsys)
    assert code == 2 and not (tmp_path / "o.npz").exists()
    assert len(err.strip().splitlines()) == 1 and re.search(
        rf"^reachirl preprocess: error: {re.escape(str(reach))}: with up = \{axis} \(--up-axis\), the (upper arm|"
        r"forearm \(elbow to fingertip\)) stands [6-9]\d° out of the vertical plane of the reach \(\d\.\d\d s after "
        r"onset\) and the upper arm never hangs within 45° of straight down \([7-9]\d° at best\): is the up axis the "
        r"lab's vertical\? \(check --up-axis\)$",
        err.strip(),
    ), err
    code, _, err = _run([*args, "--up-axis=+z", "--out", tmp_path / "z.npz"], capsys)
    assert code == 0, err


def test_a_recording_whose_axes_are_permuted_needs_its_up_axis(tmp_path, synth, capsys):
    """UE-ADL's reach and static trial with the lab's axes permuted (x, y, z) -> (y, z, x): y is now up and z the
    lateral axis. Read with the ue-adl marker set's +z it was written as a trial of nonsense; it is refused, naming
    the up axis and the marker set that gave it, and with --up-axis +y it gives the recording's own trial."""
    from reachirl.data.readers import read_vicon_csv

    folder = tmp_path / "permuted"
    folder.mkdir()
    for name in ("ADL001FL1", "ADL001_static"):
        md = read_vicon_csv(synth.SAMPLE / "ADL001" / f"{name}.csv")
        markers = {m: md[m][:, [1, 2, 0]] for m in md.names}
        (folder / f"{name}.csv").write_text(synth.vicon_text(markers, rate=md.rate, subject="ADL001"))
    info = ["--subject-info", synth.SAMPLE / "subjects.csv", "--markerset", "ue-adl"]
    code, _, err = _run([folder / "ADL001FL1.csv", *info, "--out", tmp_path / "p.npz"], capsys)
    assert code == 2 and re.search(
        r"ADL001FL1\.csv: with up = \+z \(marker set 'ue-adl'; give --up-axis\), the .* never hangs within 45° of "
        r"straight down .*\(check --up-axis\)$",
        err.strip(),
    ), err
    code, _, err = _run([folder / "ADL001FL1.csv", *info, "--up-axis=+y", "--out", tmp_path / "y.npz"], capsys)
    assert code == 0, err
    code, _, err = _run([synth.SAMPLE / "ADL001" / "ADL001FL1.csv", *info, "--out", tmp_path / "z.npz"], capsys)
    assert code == 0, err
    (y,), (z,) = load_trials(tmp_path / "y.npz"), load_trials(tmp_path / "z.npz")
    np.testing.assert_allclose(y.q, z.q, atol=1e-6)


@pytest.mark.parametrize("name", ["ADL001FR1", "ADL001FL1"])
def test_the_forward_axis_given_as_up_is_refused_naming_the_right_one(tmp_path, synth, capsys, name):
    """UE-ADL's lab has z up and y forward. --up-axis +y (its forward axis) keeps the reach's vertical plane, so the
    up-axis check let it pass, and the joint limits refused it only when the reach's forward direction came out as
    the lab's up (the resting arm then hangs backwards): 26 of the 80 trials, whose fingertip sinks a little as it
    reaches, were written as a raise of an arm held horizontally forward (q1 -15..45°). The sample's reaches end as
    high as they start; here the lab's vertical is tilted 5° (forward sinks), as those 26 reaches sink: the old
    code wrote the trial with +y. It is refused, one line naming the file, the hanging arm and the right axis; the
    lab's +z reads it."""
    from reachirl.data.readers import read_vicon_csv

    a = np.radians(-5.0)
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])
    folder = tmp_path / "tilted"
    folder.mkdir()
    for f in (name, "ADL001_static"):
        md = read_vicon_csv(synth.SAMPLE / "ADL001" / f"{f}.csv")
        markers = {m: md[m] @ tilt.T for m in md.names}
        (folder / f"{f}.csv").write_text(synth.vicon_text(markers, rate=md.rate, subject="ADL001"))
    info = ["--subject-info", synth.SAMPLE / "subjects.csv", "--markerset", "ue-adl"]
    for reach in (folder / f"{name}.csv", synth.SAMPLE / "ADL001" / f"{name}.csv"):  # tilted, and as recorded
        for axis in ("+y", "-y"):
            code, _, err = _run([reach, *info, f"--up-axis={axis}", "--out", tmp_path / "o.npz"], capsys)
            assert code == 2 and not (tmp_path / "o.npz").exists()
            assert re.fullmatch(
                rf"reachirl preprocess: error: {re.escape(str(reach))}: with up = \{axis} \(--up-axis\), the upper "
                r"arm never hangs within 45° of straight down before the reach \([89]\d° at best\), and with \+z "
                rf"\(the up of marker set 'ue-adl'\) it hangs within 1?\d°: is \{axis} a horizontal lab axis\? Give "
                r"--up-axis \+z, or leave --up-axis out\n",
                err,
            ), err
    code, _, err = _run([folder / f"{name}.csv", *info, "--up-axis=+z", "--out", tmp_path / "z.npz"], capsys)
    assert code == 0, err


@pytest.mark.parametrize("option", ["--up-axis", "--forward-axis"])
def test_a_lab_axis_that_is_none_is_refused_naming_its_option(tmp_path, reach, synth, capsys, option):
    """`--up-axis w` was refused only once a recording was read, as "axis must be one of ...", naming neither the
    option nor anything the user gave."""
    import argparse

    from reachirl.cli._args import lab_axis_arg

    with pytest.raises(argparse.ArgumentTypeError, match=r"^expected one of ±x, ±y, ±z, got 'w'$"):
        lab_axis_arg("w")
    assert [lab_axis_arg(a) for a in ("+z", "-y", "X", " z")] == ["+z", "-y", "X", " z"]
    (tmp_path / "r.trc").write_text(synth.trc_text(reach.markers, up="y"))
    args = [tmp_path / "r.trc", "--markers", synth.MAP, "--plane", "axes", option, "w", "--out", tmp_path / "o.npz"]
    with pytest.raises(SystemExit) as stop:
        _run(args, capsys)
    err = capsys.readouterr().err
    assert (
        stop.value.code == 2
        and err == f"reachirl preprocess: error: argument {option}: expected one of ±x, ±y, ±z, got 'w'\n"
    )


@pytest.mark.parametrize(
    "extra",
    [
        ["--markers", "shoulder=A,elbow=B,fingertip=D"],
        ["--up-axis", "+y"],
        ["--plane", "vertical"],
        ["--ik", "fingertip"],
    ],
)
def test_marker_options_for_joint_angle_files_alone_are_refused_not_ignored(tmp_path, extra):
    """A MOT or angle CSV holds the angles themselves: --markers, --up-axis, --plane, --ik (...) given with such
    files alone were taken and left unused. Beside a marker recording they apply to it, and are taken."""
    from reachirl.cli import build_parser
    from reachirl.cli.preprocess import _marker_options, _refuse_marker_options_for_angles
    from reachirl.data.readers import ManifestEntry
    from reachirl.errors import InputError

    args = build_parser().parse_args(["preprocess", "a.mot", *extra, "--out", "o.npz"])
    angles = [ManifestEntry(file=tmp_path / "a.mot", subject="", posture="")]
    with pytest.raises(InputError, match=rf"a\.mot: {extra[0]}.* applies to marker recordings .* every input is a"):
        _refuse_marker_options_for_angles(args, angles, _marker_options(args))
    mixed = [*angles, ManifestEntry(file=tmp_path / "r.trc", subject="", posture="")]
    _refuse_marker_options_for_angles(args, mixed, _marker_options(args))
    plain = build_parser().parse_args(["preprocess", "a.mot", "--cutoff", "8", "--out", "o.npz"])
    _refuse_marker_options_for_angles(plain, angles, _marker_options(plain))
