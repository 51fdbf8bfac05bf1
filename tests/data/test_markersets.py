"""Marker-set JSON files (--markerset FILE): every field is checked, and a bad one is an error naming the file and
the field, never an internal error nor a list of names read as characters."""

from __future__ import annotations

import json

import pytest

from reachirl.cli import main
from reachirl.data.markersets import load_markerset
from reachirl.errors import InputError

JOINTS = {"shoulder": {"markers": ["SH"]}, "elbow": {"markers": ["EL"]}, "fingertip": {"markers": ["FT"]}}


def _set(tmp_path, **fields):
    p = tmp_path / "set.json"
    p.write_text(json.dumps({"joints": JOINTS, **fields}))
    return p


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        ({"joints": None}, r"set\.json: marker set: 'joints' must be an object"),
        ({"joints": {**JOINTS, "shoulder": {"markers": [None]}}}, r"joints\.shoulder\.markers must be a list"),
        ({"joints": {**JOINTS, "shoulder": {"markers": "SH"}}}, r"joints\.shoulder\.markers must be a list"),
        ({"joints": {**JOINTS, "shoulder": ["SH"]}}, r"joint 'shoulder' must be an object"),
        ({"joints": {**JOINTS, "shoulder": {"marker": ["SH"]}}}, r"joint 'shoulder' has unknown key\(s\) marker"),
        ({"joints": {**JOINTS, "elbow": {"markers": ["EL"], "optional": "no"}}}, r"joints\.elbow\.optional"),
        ({"side_prefix": 3}, r"set\.json: marker set: 'side_prefix' must map right and left"),
        ({"up": "+q"}, r"set\.json: marker set: 'up' must be one of"),
        ({"static": "{x}_static.csv"}, r"set\.json: marker set: 'static' may hold only \{subject\}"),
        ({"joints": {"shoulder": {"markers": ["SH"]}}}, r"set\.json: marker set .* lacks the fingertip"),
    ],
)
def test_a_bad_marker_set_field_is_named_with_its_file(tmp_path, fields, match):
    with pytest.raises(InputError, match=match):
        load_markerset(_set(tmp_path, **fields))


def test_a_good_marker_set_file_loads(tmp_path):
    ms = load_markerset(_set(tmp_path, up="+z", static="{subject}_static.trc"))
    assert ms.joints["shoulder"].markers == ("SH",) and ms.up == "+z" and ms.static == "{subject}_static.trc"
    assert load_markerset("ue-adl").joints["elbow"].cluster == ("{S}UAR1", "{S}UAR2", "{S}UAR3", "{S}UAR4")


def test_preprocess_with_a_null_marker_name_is_exit_2_naming_the_set(tmp_path, capsys, synth, reach):
    rec = tmp_path / "r.trc"
    rec.write_text(synth.trc_text(reach.markers, up="y"))
    bad = _set(tmp_path, joints={**JOINTS, "shoulder": {"markers": [None]}})
    out = tmp_path / "t.npz"
    assert main(["preprocess", str(rec), "--markerset", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "set.json: marker set: joints.shoulder.markers must be a list" in err[0], err
    assert not out.exists()
