"""Readers: each format round-trips, units are applied, and every malformed file is refused naming the
problem."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import reachirl
from reachirl.arm import ArmModel
from reachirl.data.readers import (
    AngleData,
    MarkerData,
    detect_format,
    read_angles_csv,
    read_c3d,
    read_file,
    read_manifest,
    read_mot,
    read_subject_info,
    read_trc,
    read_vicon_csv,
)
from reachirl.errors import InputError


def _markers(n=20, seed=0):
    rng = np.random.default_rng(seed)
    return {m: rng.uniform(-0.5, 1.5, (n, 3)) for m in ("SH", "EL", "FT")}


@pytest.mark.parametrize("units", ["mm", "m", "cm"])
def test_trc_round_trip_in_metres(tmp_path, synth, units):
    mk = _markers()
    mk["EL"][3] = np.nan  # an unseen frame
    mk["FT"][6] = 0.0  # at the lab's origin exactly: how exports mark an unseen marker (was read as a position)
    p = tmp_path / "a.trc"
    p.write_text(synth.trc_text(mk, rate=120.0, units=units))
    md = read_trc(p)
    assert md.rate == 120.0 and md.names == ("SH", "EL", "FT") and md.up == "+y"
    np.testing.assert_allclose(md.t, np.arange(20) / 120.0, atol=1e-5)
    np.testing.assert_allclose(md["SH"], mk["SH"], atol=1e-6)
    assert np.isnan(md["EL"][3]).all() and np.isfinite(md["EL"][4]).all()
    assert np.isnan(md["FT"][6]).all() and np.isfinite(md["FT"][[5, 7]]).all()


def test_vicon_csv_bom_prefix_and_gaps(tmp_path, synth):
    mk = _markers()
    mk["FT"][5:8] = np.nan
    p = tmp_path / "v.csv"
    p.write_text(synth.vicon_text(mk, subject="ADL999"), encoding="utf-8")
    assert detect_format(p) == "vicon-csv"
    md = read_file(p)
    assert isinstance(md, MarkerData) and md.names == ("SH", "EL", "FT") and md.rate == 100.0
    np.testing.assert_allclose(md["EL"], mk["EL"], atol=1e-8)
    assert np.isnan(md["FT"][5:8]).all() and np.isfinite(md["FT"][8]).all()


_DEVICES = "Devices\n1000\n,,Imported AMTI 1 - Force\nFrame,Sub Frame,Fx,Fy,Fz\n,,N,N,N\n1,0,0,0,1\n1,1,0,0,2\n\n"


def test_vicon_csv_with_devices_block_first(tmp_path, synth):
    """Nexus writes the Devices (and Joints, Model Outputs, Segments) blocks before Trajectories when they are
    exported too: the Trajectories block is read wherever it is (such a file was taken for an angle CSV)."""
    mk = _markers()
    p = tmp_path / "v.csv"
    p.write_text("\ufeff" + _DEVICES + synth.vicon_text(mk).lstrip("\ufeff"), encoding="utf-8")
    assert detect_format(p) == "vicon-csv"
    md = read_file(p)
    assert md.names == ("SH", "EL", "FT") and md.rate == 100.0
    np.testing.assert_allclose(md["EL"], mk["EL"], atol=1e-8)
    trajectories = "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1\n"
    (tmp_path / "bad.csv").write_text(_DEVICES + trajectories)
    with pytest.raises(InputError, match=r"bad\.csv: line 14: truncated row: 3 fields, expected 5"):
        read_file(tmp_path / "bad.csv")
    (tmp_path / "dev.csv").write_text(_DEVICES)
    with pytest.raises(InputError, match=r"dev\.csv: no 'Trajectories' block \(the file's blocks: Devices\)"):
        read_file(tmp_path / "dev.csv")


def test_vicon_csv_real_sample(synth):
    md = read_vicon_csv(synth.SAMPLE / "ADL001" / "ADL001FR1.csv")
    assert md.n_frames == 339 and len(md.names) == 49 and md.rate == 100.0
    assert "RFTP" in md.names and np.isnan(md["RGTH"]).all()  # landmarks only in the static trial
    assert 0.05 < np.nanmax(np.abs(md["RFTP"])) < 2.0  # mm → m


@pytest.mark.parametrize("prefix", ["", "ADL001:"])
def test_c3d_round_trip(tmp_path, prefix):
    # Vicon's "Subject:Marker" labels are read as the markers' names, as in its CSV (they were not found before)
    ezc3d = pytest.importorskip("ezc3d")
    mk = _markers(n=12)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [200.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = [prefix + m for m in mk]
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, 3, 12))
    pts[:3] = np.stack([mk[m] * 1000 for m in mk], axis=1).transpose(2, 1, 0)
    pts[:3, 1, 4] = np.nan
    pts[:3, 2, 7] = 0.0  # at the lab's origin exactly, residual 0: how some writers mark an unseen point
    c["data"]["points"] = pts
    c.write(str(tmp_path / "a.c3d"))
    md = read_c3d(tmp_path / "a.c3d")
    assert md.rate == 200.0 and md.names == tuple(mk)
    np.testing.assert_allclose(md["FT"][:7], mk["FT"][:7], atol=1e-6)
    assert np.isnan(md["EL"][4]).all() and np.isnan(md[list(mk)[2]][7]).all()
    assert np.isfinite(md[list(mk)[2]][6]).all()


def test_mot_degrees_and_radians(tmp_path):
    q = np.array([[-90.0, 90.0], [-80.0, 70.0], [-60.0, 40.0]])
    body = "time\tq1\tq2\n" + "".join(f"{0.01 * i}\t{a}\t{b}\n" for i, (a, b) in enumerate(q))
    (tmp_path / "d.mot").write_text(f"reach\nversion=1\nnRows=3\nnColumns=3\ninDegrees=yes\nendheader\n{body}")
    ad = read_mot(tmp_path / "d.mot")
    np.testing.assert_allclose(ad.q, np.radians(q))
    rad = "time\tq1\tq2\n" + "".join(f"{0.01 * i}\t{a}\t{b}\n" for i, (a, b) in enumerate(np.radians(q)))
    (tmp_path / "r.mot").write_text(f"reach\ninDegrees=no\nendheader\n{rad}")
    np.testing.assert_allclose(read_file(tmp_path / "r.mot").q, np.radians(q))


@pytest.mark.parametrize(
    ("header", "scale"),
    [("time,q1,q2", 1.0), ("time,q1_deg,q2_deg", np.pi / 180), ("# units: deg\ntime,q1,q2", np.pi / 180)],
)
def test_csv_angle_units(tmp_path, header, scale):
    vals = np.array([[-1.2, 1.5], [-1.0, 1.0], [-0.8, 0.7]]) * (1 / scale if scale != 1 else 1)
    p = tmp_path / "a.csv"
    p.write_text(header + "\n" + "".join(f"{0.01 * i},{a},{b}\n" for i, (a, b) in enumerate(vals)))
    ad = read_file(p)
    assert isinstance(ad, AngleData)
    np.testing.assert_allclose(ad.q, vals * scale)


def test_degrees_declared_as_radians_refused(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("time,q1,q2\n0,-90,90\n0.01,-80,70\n")
    with pytest.raises(InputError, match=r"a\.csv: angles reach 5157°.*degrees declared as radians"):
        read_angles_csv(p)


@pytest.mark.parametrize(
    ("name", "header", "declared"),
    [
        ("r.mot", "reach\ninDegrees=yes\nendheader\ntime\tq1\tq2", r"inDegrees=yes"),
        ("r.mot", "reach\nversion=1\nendheader\ntime\tq1\tq2", r"no inDegrees line: OpenSim's default"),
        ("r.csv", "time,q1_deg,q2_deg", r"the columns' suffix _deg"),
        ("r.csv", "# units: deg\ntime,q1,q2", r"line 1: # units: deg"),
    ],
)
def test_radians_declared_as_degrees_refused(tmp_path, name, header, declared):
    # a reach in radians (q1 -1.57..-0.8, q2 1.6..0.5) read as degrees is a still arm: "no movement" said nothing of
    # the units; every angle within ±π is no reach in degrees
    q = np.column_stack([np.linspace(-1.57, -0.8, 50), np.linspace(1.6, 0.5, 50)])
    sep = "\t" if name.endswith(".mot") else ","
    p = tmp_path / name
    p.write_text(header + "\n" + "".join(f"{0.01 * i}{sep}{a}{sep}{b}\n" for i, (a, b) in enumerate(q)))
    with pytest.raises(
        InputError,
        match=rf"^\S+{name}: every q1 and q2 lies within ±3\.14, read as degrees \({declared}\): that is a reach in "
        r"radians, not in degrees; are radians declared as degrees\?$",
    ):
        read_file(p)


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("", r"file is empty"),
        ("\ufeffTrajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n", r"no data rows"),
        (
            "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2,0,1,2\n",
            r"line 7: truncated row: 4 fields, expected 5",
        ),
        (
            "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2,0,1,abc,3\n",
            r"line 7: non-numeric cell 'abc' in column A\.Y",
        ),
        (
            "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n1,0,1,2,3\n",
            r"frame numbers not increasing",
        ),
        (
            "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,ft,ft,ft\n1,0,1,2,3\n",
            r"unknown length unit 'ft'",
        ),
        (  # decimal commas: each coordinate split in two, read in its neighbour's column (a trailing empty is fine)
            "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3,\n2,0,1,5,2,5,3,5\n",
            r"line 7: 8 fields, more than the 5 the header names: decimal commas \(129,56 for 129\.56\), or a column "
            r"without its marker name\?$",
        ),
        (
            "Trajectories\n0\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2,0,1,2,3\n",
            r"line 2: sampling rate must be a positive number, got 0$",
        ),
        (  # the rate line left out: the marker names' line read as the rate ("non-numeric cell '' in column rate")
            "Trajectories\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2,0,1,2,3\n",
            r"line 2: expected the frame rate in Hz \(a number alone on the line after 'Trajectories'\), found "
            r"',,S:A,,'$",
        ),
        (
            "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2.5,0,1,2,3\n",
            r"line 7: frame number 2\.5 is not a whole number",
        ),
        (
            "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n99999999,0,1,2,3\n",
            r"line 7: frame numbers jump from 1 to 1e\+08: a corrupt frame number\?",
        ),
    ],
)
def test_vicon_csv_errors(tmp_path, text, pattern):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=r"bad\.csv: .*" + pattern if text else pattern):
        read_vicon_csv(p)


def test_vicon_csv_rows_left_out_are_unseen_frames(tmp_path):
    """A Vicon CSV whose Frame column skips rows: the skipped frames are unseen (NaN), on the file's own clock
    (they were once dropped, which shortened the reach and inflated its speed)."""
    head = "Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n"
    rows = [f"{f},0,{f},0,0\n" for f in (1, 2, 3, 7, 8)]
    (tmp_path / "gap.csv").write_text(head + "".join(rows))
    md = read_vicon_csv(tmp_path / "gap.csv")
    np.testing.assert_allclose(md.t, np.arange(8) / 100.0)
    x = md["A"][:, 0]
    np.testing.assert_allclose(x[[0, 1, 2, 6, 7]], [0.001, 0.002, 0.003, 0.007, 0.008])
    assert np.all(np.isnan(x[3:6]))


def test_a_lab_in_millimetres_declared_as_metres_is_named_as_such(tmp_path, synth):
    mk = {k: v * 1000.0 for k, v in _markers(n=5).items()}  # the values of a file in mm
    (tmp_path / "m.trc").write_text(synth.trc_text(mk, units="m"))
    with pytest.raises(
        InputError,
        match=r"m\.trc: frame \d+: marker 'SH' is .* m from the lab's origin, beyond any lab "
        r"\(1000 m\): millimetres declared as metres\? \(the file's units\)",
    ):
        read_trc(tmp_path / "m.trc")
    mk = _markers(n=5)
    mk["SH"][2] = 1e6  # m: far beyond even that, a corrupt value
    (tmp_path / "c.trc").write_text(synth.trc_text(mk, units="mm"))
    with pytest.raises(InputError, match=r"c\.trc: frame 3: marker 'SH' is 1e\+06 m .*: a corrupt value\?"):
        read_trc(tmp_path / "c.trc")


def test_trc_time_not_increasing(tmp_path, synth):
    text = synth.trc_text(_markers(n=5)).replace("\t0.02000\t", "\t0.00500\t")
    (tmp_path / "t.trc").write_text(text)
    with pytest.raises(InputError, match=r"t\.trc: frame 3: time is not strictly increasing"):
        read_trc(tmp_path / "t.trc")


def test_a_marker_time_column_that_skips_or_jitters_is_refused_naming_the_frame(tmp_path, synth):
    """A TRC with a row deleted (the frames numbered again) or a Time column jittered was read as evenly sampled:
    a row left out at the peak speed gave torques of 62 N·m for 10. Times written with three decimals at 120 Hz
    (steps of 8 and 9 ms) are a sampling, and pass."""
    lines = synth.trc_text(_markers(n=20), rate=100.0).splitlines()
    head, rows = lines[:6], lines[6:]
    del rows[9]  # frame 10; frames 11 ... numbered again from 10, their times kept
    rows = [f"{i + 1}\t" + r.split("\t", 1)[1] for i, r in enumerate(rows)]
    (tmp_path / "gap.trc").write_text("\n".join([*head, *rows]).replace("\t20\t", "\t19\t", 1) + "\n")
    with pytest.raises(
        InputError,
        match=r"gap\.trc: frame 10: the time steps 0\.02 s from frame 9 to 10, where the recording's steps are "
        r"0\.01 s \(frames missing\?\): the filters need even sampling$",
    ):
        read_trc(tmp_path / "gap.trc")
    t = 0.01 * np.arange(12) + np.where(np.arange(12) == 6, 0.004, 0.0)
    with pytest.raises(InputError, match=r"j: frame 7: the time steps 0\.014 s from frame 6 to 7, .*uneven Time"):
        MarkerData(rate=100.0, markers={"FT": np.ones((12, 3))}, source="j", t=t)
    rounded = np.round(np.arange(40) / 120.0, 3)  # steps of 8 and 9 ms
    assert MarkerData(rate=120.0, markers={"FT": np.ones((40, 3))}, t=rounded).n_frames == 40


def test_angle_csv_errors(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("time,q1\n0,1\n")
    with pytest.raises(InputError, match=r"a\.csv: line 1: no 'q2' column"):
        read_angles_csv(p)
    p.write_text("time,q1,q2\n0,1,1\n0,1.1,1\n")
    with pytest.raises(InputError, match=r"sample 2: time is not strictly increasing"):
        read_angles_csv(p)
    p.write_text("# units: furlongs\ntime,q1,q2\n0,1,1\n")
    with pytest.raises(InputError, match=r"unknown angle unit 'furlongs'"):
        read_angles_csv(p)


def test_subject_info_both_layouts(tmp_path, synth):
    ue = read_subject_info(synth.SAMPLE / "subjects.csv")
    s = ue["ADL001"]
    assert (s.sex, s.height_m, s.mass_kg, s.upper_arm_m) == ("F", 1.702, 96.0, None)
    p = tmp_path / "info.csv"
    p.write_text("subject,sex,height_m,mass_kg,upper_arm_m,forearm_m,hand_m\nS1,male,1.8,75,0.3,,0.19\n")
    s1 = read_subject_info(p)["S1"]
    assert (s1.sex, s1.upper_arm_m, s1.forearm_m, s1.hand_m) == ("M", 0.3, None, 0.19)
    for sex in ("X", "Mouse"):  # not read as its first letter
        p.write_text(f"subject,sex,height_m,mass_kg\nS1,{sex},1.8,75\n")
        with pytest.raises(InputError, match=r"info\.csv: line 2: sex must be M or F"):
            read_subject_info(p)
    p.write_text("subject,sex,height_m,mass_kg\nS1,M,180,75\n")
    with pytest.raises(InputError, match=r"height_m 180.0 is not a stature in metres"):
        read_subject_info(p)


@pytest.mark.parametrize(
    ("column", "value"), [("height_m", 172.0), ("mass_kg", 72000.0), ("mass_kg", 7.0), ("forearm_m", 27.0)]
)
def test_a_subject_info_file_and_the_arm_model_refuse_a_value_in_the_same_words(tmp_path, column, value):
    # the reader said "height_m 172.0 is not a stature in metres (0.5-2.6)", the arm model "height_m must be a
    # plausible stature in metres, got 172.0", for one range
    from reachirl.arm import ArmModel

    row = {"height_m": 1.7, "mass_kg": 70.0, "forearm_m": 0.26, column: value}
    p = tmp_path / "info.csv"
    p.write_text(f"subject,sex,{','.join(row)}\nS7,M,{','.join(map(str, row.values()))}\n")
    with pytest.raises(ValueError) as arm:
        ArmModel.from_anthropometrics(sex="M", **row)
    with pytest.raises(InputError) as info:
        read_subject_info(p)
    assert info.value.reason == f"subject S7: {arm.value}"
    assert str(arm.value).startswith(f"{column} {value} is not a ")


@pytest.mark.parametrize(
    ("cells", "match"),
    [
        (
            "1.6,160",
            r"subject S7: mass_kg 160.0 and height_m 1.6 give a body-mass index of 62.5 kg/m², not a person's "
            r"\(12-60\); mass_kg in pounds \(72.6 kg\)\?$",
        ),
        (
            "1.75,11",
            r"subject S7: mass_kg 11.0 and height_m 1.75 give a body-mass index of 3.6 kg/m², not a person's "
            r"\(12-60\); mass_kg in stones \(69.9 kg\)\?$",
        ),
        ("2.5,70", r"subject S7: mass_kg 70.0 and height_m 2.5 give a body-mass index of 11.2 kg/m², .*; check both"),
    ],
)
def test_a_mass_in_pounds_is_refused_by_its_body_mass_index(tmp_path, cells, match):
    # 160 (lb) for a 73 kg person of 1.60 m lay within 10-300 kg and built an arm 2.2 times too heavy
    p = tmp_path / "info.csv"
    p.write_text(f"subject,sex,height_m,mass_kg\nS7,F,{cells}\n")
    with pytest.raises(InputError, match=r"^\S+info\.csv: line 2: " + match):
        read_subject_info(p)
    with pytest.raises(ValueError, match=match.removeprefix("subject S7: ")):
        ArmModel.from_anthropometrics(*map(float, cells.split(",")), "F")


def test_a_rare_body_mass_index_is_taken_with_a_note_of_its_mass_in_pounds(tmp_path, caplog):
    # a mass in pounds of a person of ordinary build (BMI 23: 154 lb at 1.75 m) reads as a BMI of 50, which real
    # people have: taken as written, the note says what it would be in pounds
    p = tmp_path / "info.csv"
    p.write_text("subject,sex,height_m,mass_kg\nS7,M,1.75,154\nS8,M,1.75,70\n")
    with caplog.at_level("WARNING", logger="reachirl"):
        info = read_subject_info(p)
    assert info["S7"].mass_kg == 154.0
    assert caplog.messages == [
        f"{p}: line 2: subject S7: mass_kg 154.0 and height_m 1.75 give a body-mass index of 50.3 kg/m², rare: if "
        "the mass is in pounds it is 69.9 kg (taken as 154.0 kg)"
    ]


def test_every_virtual_and_ue_adl_subject_has_a_body_mass_index_in_range():
    from reachirl.arm import bmi_note, bmi_problem
    from reachirl.virtual.population import draw_subject

    drawn = [draw_subject(seed, i) for seed in range(20) for i in range(50)]  # synth's population
    sample = Path(reachirl.__file__).parent / "data" / "ue_adl_sample" / "subjects.csv"
    subjects = [(s.height_m, s.mass_kg) for s in [*drawn, *read_subject_info(sample).values()]]
    assert [s for s in subjects if bmi_problem(*s) or bmi_note(*s)] == []


def test_manifest_paths_relative_to_it(tmp_path):
    (tmp_path / "sub").mkdir()
    m = tmp_path / "sub" / "manifest.csv"
    m.write_text("file,subject,posture,side\nr1.trc,S1,P2,L\n")
    (e,) = read_manifest(m)
    assert e.file == tmp_path / "sub" / "r1.trc" and (e.subject, e.posture, e.side) == ("S1", "P2", "left")


def test_angles_of_two_arms_in_one_file_are_read_for_the_side_given_not_as_the_first(tmp_path):
    rows = "\n".join(f"{k / 100:.2f}\t0\t10\t{-90 + k}\t{90 - k}" for k in range(50))
    p = tmp_path / "both.mot"
    p.write_text(
        "both\nnRows=50\nnColumns=5\ninDegrees=yes\nendheader\n"
        f"time\tr_shoulder_elev\tr_elbow_flex\tl_shoulder_elev\tl_elbow_flex\n{rows}\n"
    )
    with pytest.raises(InputError, match=r"both\.mot: line 6: columns r_shoulder_elev and l_shoulder_elev all give q1"):
        read_mot(p)
    # given the arm, its own columns (the shoulder's 90° offset of OpenSim's elevation on either side)
    left, right = read_mot(p, side="left"), read_file(p, side="right")
    np.testing.assert_allclose(np.degrees(left.q[:3]), [[-180, 90], [-179, 89], [-178, 88]], atol=1e-9)
    np.testing.assert_allclose(np.degrees(right.q[:3]), [[-90, 10]] * 3, atol=1e-9)
    c = tmp_path / "one.csv"  # one angle in two units (reachirl's own exports) is one column
    c.write_text(
        "time_s,demo_q1_rad,demo_q2_rad,demo_q1_deg,demo_q2_deg\n0,-1.5,1.5,-85.9,85.9\n0.01,-1.4,1.4,-80.2,80.2\n"
    )
    np.testing.assert_allclose(read_angles_csv(c).q, [[-1.5, 1.5], [-1.4, 1.4]])


@pytest.mark.parametrize(
    ("read", "text"),
    [
        (read_subject_info, "subject,sex,height_m,mass_kg,height_m\nS1,M,1.76,70,1.20\n"),
        (read_manifest, "file,subject,posture,subject\nr1.trc,S1,P2,S2\n"),
    ],
)
def test_a_column_named_twice_is_refused_not_read_from_the_last(tmp_path, read, text):
    p = tmp_path / "info.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=r"info\.csv: line 1: column\(s\) (height_m|subject) appear more than once"):
        read(p)


def test_a_column_the_reader_ignores_may_be_named_twice(tmp_path):
    # a spreadsheet's second "notes" column holds nothing the reader takes: the file is read, not refused
    p = tmp_path / "info.csv"
    p.write_text("subject,notes,sex,height_m,mass_kg,notes\nS1,a,M,1.76,70,b\n")
    assert read_subject_info(p)["S1"].height_m == 1.76
    m = tmp_path / "manifest.csv"
    m.write_text("file,notes,subject,posture,notes\nr1.trc,a,S1,P2,b\n")
    assert [e.subject for e in read_manifest(m)] == ["S1"]


@pytest.mark.parametrize(
    ("unit", "scale"), [("millimeter", 1e-3), ("Millimetre", 1e-3), ("centimeter", 1e-2), ("metre", 1.0)]
)
def test_singular_length_units_are_read(tmp_path, unit, scale):
    p = tmp_path / "u.csv"
    p.write_text(f"Trajectories\n100\n,,S:A,,\nFrame,Sub Frame,X,Y,Z\n,,{unit},{unit},{unit}\n1,0,1,2,3\n2,0,1,2,4\n")
    np.testing.assert_allclose(read_vicon_csv(p).markers["A"][1], np.array([1.0, 2.0, 4.0]) * scale)


def test_c3d_with_another_subjects_marker_keeps_the_recorded_subjects_names(tmp_path):
    """One stray "ADL002:FT" among ADL001's markers: ADL001's are read by their bare names (they were all left
    prefixed, and the marker set found none of them)."""
    ezc3d = pytest.importorskip("ezc3d")
    mk = _markers(n=12)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = [f"ADL001:{m}" for m in mk] + ["ADL002:FT"]
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    pts = np.ones((4, 4, 12))
    pts[:3, :3] = np.stack([mk[m] for m in mk], axis=1).transpose(2, 1, 0)
    pts[:3, 3] = 0.5
    c["data"]["points"] = pts
    c.write(str(tmp_path / "a.c3d"))
    md = read_c3d(tmp_path / "a.c3d")
    assert md.names == (*mk, "ADL002:FT")
    np.testing.assert_allclose(md["FT"], mk["FT"], atol=1e-6)


def test_c3d_of_two_subjects_alike_is_not_guessed(tmp_path):
    """Two subjects with three and four markers: neither is clearly the one recorded, so the names stay prefixed
    (and a marker set then says which marker it cannot find) rather than one being picked silently."""
    ezc3d = pytest.importorskip("ezc3d")
    labels = ["S1:SH", "S1:EL", "S1:FT", "S2:SH", "S2:EL", "S2:FT", "S2:HEAD"]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    pts = np.ones((4, len(labels), 5))
    pts[:3] = np.random.default_rng(0).uniform(0.1, 1.0, (3, len(labels), 5))
    c["data"]["points"] = pts
    c.write(str(tmp_path / "two.c3d"))
    assert read_c3d(tmp_path / "two.c3d").names == tuple(labels)


def test_trc_rows_read_alike_whether_each_cell_is_a_number_or_not(tmp_path):
    """A row of numbers is read in one pass, a row with a blank cell cell by cell: both read a cell alike (signs,
    exponents, NaN, spaces around it, Windows line endings, a tab ending the line)."""
    head = (
        "PathFileType\t4\t(X/Y/Z)\tt.trc\r\nDataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\r\n"
        "100\t100\t2\t2\tm\r\nFrame#\tTime\tA\t\t\tB\t\t\r\n\t\tX1\tY1\tZ1\tX2\tY2\tZ2\r\n"
    )
    cells = "1e-1\t+1\t-0\t NaN \tnan\t 2.5"
    p = tmp_path / "t.trc"
    p.write_bytes(f"{head}1\t0\t{cells}\t\r\n2\t0.01\t{cells.replace('nan', ' ')}\t\r\n".encode())
    m = read_trc(p)
    for marker, row in (("A", [0.1, 1.0, -0.0]), ("B", [np.nan, np.nan, 2.5])):
        np.testing.assert_array_equal(m.markers[marker], [row, row])
    assert np.signbit(m.markers["A"][:, 2]).all()


@pytest.mark.parametrize(
    ("cells", "match"),
    [
        ("1.702,72000", r"subject S7: mass_kg 72000.0 is not a body mass in kg \(10-300\); in grams\?$"),
        ("172,72", r"subject S7: height_m 172.0 is not a stature in metres \(0.5-2.6\); in centimetres\?$"),
        ("1720,72", r"subject S7: height_m 1720.0 is not a stature in metres \(0.5-2.6\); in millimetres\?$"),
        (
            "1.72,72,28.4",
            r"subject S7: upper_arm_m 28.4 is not a segment length in metres \(0.02-1.0\); in centimetres",
        ),
        (
            "1.72,72,284",
            r"subject S7: upper_arm_m 284.0 is not a segment length in metres \(0.02-1.0\); in millimetres",
        ),
        ("1.72,7", r"subject S7: mass_kg 7.0 is not a body mass in kg \(10-300\)$"),  # no unit fits: none guessed
    ],
)
def test_a_subject_info_in_other_units_is_refused_naming_the_subject_column_and_likely_unit(tmp_path, cells, match):
    p = tmp_path / "info.csv"
    p.write_text(f"subject,sex,height_m,mass_kg,upper_arm_m\nS7,F,{cells}\n")
    with pytest.raises(InputError, match=r"^\S+info\.csv: line 2: " + match):
        read_subject_info(p)
