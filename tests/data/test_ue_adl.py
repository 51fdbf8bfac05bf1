"""The UE-ADL check on the shipped one-subject sample: our angles against the authors' own."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from reachirl.data.preprocess import PreprocessOptions
from reachirl.data.readers import read_subject_info
from reachirl.data.ue_adl import (
    SAMPLE_DIR,
    agreement,
    agreement_markdown,
    convert_subjects,
    find_static,
    parse_trial_name,
    reach_files,
    read_authors_angles,
)
from reachirl.errors import InputError


def test_names_and_statics():
    assert parse_trial_name("x/ADL001FR3.csv") == ("ADL001", "right", "FR3")
    assert parse_trial_name("ADL013FL5.csv") == ("ADL013", "left", "FL5")
    assert parse_trial_name("ADL001FR3angles.csv") is None and parse_trial_name("ADL001_static.csv") is None
    files = reach_files(SAMPLE_DIR)
    assert [f.name for f in files] == ["ADL001FL1.csv", "ADL001FL2.csv", "ADL001FR1.csv", "ADL001FR2.csv"]
    assert find_static(files[0], "ADL001") == SAMPLE_DIR / "ADL001" / "ADL001_static.csv"
    assert (SAMPLE_DIR / "LICENSE").is_file() and "MIT" in (SAMPLE_DIR / "LICENSE").read_text()
    assert "Mia Huang" in (SAMPLE_DIR / "README.md").read_text()


def test_convert_subjects(tmp_path):
    out = convert_subjects(SAMPLE_DIR / "subjects.csv", tmp_path / "info.csv", with_lengths=True)
    s = read_subject_info(out)["ADL001"]
    assert (s.sex, s.height_m, s.mass_kg, s.upper_arm_m, s.forearm_m) == ("F", 1.702, 96.0, 0.325, 0.255)


def test_authors_angles_file():
    a = read_authors_angles(SAMPLE_DIR / "ADL001" / "ADL001FR1angles.csv")
    assert a["elbow_flexion"].shape == (115,)
    assert a["elbow_flexion"][0] > 70 and abs(a["elbow_flexion"][-1]) < 5  # from flexed to straight


def test_agreement_on_sample():
    rows, trials = agreement(SAMPLE_DIR)
    assert len(trials) == 4 and [(r.subject, r.side) for r in rows][-1] == ("ALL", "both")
    for r in rows:
        assert r.elbow_r >= 0.95 and r.elbow_r_min >= 0.95
        assert r.shoulder_r >= 0.95
        # q1 is from the horizontal, their flexion from a (thorax-based) vertical: a large negative offset
        assert -70 < r.shoulder_offset_deg < -30
    for t in trials:
        assert t["forearm_mm"] == pytest.approx(247, abs=4) and t["forearm_sd_mm"] < 5
        assert abs(t["frames_ours"] - t["frames_theirs"]) <= 20  # the same 3 % segmentation, give or take
    assert "| ALL | both | 4 |" in agreement_markdown(rows)
    # the anatomical elbow (elbow→wrist) tracks theirs just as well
    rows_w, _ = agreement(SAMPLE_DIR, PreprocessOptions(distal="wrist"))
    assert rows_w[-1].elbow_r >= 0.95


def test_agreement_refuses_an_empty_folder(tmp_path):
    with pytest.raises(InputError, match="no reach with its angles and static files found"):
        agreement(tmp_path)


def test_example_runs(capsys):
    path = Path(__file__).resolve().parents[2] / "examples" / "ue_adl_agreement.py"
    spec = importlib.util.spec_from_file_location("ue_adl_agreement", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main([]) == 0
    assert "| ADL001 | right | 2 |" in capsys.readouterr().out
