"""Onset and offset on a noisy fingertip: the harder low-pass of the segmentation speed."""

import re

import numpy as np
import pytest

from reachirl.cli import main
from reachirl.data.preprocess import PreprocessOptions
from reachirl.data.segmentation import detect_onset_offset, segmentation_cutoff, segmentation_speed
from reachirl.data.signal import lowpass, noise_gains

RATE = 100.0


def _reach(noise_m: float, seed: int):
    """0.5 s rest, a 0.6 s minimum-jerk reach of 0.32 m (peak speed about 1 m/s), 0.6 s rest, at 100 Hz."""
    t = np.arange(0.0, 1.7, 1.0 / RATE)
    s = np.clip((t - 0.5) / 0.6, 0.0, 1.0)
    mj = 10 * s**3 - 15 * s**4 + 6 * s**5
    p = np.column_stack([0.3 * mj, np.full_like(t, 0.05), 0.1 * mj])
    return t, p + noise_m * np.random.default_rng(seed).standard_normal(p.shape)


def _detect(t, p, options):
    """As the marker pipeline does: the angles' 10 Hz speed, then the segmentation speed."""
    speed = np.linalg.norm(np.gradient(lowpass(p, RATE, options.cutoff_hz, options.filter_order), t, axis=0), axis=1)
    return detect_onset_offset(segmentation_speed(t, p, speed, options), options.onset_threshold)


def _deviation(options, seeds=range(10)):
    ref = _detect(*_reach(0.0, 0), options)
    return ref, [int(np.abs(np.subtract(_detect(*_reach(0.002, s), options), ref)).max()) for s in seeds]


def test_onset_and_offset_stay_put_under_two_millimetres_of_marker_noise():
    ref, dev = _deviation(PreprocessOptions())
    assert max(dev) <= 2, dev  # frames, over 10 noise draws
    # the 10 Hz speed alone carries about 5 % of the peak in noise, the threshold itself: the cut wanders
    ref_berret, dev_berret = _deviation(PreprocessOptions(segment_cutoff_hz=None))
    assert max(dev_berret) >= 5, dev_berret
    assert ref == ref_berret  # clean: "auto" keeps the 10 Hz speed
    # a fixed 5 Hz speed crosses 5 % of the peak at the same frames on clean data
    assert _deviation(PreprocessOptions(segment_cutoff_hz=5.0), seeds=())[0] == ref


def test_auto_lowers_the_cutoff_only_as_far_as_the_noise_needs():
    opts = PreprocessOptions()
    cut = {}
    for noise_mm in (0.0, 0.05, 1.0, 1.5, 2.0, 6.0):
        t, p = _reach(noise_mm / 1000, 3)
        cut[noise_mm] = segmentation_cutoff(t, p, 1.0, opts)
    assert cut[0.0] is None and cut[0.05] is None  # clean (UE-ADL's markers: 0.06 mm): Berret's speed
    assert 4.0 <= cut[1.0] <= 6.0 and 3.5 <= cut[1.5] <= 5.0 and 3.0 <= cut[2.0] <= 4.5
    assert cut[1.0] >= cut[1.5] >= cut[2.0] >= cut[6.0] == 3.0  # never below the floor


@pytest.mark.parametrize(
    ("noise_mm", "threshold", "said"),
    [
        (
            6.0,
            0.05,
            r"noise \(6 mm RMS.*\) is large beside the onset threshold's speed \(50 mm/s: --threshold "
            r"0\.05 of the peak 1\.00 m/s\)",
        ),
        # clean markers and a tiny --threshold: the threshold, not the reach, is what the noise is large beside
        (
            0.1,
            0.001,
            r"noise \(0\.1 mm RMS.*\) is large beside the onset threshold's speed \(1 mm/s: --threshold "
            r"0\.001 of the peak 1\.00 m/s\)",
        ),
    ],
)
def test_the_noise_warning_names_the_threshold_speed_it_is_large_beside(caplog, noise_mm, threshold, said):
    """It said 'large for a reach this slow' of 0.1 mm of noise on a 1 m/s reach (--threshold 0.001)."""
    t, p = _reach(noise_mm / 1000, 3)
    assert segmentation_cutoff(t, p, 1.0, PreprocessOptions(onset_threshold=threshold), "r.trc") == 3.0
    assert re.search(r"r\.trc: the recording's " + said + r"; onset and offset are found on a 3 Hz speed", caplog.text)


def test_the_noise_model_predicts_the_speed_noise():
    """White noise on a still marker: the RMS left above 10 Hz gives σ back, and the speed's RMS is predicted."""
    rng = np.random.default_rng(11)
    sigma, n = 0.0015, 20000
    x = sigma * rng.standard_normal((n, 3))
    res_gain, vel_gain = noise_gains(RATE, 10.0, 5)
    residual = x - lowpass(x, RATE, 10.0, 5)
    assert np.sqrt(np.mean(residual**2) / res_gain) == pytest.approx(sigma, rel=0.02)
    v = np.gradient(lowpass(x, RATE, 10.0, 5), 1.0 / RATE, axis=0)
    assert np.sqrt(np.mean(np.sum(v**2, axis=1))) == pytest.approx(np.sqrt(3 * sigma**2 * vel_gain), rel=0.03)


def test_the_segmentation_speed_falls_back_to_the_given_speed():
    t, p = _reach(0.0, 0)
    speed = np.ones(t.shape[0])
    assert segmentation_speed(t, p, speed, PreprocessOptions(segment_cutoff_hz=None)) is speed
    # not below the angles' cutoff: nothing to gain
    assert segmentation_speed(t, p, speed, PreprocessOptions(cutoff_hz=4.0, segment_cutoff_hz=5.0)) is speed
    # too short for the filter's padding
    short = speed[:12]
    assert segmentation_speed(t[:12], p[:12], short, PreprocessOptions(segment_cutoff_hz=5.0)) is short
    # otherwise the speed of the 5 Hz fingertip, in m/s: about 1.9 × 0.32 m / 0.6 s at its peak
    s5 = segmentation_speed(t, p, speed, PreprocessOptions(segment_cutoff_hz=5.0))
    assert s5.max() == pytest.approx(1.875 * np.hypot(0.3, 0.1) / 0.6, rel=0.03)


def test_unfiltered_angles_still_find_onset_and_offset_on_a_filtered_speed():
    """--cutoff 0 (angles unfiltered) turned the segmentation speed's filter off too, "auto" and an explicit
    --segment-cutoff alike: a reach with 2 mm of marker noise was cut on noise (1.27 s for 0.66 s, measured on
    a virtual trial). Now a given cutoff applies as given, and "auto" starts from the default cutoff."""
    raw = PreprocessOptions(cutoff_hz=None)
    t, p = _reach(0.002, 3)
    assert segmentation_cutoff(t, p, 1.0, PreprocessOptions(cutoff_hz=None, segment_cutoff_hz=3.0)) == 3.0
    assert segmentation_cutoff(t, p, 1.0, raw) == segmentation_cutoff(t, p, 1.0, PreprocessOptions())
    clean_t, clean_p = _reach(0.0, 0)
    assert segmentation_cutoff(clean_t, clean_p, 1.0, raw) == PreprocessOptions().cutoff_hz  # never unfiltered
    assert segmentation_cutoff(t, p, 1.0, PreprocessOptions(cutoff_hz=None, segment_cutoff_hz=None)) is None
    assert (
        segmentation_cutoff(t, p, 1.0, PreprocessOptions(cutoff_hz=None, segment_cutoff_hz=60.0)) is None
    )  # > Nyquist
    # the reach found where the default finds it, not on the raw speed's noise
    raw_speed = np.linalg.norm(np.gradient(p, t, axis=0), axis=1)
    on, off = detect_onset_offset(segmentation_speed(t, p, raw_speed, raw))
    ref = _deviation(PreprocessOptions(), seeds=())[0]
    assert abs(on - ref[0]) <= 2 and abs(off - ref[1]) <= 2, (on, off, ref)
    bad_on, bad_off = detect_onset_offset(raw_speed)
    assert bad_off - bad_on > (ref[1] - ref[0]) + 20  # what it was: the noise's speed crosses 5 % far outside


@pytest.mark.parametrize("bad", [0.0, -1.0, "fast", float("nan")])
def test_a_bad_segmentation_cutoff_is_refused(bad):
    with pytest.raises(ValueError, match="segment_cutoff_hz must be 'auto', a number > 0 or None"):
        PreprocessOptions(segment_cutoff_hz=bad)


def test_the_cli_takes_the_segmentation_cutoff(tmp_path, capsys):
    import json

    from reachirl.data.trial import load_trials
    from reachirl.virtual import SynthConfig, generate

    data = tmp_path / "syn"
    generate(data, SynthConfig(n_subjects=1, n_trials=1, postures=("P2",), workers=1))
    horizon = json.loads((data / "truth.json").read_text())["subjects"]["S01"]["trials"]["P2"][0]["horizon_s"]
    duration = {}
    for hz in ("auto", "0"):  # 0: onset and offset on the --cutoff speed, as Berret
        out = tmp_path / f"t{hz}.npz"
        assert main(["preprocess", str(data), "--segment-cutoff", hz, "--out", str(out)]) == 0
        duration[hz] = load_trials(out)[0].duration
    # the DOC's reach, rest to rest, cut at 5 % of its peak speed: about 90 % of its horizon
    assert 0.85 < duration["auto"] / horizon < 0.95, duration["auto"] / horizon
    assert duration["0"] != duration["auto"]  # this recording's noise moves Berret's cut
    capsys.readouterr()
    for bad in ("-1", "fast", "1e9"):
        with pytest.raises(SystemExit) as e:
            main(["preprocess", str(data), "--segment-cutoff", bad, "--out", str(tmp_path / "bad.npz")])
        assert e.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--segment-cutoff: expected auto or a number of Hz in [0, 1000]" in err[0], err
    assert not (tmp_path / "bad.npz").exists()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cutoff_hz": float("nan")}, r"^cutoff_hz must be a number > 0 \(Hz\) or None, got nan$"),
        ({"filter_order": 0}, r"^filter_order must be an integer >= 1 and <= 8, got 0$"),
        ({"filter_order": 2.5}, r"^filter_order must be an integer >= 1 and <= 8, got 2\.5$"),
        ({"min_peak_speed": float("nan")}, r"^min_peak_speed must be a number > 0 \(m/s\), got nan$"),
        ({"max_gap_frames": 2.5}, r"^max_gap_frames must be an integer >= 0, got 2\.5$"),
        ({"n_samples": 100.5}, r"^n_samples must be an integer >= 4, got 100\.5$"),
        ({"segment_range_m": (float("nan"), 1.0)}, r"^segment_range_m must be two numbers 0 < low < high \(m\)"),
        ({"pca_max_tilt_deg": float("nan")}, r"^pca_max_tilt_deg must be a number in \(0, 90\] \(degrees\), got nan$"),
        ({"onset_threshold": "0.05"}, r"^onset_threshold must be a number in \(0, 1\), got '0\.05'$"),
    ],
)
def test_preprocess_options_name_a_bad_number(kwargs, match):
    # these failed deep in numpy and scipy ("attempt to get argmin of an empty sequence" for a NaN cutoff, "float
    # division by zero" for order 0) or were taken as given (a NaN minimum speed, a NaN plane tilt)
    with pytest.raises(ValueError, match=match):
        PreprocessOptions(**kwargs)
