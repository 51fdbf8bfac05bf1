"""Preprocessing on known geometry: markers made from a known q trajectory must give q back."""

from __future__ import annotations

import re
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from reachirl.data.kinematics import cast_reconstruct, kabsch
from reachirl.data.markersets import load_markerset, parse_marker_map
from reachirl.data.preprocess import PreprocessOptions, angles_to_trial, markers_to_trial, reconstruct_markers
from reachirl.data.readers import AngleData, MarkerData, SubjectInfo, read_file, read_vicon_csv
from reachirl.data.segmentation import detect_onset_offset
from reachirl.data.signal import fill_gaps, lowpass
from reachirl.data.trial import load_trials, save_trials
from reachirl.errors import InputError


def _trial(synth, markers, rate=100.0, source="s.trc"):
    """The trial ``markers_to_trial`` makes of ``markers`` (the synthetic marker map)."""
    kw = {"subject": "S1", "posture": "P2", "trial_id": "1"}
    return markers_to_trial(MarkerData(rate, markers, source=source), parse_marker_map(synth.MAP), **kw)


def _rec(reach, synth, side="right", options=None, markers=None, **kw):
    md = MarkerData(100.0, markers or reach.markers, source="synthetic.trc")
    return reconstruct_markers(md, parse_marker_map(synth.MAP), side=side, options=options, **kw)


# ---------------------------------------------------------------------- small steps
def test_fill_gaps_short_by_spline_long_refused():
    t = np.linspace(0, 1, 101)
    x = np.stack([np.sin(2 * np.pi * t), np.cos(2 * np.pi * t), t], axis=1)
    g = x.copy()
    g[40:46] = np.nan
    g[:2] = np.nan
    filled = fill_gaps(g, max_gap=10, name="EL")
    np.testing.assert_allclose(filled[40:46], x[40:46], atol=2e-4)
    np.testing.assert_allclose(filled[:2], np.repeat(x[2:3], 2, axis=0))
    g[60:75] = np.nan
    with pytest.raises(InputError, match=r"f\.trc: marker EL is missing for 15 frames \(61-75\), longer than the 10"):
        fill_gaps(g, max_gap=10, name="EL", source="f.trc")
    one = x.copy()
    one[50] = np.nan
    with pytest.raises(InputError, match=r"marker EL is missing in frame 51, and gap filling is off \(--max-gap 0\)$"):
        fill_gaps(one, max_gap=0, name="EL")
    one[51] = np.nan
    with pytest.raises(InputError, match=r"missing for 2 frames \(51-52\), longer than the 1 frame gap filling allows"):
        fill_gaps(one, max_gap=1, name="EL")


def test_lowpass_zero_lag_removes_noise():
    rate = 100.0
    t = np.arange(400) / rate
    clean = np.sin(2 * np.pi * 1.5 * t)
    noisy = clean + 0.2 * np.sin(2 * np.pi * 35 * t)
    out = lowpass(noisy, rate, 10.0, 5)
    inner = slice(50, -50)
    assert np.abs(out - clean)[inner].max() < 5e-3  # no lag: a shift would leave ~0.1 error at 1.5 Hz
    assert np.abs(noisy - clean)[inner].max() > 0.15
    with pytest.raises(InputError, match=r"10 Hz low-pass needs a sampling rate above 20 Hz"):
        lowpass(noisy, 15.0, 10.0)


def test_kabsch_and_cast_recover_a_rigid_landmark():
    rng = np.random.default_rng(1)
    ref = rng.normal(size=(4, 3)) * 0.05
    point = np.array([0.02, -0.1, 0.03])
    angles = np.linspace(0, 1.2, 30)
    R = np.stack([[[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]] for a in angles])
    t = np.stack([angles, 2 * angles, np.ones_like(angles)], axis=1)
    cluster = np.einsum("nij,kj->nki", R, ref) + t[:, None, :]
    R_est, _ = kabsch(np.broadcast_to(ref, cluster.shape), cluster)
    np.testing.assert_allclose(R_est, R, atol=1e-10)
    cluster[5, 2] = np.nan  # 3 markers still seen
    out = cast_reconstruct(cluster, ref, point)
    np.testing.assert_allclose(out, np.einsum("nij,j->ni", R, point) + t, atol=1e-10)


def test_onset_offset_on_min_jerk(synth):
    # Cartesian min-jerk speed ∝ τ²(1-τ)²: 5 % of the peak is crossed at τ = 0.0593 and 0.9407
    rate, rest, T = 1000.0, 0.3, 0.7
    t = np.arange(round((2 * rest + T) * rate) + 1) / rate
    tau = np.clip((t - rest) / T, 0, 1)
    speed = 30 * tau**2 * (1 - tau) ** 2 / T
    on, off = detect_onset_offset(speed, 0.05)
    tau_c = 0.5 - np.sqrt(0.25 - np.sqrt(0.05 * 1.875 / 30))
    assert abs(t[on] - (rest + tau_c * T)) < 1.5 / rate
    assert abs(t[off] - (rest + (1 - tau_c) * T)) < 1.5 / rate


def test_a_recording_of_the_reach_and_a_faster_return_gives_the_reach(reach, synth):
    """Reach, rest, then the way back at twice the speed: the fastest movement is the return, and the trial must
    still be the reach (it was the return, read as a mirrored reach and refused)."""
    _, back = synth.min_jerk_q(reach.q[-1], reach.q[0], duration=0.4, rest=0.5)
    both = np.concatenate([reach.q, back[1:]])
    alone = _rec(reach, synth)
    whole = _rec(reach, synth, markers=synth.lab_markers(reach.arm, both))
    assert whole.t[whole.offset] < reach.t[-1]  # ends before the return starts
    assert abs((whole.offset - whole.onset) - (alone.offset - alone.onset)) <= 1
    np.testing.assert_allclose(whole.q[whole.offset], alone.q[alone.offset], atol=np.radians(0.5))


# ---------------------------------------------------------------------- known geometry
@pytest.mark.parametrize(
    "options",
    [
        PreprocessOptions(),
        PreprocessOptions(ik="fingertip"),
        PreprocessOptions(distal="wrist"),
        PreprocessOptions(plane="vertical"),
    ],
    ids=["segments", "berret-ik", "wrist", "vertical"],
)
def test_known_q_recovered_within_0_1_deg(reach, synth, options):
    rec = _rec(reach, synth, options=options)
    sl = slice(rec.onset, rec.offset + 1)
    assert np.degrees(np.abs(rec.q[sl] - reach.q[sl])).max() < 0.1
    assert rec.lengths["upper_arm"] == pytest.approx(reach.arm.l1, abs=1e-6)
    assert rec.arm.l2 == pytest.approx(reach.arm.l2, abs=1e-6)
    # the fingertip moved forward (+x) and the basis' up is the lab's Z
    assert rec.fingertip[rec.offset, 0] > rec.fingertip[rec.onset, 0]
    assert rec.basis[1] @ [0, 0, 1] > 0.99


def test_left_arm_mirrors_onto_the_right(reach, synth):
    left = synth.lab_markers(reach.arm, reach.q, side="left")
    right = _rec(reach, synth)
    rec = _rec(reach, synth, side="left", markers=left)
    np.testing.assert_allclose(rec.q, right.q, atol=1e-9)
    assert (rec.onset, rec.offset) == (right.onset, right.offset)
    # once mirrored, the left arm's 3-D joints coincide with the right arm's
    np.testing.assert_allclose(rec.joints["elbow"][:, 0], right.joints["elbow"][:, 0], atol=1e-9)


def _min_jerk_torques(arm, t, q0=(-1.4, 1.6), qf=(-0.6, 0.5), duration=0.8, rest=0.5):
    """Torques of the conftest's minimum-jerk reach at times ``t``, from its analytic derivatives and RNEA."""
    import pinocchio as pin

    tau_ = np.clip((np.asarray(t) - rest) / duration, 0, 1)
    dq = np.asarray(qf) - np.asarray(q0)
    s = 10 * tau_**3 - 15 * tau_**4 + 6 * tau_**5
    ds = (30 * tau_**2 - 60 * tau_**3 + 30 * tau_**4) / duration
    dds = (60 * tau_ - 180 * tau_**2 + 120 * tau_**3) / duration**2
    model = arm.pinocchio_model()
    data = model.createData()
    return np.array(
        [
            pin.rnea(model, data, np.asarray(q0) + dq * a, dq * b, dq * c).copy()
            for a, b, c in zip(s, ds, dds, strict=True)
        ]
    )


def test_trial_fields_and_dynamics(reach, synth):
    md = MarkerData(100.0, reach.markers, source="s.trc")
    tr = markers_to_trial(md, parse_marker_map(synth.MAP), subject="S1", posture="P2", trial_id="7")
    assert tr.t[0] == 0 and tr.duration == pytest.approx(0.68, abs=0.03)
    # the torques are the true ones: Pinocchio's RNEA on the analytic minimum-jerk reach at the same instants
    # (the recording's 10 Hz filter leaves a small error)
    k0 = min(range(40, 70), key=lambda k: np.abs(reach.q[k : k + len(tr.t)] - tr.q).max())
    tau_true = _min_jerk_torques(reach.arm, reach.t[k0 : k0 + len(tr.t)])
    err = np.sqrt(np.mean((tr.tau - tau_true) ** 2)) / np.sqrt(np.mean((tau_true - tau_true.mean(0)) ** 2))
    assert err < 0.08, err  # measured 0.045 of the torques' variation; a wrong mass or gravity is far above
    # the velocities come from the same angles: integrating qd gives q back
    dq = np.cumsum((tr.qd[1:] + tr.qd[:-1]) / 2 * np.diff(tr.t)[:, None], axis=0)
    np.testing.assert_allclose(tr.q[1:] - tr.q[0], dq, atol=2e-3)
    assert tr.target_x == pytest.approx(reach.arm.fk(reach.q[-1])[0], abs=1e-3)
    assert np.degrees(np.abs(tr.x0[:2] - reach.q[k0])).max() < 0.1  # the true posture at onset
    r200 = markers_to_trial(
        md,
        parse_marker_map(synth.MAP),
        subject="S1",
        posture="P2",
        trial_id="7",
        options=PreprocessOptions(n_samples=200),
    )
    assert r200.q.shape == (200, 2) and r200.duration == pytest.approx(tr.duration)


def test_torques_agree_with_pinocchio_rnea(reach, synth):
    pin = pytest.importorskip("pinocchio")
    md = MarkerData(100.0, reach.markers, source="s.trc")
    tr = markers_to_trial(md, parse_marker_map(synth.MAP), subject="S1", posture="P", trial_id="1")
    model = tr.arm.pinocchio_model()
    data = model.createData()
    for k in range(0, len(tr.t), 10):
        tau = pin.rnea(model, data, tr.q[k], tr.qd[k], tr.qdd[k])
        np.testing.assert_allclose(tau, tr.tau[k], atol=1e-9)


def test_round_trip_save_load(tmp_path, reach, synth):
    md = MarkerData(100.0, reach.markers, source="s.trc")
    trials = [
        markers_to_trial(md, parse_marker_map(synth.MAP), subject="S1", posture="P1", trial_id=str(i), side=side)
        for i, side in enumerate(("right", "left"))
    ]
    back = load_trials(save_trials(tmp_path / "t.npz", trials))
    for a, b in zip(trials, back, strict=True):
        assert (a.id, a.source, a.target_x, a.arm) == (b.id, b.source, b.target_x, b.arm)
        for name in ("t", "q", "qd", "qdd", "tau", "x0"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_a_trial_in_degrees_is_refused_where_it_is_made(tmp_path, synth):
    """UE-ADL's ADL001FR1 preprocessed (q1 -97..-49°, q2 28..94°), then given in degrees, as another tool's export
    would: the Trial was made and saved, and refused only where a fit checked it against the joint limits (the start
    q0 = (-5131.5°, ...)). It is refused where it is made, and a trials file holding it where it is loaded, naming
    the field and radians; the angles in radians, within two turns, are kept."""
    from dataclasses import replace as renew

    from reachirl.data.readers import read_subject_info

    d = synth.SAMPLE / "ADL001"
    info = read_subject_info(synth.SAMPLE / "subjects.csv")["ADL001"]
    trial = markers_to_trial(
        read_vicon_csv(d / "ADL001FR1.csv"),
        load_markerset("ue-adl"),
        subject="ADL001",
        posture="forward",
        trial_id="FR1",
        static=read_vicon_csv(d / "ADL001_static.csv"),
        subject_info=info,
    )
    degrees = {"q": np.degrees(trial.q), "qd": np.degrees(trial.qd), "qdd": np.degrees(trial.qdd)}
    said = r"q must be in radians, got 9\d(\.\d+)? at most: beyond any joint's 2 turns \(12\.57 rad; degrees\?\)$"
    with pytest.raises(InputError, match=rf"^{re.escape(trial.source)}: {said}"):
        renew(trial, x0=None, **degrees)
    with pytest.raises(InputError, match=r": x0's angles must be in radians, got 9\d(\.\d+)? at most"):
        renew(trial, x0=np.r_[np.degrees(trial.q[0]), trial.qd[0]])
    # a trials file written in degrees by another tool: refused as it is loaded, naming the file and the trial
    path = save_trials(tmp_path / "t.npz", [trial])
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update({f"0/{k}": v for k, v in degrees.items()})
    arrays["0/x0"] = np.r_[degrees["q"][0], degrees["qd"][0]]
    np.savez(tmp_path / "deg.npz", **arrays)
    with pytest.raises(InputError, match=rf"deg\.npz: trial 0 \(ADL001/forward/right/FR1\): {said}"):
        load_trials(tmp_path / "deg.npz")
    assert load_trials(path) == [trial]  # radians load
    turned = renew(trial, q=trial.q + 2 * np.pi, x0=None)  # an angle convention a turn away is still radians
    assert np.abs(turned.q).max() > 2 * np.pi


def test_angles_to_trial(reach):
    info = SubjectInfo("S1", "M", 1.76, 70.0, upper_arm_m=0.30, forearm_m=0.26, hand_m=0.18)
    tr = angles_to_trial(
        AngleData(reach.t, reach.q, "a.mot"),
        subject="S1",
        posture="P",
        trial_id="1",
        subject_info=info,
        options=PreprocessOptions(cutoff_hz=None),
    )
    assert tr.arm == reach.arm
    n = len(tr.t)
    k0 = min(range(50, 61), key=lambda k: np.abs(reach.q[k : k + n] - tr.q).max())  # onset just after the rest
    np.testing.assert_allclose(tr.q, reach.q[k0 : k0 + n], atol=1e-12)
    assert tr.target_x == pytest.approx(reach.arm.fk(tr.q[-1])[0])
    # unfiltered exact angles: the spline's derivatives give the true torques (RNEA on the analytic reach)
    tau_true = _min_jerk_torques(reach.arm, reach.t[k0 : k0 + n])
    assert np.sqrt(np.mean((tr.tau - tau_true) ** 2)) < 0.01 * np.abs(tau_true).max()


# ---------------------------------------------------------------------- refusals
def test_no_movement(reach, synth):
    still = {k: np.repeat(v[:1], len(v), axis=0) for k, v in reach.markers.items()}
    with pytest.raises(InputError, match=r"synthetic\.trc: no movement detected: the fingertip's peak speed"):
        _rec(reach, synth, markers=still)


@pytest.mark.parametrize(("shoulder_mm", "fingertip_mm"), [(1.0, 1.0), (1.5, 1.5), (0.5, 2.0), (1.0, 3.0)])
def test_a_noisy_recording_of_rest_is_no_reach(synth, synth_arm, shoulder_mm, fingertip_mm):
    """A recording of the arm at rest, with 1-3 mm of marker noise: the noise carried the fingertip's 10 Hz speed
    above 0.05 m/s, and the record was refused as 'are the markers swapped?' (the shoulder's noisy path as long
    as the fingertip's), or, with a noisier fingertip, written as a trial of noise (onset and offset in it)."""
    _, q = synth.min_jerk_q([-1.4, 1.6], [-1.4, 1.6], rest=1.0)
    rng = np.random.default_rng(0)
    sd = {"SH": shoulder_mm / 1000}
    rest = {
        k: v + rng.normal(0.0, sd.get(k, fingertip_mm / 1000), v.shape)
        for k, v in synth.lab_markers(synth_arm, q).items()
    }
    with pytest.raises(
        InputError, match=r"s\.trc: no movement detected: the fingertip ranges over \d mm, less than 5% of its distance"
    ):
        _trial(synth, rest)


@pytest.mark.parametrize("sd_deg", [0.1, 0.3])
def test_a_noisy_joint_angle_recording_of_rest_is_no_reach(sd_deg):
    """The angles' path as the markers': a joint-angle file of the arm at rest with 0.1-0.3° of noise (1-3 mm at the
    fingertip) carried the speed above 0.05 m/s and was written as a trial of noise (0.1-0.3 s long)."""
    t = np.arange(300) / 100.0
    q = np.deg2rad([-80.0, 60.0]) + np.deg2rad(sd_deg) * np.random.default_rng(0).normal(size=(300, 2))
    with pytest.raises(
        InputError,
        match=r"^r\.mot: no movement detected: the fingertip ranges over \d mm, less than 5% of its distance from the "
        r"shoulder \(\d+ mm\): rest and angle noise, not a reach$",
    ):
        angles_to_trial(AngleData(t, q, "r.mot"), subject="S1", posture="P", trial_id="1")


@pytest.mark.parametrize(
    ("scale", "said"),
    [
        (1e-3, r"0\.3 mm, absurdly small for an arm \(metres declared as mm\?\)"),
        (1e-1, r"30 mm, absurdly small for an arm \(centimetres declared as mm\?\)"),  # was "metres as mm"
        (10.0, r"3 m, absurdly large for an arm \(millimetres declared as cm\?\)"),  # was "mm as metres"
        (1e2, r"30 m, absurdly large for an arm \(centimetres declared as metres\?\)"),
    ],
)
def test_units_look_wrong_and_the_mistake_is_named_by_its_factor(reach, synth, scale, said):
    scaled = {k: v * scale for k, v in reach.markers.items()}
    with pytest.raises(InputError, match=r"units look wrong: the median upper arm distance is " + said):
        _rec(reach, synth, markers=scaled)


def test_subject_info_too_short_for_the_markers(reach, synth):
    """Segments half the markers' lengths would make the target unreachable: refused, naming the field."""
    short = SubjectInfo("S1", "M", 1.76, 70.0, upper_arm_m=0.15, forearm_m=0.12, hand_m=0.08)
    md = MarkerData(100.0, reach.markers, source="s.trc")
    too_short = r"s\.trc: subject S1: subject-info upper_arm_m = 0\.150 m but the markers measure 0\.300 m"
    with pytest.raises(InputError, match=too_short):
        markers_to_trial(md, parse_marker_map(synth.MAP), subject="S1", posture="P", trial_id="1", subject_info=short)
    with pytest.raises(InputError, match=too_short):
        markers_to_trial(
            md,
            parse_marker_map(synth.MAP),
            subject="S1",
            posture="P",
            trial_id="1",
            subject_info=short,
            options=PreprocessOptions(ik="fingertip"),
        )


def test_missing_marker_and_long_gap(reach, synth):
    mk = dict(reach.markers)
    del mk["EL"]
    with pytest.raises(InputError, match=r"marker 'EL' \(elbow\) not found \(markers: SH, WR, FT\)"):
        _rec(reach, synth, markers=mk)
    # a misspelt marker is named with the file's closest ones, before the list (which shows only 12 of many)
    mk = {
        **{("ELB" if k == "EL" else k): v for k, v in reach.markers.items()},
        **{f"X{i:02d}": reach.markers["SH"] for i in range(12)},
    }
    with pytest.raises(InputError, match=r"marker 'EL' \(elbow\) not found; did you mean 'ELB'\? \(markers: SH, ELB,"):
        _rec(reach, synth, markers=mk)
    # two names that differ only in case: neither is taken, and the message says why
    mk = {**{k: v for k, v in reach.markers.items() if k != "EL"}, "el": reach.markers["EL"], "El": reach.markers["EL"]}
    with pytest.raises(InputError, match=r"marker 'EL' \(elbow\) not found: el, El differ from it only in case"):
        _rec(reach, synth, markers=mk)
    mk = {k: v.copy() for k, v in reach.markers.items()}
    mk["FT"][30:50] = np.nan
    with pytest.raises(InputError, match=r"marker FT is missing for 20 frames \(31-50\)"):
        _rec(reach, synth, markers=mk)
    mk["FT"][30:50] = reach.markers["FT"][30:50]
    mk["FT"][30:36] = np.nan  # short: filled
    rec = _rec(reach, synth, markers=mk)
    assert np.isfinite(rec.q).all()


def _gapped(reach, frames, marker="FT"):
    mk = {k: np.array(v) for k, v in reach.markers.items()}
    mk[marker][frames] = np.nan
    return mk


@pytest.mark.parametrize(
    ("frames", "where"),
    [(slice(5, 30), "before"), (slice(150, 175), "after"), (slice(0, 25), "before")],  # the reach: 0.5-1.3 s
)
def test_a_long_gap_in_the_rest_is_cut_off_with_a_warning(reach, synth, caplog, frames, where):
    """A marker occluded for longer than gap filling allows while the hand rests: the trial comes from the seen
    part of the record, the same reach as with the marker seen throughout, and a warning names the gap."""
    noise = np.random.default_rng(3).normal(0.0, 0.0005, (len(reach.t), 3))  # 0.5 mm
    noisy = SimpleNamespace(markers={k: np.asarray(v) + noise for k, v in reach.markers.items()})
    seen = _trial(synth, noisy.markers)
    with caplog.at_level("WARNING", logger="reachirl"):
        cut = _trial(synth, _gapped(noisy, frames))
    a, b = frames.indices(len(reach.t))[:2]
    assert f"marker FT is missing for 25 frames ({a + 1}-{b}), in the rest {where} the reach" in caplog.text
    assert cut.t.shape == seen.t.shape
    np.testing.assert_allclose(cut.t, seen.t)
    np.testing.assert_allclose(np.degrees(cut.q), np.degrees(seen.q), atol=0.05)  # the filter's edge moved


@pytest.mark.parametrize(
    ("frames", "why"),
    [
        (slice(25, 52), "the reach does not begin in 0.1 s of seen rest after it"),  # ends 0.02 s before the reach
        (slice(65, 85), "the reach does not begin in 0.1 s of seen rest after it"),  # inside the reach
        (slice(125, 140), "the reach does not end in 0.1 s of seen rest before it"),  # just after the reach
    ],
)
def test_a_long_gap_beside_or_inside_the_reach_is_refused(reach, synth, frames, why):
    a, b = frames.indices(len(reach.t))[:2]
    with pytest.raises(
        InputError,
        match=rf"s\.trc: marker FT is missing for {b - a} frames \({a + 1}-{b}\), longer than the 10 frames gap "
        rf"filling allows \(--max-gap\), and {why}$",
    ):
        _trial(synth, _gapped(reach, frames))


def test_a_long_gap_inside_a_noisy_reach_is_refused_without_a_noise_warning(reach, synth, caplog):
    """1 mm of marker noise (no warning on the whole reach) and the fingertip hidden over the reach's peak: the
    record is cut at the gap, and what is kept holds the reach's tail only, whose peak speed (0.29 m/s, not the
    reach's 0.51) made the noise look large (its speed's noise 1.1 times the most allowed, the whole reach's 0.6
    times). 'the recording's noise ... is large' was logged, then the gap refused. The refusal now comes alone:
    warnings about a record wait until its cut is accepted."""
    noise = np.random.default_rng(3).normal(0.0, 0.001, (len(reach.t), 3))
    noisy = {k: np.asarray(v) + noise for k, v in reach.markers.items()}
    with caplog.at_level("WARNING", logger="reachirl"):
        _trial(synth, noisy)
    assert caplog.records == []  # the noise is not large beside the whole reach
    noisy["FT"][60:102] = np.nan
    with (
        caplog.at_level("WARNING", logger="reachirl"),
        pytest.raises(
            InputError,
            match=r"s\.trc: marker FT is missing for 42 frames \(61-102\), .*, and the reach does not begin in 0\.1 s "
            r"of seen rest after it$",
        ),
    ):
        _trial(synth, noisy)
    assert caplog.records == []


def test_a_gap_that_hides_a_noisy_reach_is_named_not_taken_for_swapped_markers(reach, synth):
    """The fingertip hidden from the reach's start to its end, with 1 mm of marker noise: the rest kept beside the gap
    passed the speed test on its noise, and was refused as 'the shoulder travels 0.02 m and the fingertip 0.02 m:
    are the markers swapped?'. The gap is named."""
    noise = np.random.default_rng(3).normal(0.0, 0.001, (len(reach.t), 3))
    noisy = {k: np.asarray(v) + noise for k, v in reach.markers.items()}
    noisy["FT"][50:125] = np.nan
    with pytest.raises(
        InputError, match=r"s\.trc: marker FT is missing for 75 frames \(51-125\), .*, and no reach is seen outside the"
    ):
        _trial(synth, noisy)


def test_a_gap_that_hides_the_reach_or_leaves_only_its_return_is_refused(reach, synth):
    with pytest.raises(
        InputError, match=r"marker FT is missing for 100 frames \(41-140\), .*, and no reach is seen outside the long"
    ):
        _trial(synth, _gapped(reach, slice(40, 140)))
    # the reach, 0.5 s at the bar, and the same movement back: the fingertip hidden from the rest into the reach
    there_and_back = {k: np.concatenate([v, np.asarray(v)[::-1][1:]]) for k, v in reach.markers.items()}
    there_and_back["FT"][5:120] = np.nan
    with pytest.raises(InputError, match=r"\(6-120\), .*, and the fingertip moves 20\d mm across it: the hand is not"):
        _trial(synth, there_and_back)
    there_and_back["FT"][:5] = np.nan  # hidden from the record's start: only the return is seen
    with pytest.raises(InputError, match=r"\(1-120\), .*, and the movement seen after it shortens the arm: a return"):
        _trial(synth, there_and_back)


@pytest.mark.parametrize(("copies", "where"), [(1, "frame 71"), (3, "frames 71-73")])
def test_a_frame_padded_with_copies_is_refused(synth, synth_arm, copies, where):
    """A file whose frame rate was padded by copying frames (the time column runs on): mid-reach the arm stands
    still for a frame and then goes on, a stall too small for the glitch test (100 m/s² at 1 m/s and 100 Hz), which
    the filter smeared into the speed. No camera sees two frames alike (noise alone tells them apart): refused."""
    _, q = synth.min_jerk_q([-1.4, 1.6], [-0.6, 0.5], duration=0.4)
    markers = {k: np.insert(v, [70] * copies, v[69], axis=0) for k, v in synth.lab_markers(synth_arm, q).items()}
    with pytest.raises(
        InputError,
        match=rf"^s\.trc: {where}: every joint repeats frame 70 exactly, while the fingertip moves 1\d mm in the frame "
        r"before and 1\d mm in the frame after: duplicated frames \(a frame rate padded with copies\)\? Remove them",
    ):
        _trial(synth, markers)


def test_a_glitch_after_a_gap_in_the_rest_names_the_recording_s_frame(reach, synth):
    spiked = {k: np.array(v) for k, v in reach.markers.items()}
    spiked["FT"][55, 0] += 0.5
    with pytest.raises(InputError, match=r"frame 5[67]: the fingertip moves 500 mm") as whole:
        _trial(synth, spiked)
    spiked["FT"][5:30] = np.nan  # the record is now cut at frame 31
    with pytest.raises(InputError) as cut:
        _trial(synth, spiked)
    assert str(cut.value) == str(whole.value)


def test_nested_gaps_name_the_one_beside_the_reach(reach, synth):
    nested = _gapped(reach, slice(5, 48), "SH")  # the shoulder hidden up to 0.07 s before the reach
    nested["FT"][10:30] = np.nan
    with pytest.raises(InputError, match=r"marker SH is missing for 43 frames \(6-48\), .*, and the reach does not"):
        _trial(synth, nested)


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("up", ["+x", "-x"])
def test_a_lateral_up_axis_is_refused(reach, synth, synth_arm, side, up):
    """The synthetic lab has z up, y forward (turned by 10°) and x lateral; a left arm is the right one mirrored
    across x = 0. With x given as up the reach was made a trial (its angles the projections of an arm standing 80°
    out of the plane); it is refused, as the arm then never hangs and lies across the plane of the reach."""
    md = MarkerData(100.0, synth.lab_markers(synth_arm, reach.q, side=side), source="s.trc")
    kw = {"subject": "S1", "posture": "P2", "trial_id": "1", "side": side}
    with pytest.raises(
        InputError,
        match=rf"^s\.trc: with up = \{up} \(--up-axis\), the upper arm stands [7-9]\d° out of the vertical plane of "
        r"the reach \(\d\.\d\d s after onset\) and the upper arm never hangs within 45° of straight down \([89]\d° at "
        r"best\): is the up axis the lab's vertical\? \(check --up-axis\)$",
    ):
        markers_to_trial(md, parse_marker_map(synth.MAP), options=PreprocessOptions(up_axis=up), **kw)
    tr = markers_to_trial(md, parse_marker_map(synth.MAP), options=PreprocessOptions(up_axis="+z"), **kw)
    np.testing.assert_allclose(tr.q[0], reach.q[0], atol=0.01)


@pytest.mark.parametrize(
    ("where", "declared", "said"),
    [
        ("set", False, "marker set 'custom'; give --up-axis"),  # was: "the file's convention"
        ("file", True, "the file's own; give --up-axis"),
        ("format", False, "the format's convention; give --up-axis"),
    ],
)
def test_a_lateral_up_axis_names_where_it_came_from(reach, synth, synth_arm, where, declared, said):
    """Without --up-axis, the up axis is the file's own statement (a C3D's POINT:Y_SCREEN), else the marker set's,
    else the format's convention (usage.md); the refusal of a lateral one named 'the file's convention' whatever
    gave it, also a marker set's "up" (which no file or format states), where the fix is in the marker set."""
    ms = replace(parse_marker_map(synth.MAP), name="custom", up="+x" if where == "set" else None)
    up = "+z" if where == "set" else "+x"
    md = MarkerData(100.0, synth.lab_markers(synth_arm, reach.q), source="s.trc", up=up, up_declared=declared)
    kw = {"subject": "S1", "posture": "P2", "trial_id": "1"}
    with pytest.raises(InputError, match=rf"^s\.trc: with up = \+x \({re.escape(said)}\), the upper arm stands "):
        markers_to_trial(md, ms, **kw)


def test_lengths_leave_out_a_pair_never_seen_together():
    from reachirl.data.kinematics import estimate_lengths

    a = np.zeros((6, 3))
    b = np.array([[0.3, 0, 0]] * 3 + [[np.nan] * 3] * 3)
    c = np.array([[np.nan] * 3] * 3 + [[0.3, 0.25, 0]] * 3)
    out = estimate_lengths({"shoulder": a, "elbow": b, "fingertip": c})
    assert out["upper_arm"] == pytest.approx(0.3) and out["reach"] == pytest.approx(np.hypot(0.3, 0.25))
    assert "elbow_fingertip" not in out


# ---------------------------------------------------------------------- real data (the shipped sample)
def test_ue_adl_cast_forearm_length(synth):
    d = synth.SAMPLE / "ADL001"
    static = read_vicon_csv(d / "ADL001_static.csv")
    rec = reconstruct_markers(read_vicon_csv(d / "ADL001FR1.csv"), load_markerset("ue-adl"), static=static)
    assert rec.lengths["forearm"] == pytest.approx(0.247, abs=0.003)
    assert rec.lengths["forearm_sd"] < 0.005
    assert rec.lengths["upper_arm"] == pytest.approx(0.284, abs=0.005)
    q0, q1 = np.degrees(rec.q[rec.onset]), np.degrees(rec.q[rec.offset])
    assert -100 < q0[0] < -80 and q1[0] > q0[0] + 30  # upper arm from hanging to raised forward
    assert q0[1] > q1[1] + 40  # the elbow extends
    with pytest.raises(InputError, match=r"needs a static trial"):
        reconstruct_markers(read_vicon_csv(d / "ADL001FR1.csv"), load_markerset("ue-adl"))


@pytest.mark.parametrize(
    ("name", "side", "frames"), [("ADL001FR1", "right", (10, 45)), ("ADL001FL1", "left", (230, 300))]
)
def test_ue_adl_fingertip_occluded_at_rest(synth, caplog, name, side, frames):
    """A real recording whose fingertip marker is lost for 0.35-0.7 s while the hand rests (before the reach of
    FR1, which starts at frame 62; after the left arm's, which ends at frame 196) gives the reach it gives
    whole."""
    d = synth.SAMPLE / "ADL001"
    static, md = read_vicon_csv(d / "ADL001_static.csv"), read_vicon_csv(d / f"{name}.csv")
    tip = f"{side[0].upper()}FTP"
    occluded = {k: np.array(v) for k, v in md.markers.items()}
    occluded[tip][frames[0] : frames[1]] = np.nan
    whole = reconstruct_markers(md, load_markerset("ue-adl"), static=static, side=side)
    with caplog.at_level("WARNING", logger="reachirl"):
        cut = reconstruct_markers(
            MarkerData(md.rate, occluded, source=md.source), load_markerset("ue-adl"), static=static, side=side
        )
    assert f"marker {tip} is missing for {frames[1] - frames[0]} frames ({frames[0] + 1}-{frames[1]})" in caplog.text
    first = cut.first_frame
    assert first == (frames[1] if frames[0] < whole.onset else 0)
    assert (cut.onset + first, cut.offset + first) == (whole.onset, whole.offset)
    np.testing.assert_allclose(
        np.degrees(cut.q[cut.onset : cut.offset + 1]), np.degrees(whole.q[whole.onset : whole.offset + 1]), atol=0.01
    )
    # the same arm: its lengths come from every frame where its joints are seen, not from the frames kept
    for k in ("upper_arm", "forearm", "elbow_fingertip"):
        assert cut.lengths[k] == pytest.approx(whole.lengths[k], rel=1e-3)


def test_ue_adl_a_marker_seen_for_a_frame_in_a_long_gap_does_not_stand_for_rest(synth):
    """Occluded from the rest into the reach but for one frame, with a short (filled) gap over the onset or the
    offset: the one frame is not seen rest, and the gap is refused (it used to move onset or offset by 6-10
    frames)."""
    d = synth.SAMPLE / "ADL001"
    static, md = read_vicon_csv(d / "ADL001_static.csv"), read_vicon_csv(d / "ADL001FR1.csv")  # reach: 62-172
    for long, short in (((20, 55), (56, 64)), ((177, 230), (168, 176))):
        occluded = {k: np.array(v) for k, v in md.markers.items()}
        occluded["RFTP"][slice(*long)] = np.nan
        occluded["RFTP"][slice(*short)] = np.nan
        with pytest.raises(
            InputError,
            match=rf"\({long[0] + 1}-{long[1]}\), .*, and the reach does not (begin|end) in 0.1 s of seen rest",
        ):
            reconstruct_markers(
                MarkerData(md.rate, occluded, source=md.source), load_markerset("ue-adl"), static=static
            )


def test_options_are_validated():
    with pytest.raises(ValueError, match="plane must be"):
        PreprocessOptions(plane="diagonal")
    assert replace(PreprocessOptions(), n_samples=200).n_samples == 200


def test_marker_glitches_and_swaps_are_input_errors(reach, synth):
    """Issue 12: a one-frame marker jump, swapped markers and an absurd coordinate are refused with the frame."""
    from reachirl.errors import InputError

    spiked = {k: np.array(v) for k, v in reach.markers.items()}
    spiked["FT"][55, 0] += 0.5  # 0.5 m in one frame at 100 Hz
    with pytest.raises(InputError, match=r"s\.trc: frame 5[67]: the fingertip moves 500 mm in one frame"):
        _trial(synth, spiked)
    swapped = "shoulder=FT,elbow=WR,wrist=EL,fingertip=SH"
    n = len(reach.t)
    sway = np.c_[0.03 * np.sin(2 * np.pi * np.arange(n) / 100.0), np.zeros((n, 2))]  # the trunk sways 3 cm
    swaying = {k: np.asarray(v) + sway for k, v in reach.markers.items()}
    with pytest.raises(
        InputError,
        match=r"s\.trc: the shoulder travels .* m and the fingertip .* m: are the "
        r"markers swapped\?",
    ):
        markers_to_trial(
            MarkerData(100.0, swaying, source="s.trc"),
            parse_marker_map(swapped),
            subject="S1",
            posture="P2",
            trial_id="1",
        )
    far = {k: np.array(v) for k, v in reach.markers.items()}
    far["EL"][10, 2] = 1e308
    with pytest.raises(InputError, match=r"s\.trc: frame 11: marker 'EL' is 1e\+308 m from the lab's origin"):
        MarkerData(100.0, far, source="s.trc")


@pytest.mark.parametrize(
    ("marker", "name", "spoil", "where"),
    [
        ("FT", "fingertip", "spike", "frame {mid1}"),  # 40 mm for one frame: 4 m/s, far under the speed limit
        ("FT", "fingertip", "freeze", "frames {held}"),  # held for 15 frames mid-reach, then caught up: those
        ("EL", "elbow", "spike", "frame {mid1}"),  # the elbow is checked as well as the fingertip
        ("EL", "elbow", "block", "frames {mid1}-{mid3}"),  # three frames off and back
        ("EL", "elbow", "far", "frame {mid1}"),  # 400 mm: beyond the speed limit, named alike
    ],
)
def test_jumps_slower_than_the_speed_limit_are_refused(reach, synth, marker, name, spoil, where):
    """A spike is named by its own frames, what to blank: a one-frame spike was named by the frame after it (or
    by itself) as its two jumps' sizes fell, and a block by the frame after its jump back."""
    spoiled = {k: np.array(v) for k, v in reach.markers.items()}
    mid = len(reach.t) // 2
    if spoil in ("spike", "block", "far"):
        spoiled[marker][mid : mid + (3 if spoil == "block" else 1), 0] += 0.4 if spoil == "far" else 0.04
    else:
        spoiled[marker][mid - 15 : mid] = spoiled[marker][mid - 16]
    frame = where.format(mid1=mid + 1, mid3=mid + 3, held=f"{mid - 14}-{mid}")  # rows mid - 15 … mid - 1
    how = "moves" if spoil == "far" else "jumps"
    with pytest.raises(InputError, match=rf"s\.trc: {frame}: the {name} {how} \d+ mm in one frame \("):
        _trial(synth, spoiled)


def _moved_back(md: MarkerData, at: int, block: int, back: int) -> MarkerData:
    """``md`` with its rows ``at`` … ``at + block - 1`` put back ``back`` rows earlier (frames re-inserted out of
    order; the frame numbers and times stay in order, as an export that renumbers its rows writes them)."""
    order = list(range(md.n_frames))
    moved = order[at : at + block]
    del order[at : at + block]
    order[at - back : at - back] = moved
    return replace(md, markers={k: np.asarray(v)[order] for k, v in md.markers.items()})


@pytest.fixture(scope="module")
def virtual_reach(tmp_path_factory):
    """A virtual subject's reach as ``reachirl synth`` records it (100 Hz, TRC, 1-2 mm of marker noise)."""
    from recordings import MARKERS, synth

    folder = synth(tmp_path_factory.mktemp("virtual"), ("P2",), seed=3)
    return read_file(folder / "S01_P2_T01.trc"), parse_marker_map(MARKERS)


@pytest.mark.parametrize(
    ("recording", "at", "block", "back", "frame", "mm"),
    [
        ("ue-adl", 110, 1, 1, 111, 5),  # the real reach's frames 110 and 111 swapped, at its peak speed (0.47 m/s)
        ("virtual", 88, 5, 5, 89, 62),  # 5 frames put back 5 frames, at the peak (0.7 m/s)
        ("virtual", 98, 2, 2, 99, 22),  # 2 put back 2, decelerating
    ],
)
def test_frames_out_of_order_are_refused(synth, virtual_reach, recording, at, block, back, frame, mm):
    """A block of frames re-inserted before its place makes the fingertip jump back against its way of travel, by
    as many frames of its travel. The acceleration check let these pass (its limit, 20× the median acceleration,
    grows with the noise: 859 m/s² at the virtual recording's 1 mm, whose 62 mm jump back gives 694; the real
    swap gives 5 mm back at 0.47 m/s, 140 m/s² against 200): no hand steps back mid-reach, and noise steps back
    less than 6 SDs of a step's noise (10 mm here) or 3 mm (UE-ADL's markers flicker by up to 1.3 mm back while
    the fingertip travels)."""
    if recording == "ue-adl":
        d = synth.SAMPLE / "ADL001"
        md, mset = read_vicon_csv(d / "ADL001FR1.csv"), load_markerset("ue-adl")
        static = read_vicon_csv(d / "ADL001_static.csv")
    else:
        (md, mset), static = virtual_reach, None
    reconstruct_markers(md, mset, static=static)  # the recording in order is a reach
    with pytest.raises(
        InputError,
        match=rf"{re.escape(md.source)}: frame {frame}: the fingertip steps {mm} mm back against its way of travel in "
        r"one frame, while it travels at 0\.\d\d m/s \(the recording's noise allows \d+\.\d mm\): frames out of order "
        r"\(a block of frames put back before its place\)\? Put them in order, or blank them to be filled as a gap$",
    ):
        reconstruct_markers(_moved_back(md, at, block, back), mset, static=static)


@pytest.mark.parametrize(
    ("corrupt", "refusal"),
    [
        # the fingertip 10 mm off for 3 frames in the rest before the reach: 100 m/s², within the 200 of any arm
        (
            "spike",
            r"frames 21-23: the fingertip leaves its path by 10 mm and comes back \(the recording's noise allows 4\.0 "
            r"mm\): a spike, two labels swapped, or frames out of order\? Fix them, or blank those frames",
        ),
        # the elbow's cluster 15 mm off for 3 frames where the reach starts (150 m/s²): unflagged, it moved q2 by 1.1°
        # and q̈2 by 29 rad/s², more than its peak over the whole reach (20)
        (
            "elbow",
            r"frames 61-63: the elbow leaves its path by 15 mm and comes back \(the recording's noise allows 10\.0 "
            r"mm\): a spike, two labels swapped, or frames out of order\? Fix them, or blank those frames",
        ),
        # the shoulder's cluster 12 mm off for 2 frames in the rest: 120 m/s² (mid-reach, 5 frames 19 mm off: 1.3°)
        ("shoulder", r"frames 31-32: the shoulder leaves its path by 12 mm and comes back \(the recording's noise"),
        # 3 frames put back 3 where the reach starts (0.03 m/s): 1.1 mm back at the fingertip, below the 3 mm and
        # the 0.05 m/s of the fingertip's own back-step check
        (
            "order",
            r"frame 64: every joint of the arm steps back against its way of travel in the same frame \(the elbow "
            r"\d\.\d mm, the wrist \d\.\d mm, the fingertip 1\.1 mm; the recording's noise allows 0\.5, 0\.5, "
            r"0\.5 mm\): frames out of order \(a block of frames put back before its place\)\?",
        ),
    ],
)
def test_spikes_and_frames_out_of_order_at_slow_speed_are_refused(synth, corrupt, refusal):
    """UE-ADL's ADL001FR1 (its reach from frame 62 on, 0.005-0.04 m/s in its first 5 frames), corrupted where the
    hand is still or slow. Both passed, and the fingertip's speed, which sets onset and offset, moved them: the
    spike's trial was 2 frames shorter (the angles 2.5° apart at the same sample), the block's began 4 frames later
    (5°). A spike leaves the fingertip's running
    median (a real one stays within 2.4 mm of it, over UE-ADL's 80 reaches); a block of frames put back makes every
    joint step back at once (a real marker's flicker is its own: at most 0.09 mm at once over the 80 reaches)."""
    d = synth.SAMPLE / "ADL001"
    md, mset = read_vicon_csv(d / "ADL001FR1.csv"), load_markerset("ue-adl")
    static = read_vicon_csv(d / "ADL001_static.csv")
    clean = reconstruct_markers(md, mset, static=static)
    assert clean.onset == 61 and clean.speed[61:66].max() < 0.05  # the frames corrupted are the slow start's
    if corrupt == "spike":
        tip = np.array(md["RFTP"])
        tip[20:23, 2] += 0.010
        bad = replace(md, markers={**md.markers, "RFTP": tip})
    elif corrupt in ("elbow", "shoulder"):  # the cluster that carries the joint centre, off for a few frames
        cluster, rows, mm = {"elbow": ("RUAR", slice(60, 63), 15), "shoulder": ("RSHO", slice(30, 32), 12)}[corrupt]
        markers = {k: np.array(v) for k, v in md.markers.items()}
        for k in (f"{cluster}{i}" for i in range(1, 5)):
            markers[k][rows, 2] += mm / 1000
        bad = replace(md, markers=markers)
    else:
        bad = _moved_back(md, 63, 3, 3)
    with pytest.raises(InputError, match=rf"^{re.escape(md.source)}: {refusal}"):
        reconstruct_markers(bad, mset, static=static)


@pytest.mark.parametrize(
    ("recording", "up", "refusal"),
    [
        ("virtual", "file +x", r"the start posture q0 = \(17\d\.\d°, -9\d\.\d°\) lies outside the joint limits"),
        ("virtual", "+x", r"with up = \+x \(--up-axis\), the upper arm never hangs within 45° of straight down"),
        ("virtual", "+z", r"with up = \+z \(--up-axis\), the upper arm stands 8\d° out of the vertical plane"),
        ("ue-adl", "+y", r"with up = \+y \(--up-axis\), the upper arm never hangs within 45° of straight down"),
        ("ue-adl", "+x", r"with up = \+x \(--up-axis\), the upper arm stands 8\d° out of the vertical plane"),
    ],
)
def test_a_refused_recording_is_not_first_warned_about(synth, virtual_reach, caplog, recording, up, refusal):
    """A recording's warnings (the virtual reach's noise is large beside a low --threshold; UE-ADL's fingertip is
    hidden for 0.35 s in the rest before the reach, which is cut off) were logged as the record was cut, and a
    refusal after the cut (the up axis; the joint limits, checked by the pipeline) came after them: 'the noise is
    large', then the refusal. They now wait until the trial is accepted, and a refusal comes alone. ``file +x``: the
    file itself states +x as up (no --up-axis), refused by the pipeline's joint limits."""
    from pathlib import Path

    import reachirl.data.pipeline as pipeline
    from reachirl.data.readers import ManifestEntry

    if recording == "ue-adl":
        md, mset = read_vicon_csv(synth.SAMPLE / "ADL001" / "ADL001FR1.csv"), None  # the reach: frames 62-172
        hidden = {k: np.array(v) for k, v in md.markers.items()}
        hidden["RFTP"][10:45] = np.nan
        md, options = replace(md, markers=hidden), PreprocessOptions()
        warning = "marker RFTP is missing for 35 frames (11-45), in the rest before the reach"
    else:
        (md, mset), options = virtual_reach, PreprocessOptions(onset_threshold=0.01)
        warning = "the recording's noise (1.1 mm RMS, markers or angles seen at the fingertip) is large"
    entry = ManifestEntry(file=Path(md.source), subject="", posture="")
    real_read = pipeline.read_file

    def read_file(path, fmt="auto", side="right"):  # the recording as above, its static trial from the file
        return md if Path(path) == entry.file else real_read(path, fmt, side=side)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pipeline, "read_file", read_file)
        with caplog.at_level("WARNING", logger="reachirl"):
            pipeline.preprocess_entries([entry], markers=mset, options=options)
        assert warning in caplog.text  # the trial accepted is warned about
        caplog.clear()
        with (
            caplog.at_level("WARNING", logger="reachirl"),
            pytest.raises(InputError, match=rf"^{re.escape(md.source)}: {refusal}"),
        ):
            if up.startswith("file "):
                md = replace(md, up=up.split()[1], up_declared=True)
                pipeline.preprocess_entries([entry], markers=mset, options=options)
            else:
                pipeline.preprocess_entries([entry], markers=mset, options=replace(options, up_axis=up))
    assert caplog.messages == []


def test_the_acceleration_check_keeps_noisy_and_fast_recordings(reach, synth):
    """2 mm of marker noise at 100 Hz, and the same reach sampled at 1000 Hz (second differences over 10 ms):
    neither is a glitch, and both give the clean recording's reach."""
    clean = _trial(synth, reach.markers)
    rng = np.random.default_rng(0)
    noisy = {k: np.asarray(v) + rng.normal(0, 0.002, np.shape(v)) for k, v in reach.markers.items()}
    t_fast = np.arange(0, reach.t[-1], 1e-3)
    fast = {
        k: np.column_stack([np.interp(t_fast, reach.t, np.asarray(v)[:, j]) for j in range(3)])
        for k, v in reach.markers.items()
    }
    for rate, markers, tol_deg in ((100.0, noisy, 4.0), (1000.0, fast, 0.5)):  # noise moves the cut
        trial = _trial(synth, markers, rate)
        assert trial.duration == pytest.approx(clean.duration, rel=0.1)
        assert np.degrees(np.abs(trial.q_at(50) - clean.q_at(50))).max() < tol_deg


def test_a_second_reach_in_the_recording_is_reported_and_a_return_is_not(reach, synth, caplog):
    import logging

    _, back = synth.min_jerk_q(reach.q[-1], reach.q[0], duration=0.6, rest=0.5)
    _, again = synth.min_jerk_q(reach.q[0], reach.q[-1], duration=0.5, rest=0.5)  # faster than the first (0.8 s)
    for moves, warned in (([reach.q, back[1:]], False), ([reach.q, back[1:], again[1:]], True)):
        caplog.clear()
        q = np.concatenate(moves)
        with caplog.at_level(logging.WARNING):
            trial = _trial(synth, synth.lab_markers(reach.arm, q), source="r.trc")
        # the faster forward reach: the first alone (0.8 s), the second of the two (0.5 s)
        assert trial.duration == pytest.approx(0.5 if warned else 0.8, abs=0.15)
        assert any("r.trc: the recording holds another reach" in m for m in caplog.messages) == warned
