"""The command line's manners: -v anywhere, a help line with its default for every option, a folder's manifest."""

import argparse
import re

import numpy as np
import pytest

from reachirl.cli import build_parser, main
from reachirl.data.trial import load_trials


def _subparsers():
    p = build_parser()
    return next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices


@pytest.mark.parametrize("where", ["before", "after"])
def test_verbose_anywhere_on_the_line(where, tmp_path, cli):
    args = ["fit", tmp_path / "missing.npz", "--sections", "1", "--out", tmp_path / "m.json"]
    proc = cli(*(["-v", *args] if where == "before" else [*args, "-v"]))
    assert proc.returncode == 2 and "unrecognized arguments" not in proc.stderr
    assert proc.stderr.strip() == f"reachirl fit: error: {tmp_path / 'missing.npz'}: file not found"


@pytest.mark.parametrize("command", ["fit", "evaluate", "simulate"])
def test_an_unknown_option_is_the_commands_own_error(command, tmp_path, capsys):
    from reachirl.cli import main

    out = ["--out", str(tmp_path / "o.json")]
    argv = {
        "fit": ["fit", "t.npz", "--sections", "2", *out],
        "evaluate": ["evaluate", "--model", "m.json", "t.npz", *out],
        "simulate": ["simulate", "--model", "m.json", "t.npz"],
    }[command]
    with pytest.raises(SystemExit) as e:
        main([*argv, "--bogus", "1"])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip() == f"reachirl {command}: error: unrecognized arguments: --bogus 1"


@pytest.mark.parametrize("name", sorted(_subparsers()))
def test_every_option_has_help_with_its_default(name):
    sp = _subparsers()[name]
    assert sp.description, f"{name} has no description"
    assert "``" not in sp.format_help()
    for a in sp._actions:
        if isinstance(a, argparse._HelpAction) or a.help == argparse.SUPPRESS:  # run-file keys: the description
            continue
        assert a.help, f"{name} {a.option_strings or a.dest} has no help"
        if a.option_strings and not a.required and not isinstance(a, argparse._StoreTrueAction):
            assert "default" in a.help.lower() or "required" in a.help.lower(), (
                f"{name} {a.option_strings}: the help does not say the default"
            )


def test_preprocess_folder_uses_its_manifest(tmp_path, capsys):
    assert (
        main(
            [
                "synth",
                "--out",
                str(tmp_path / "syn"),
                "--subjects",
                "1",
                "--trials",
                "2",
                "--postures",
                "P2",
                "--workers",
                "1",
            ]
        )
        == 0
    )
    capsys.readouterr()
    out = tmp_path / "t.npz"
    assert main(["preprocess", str(tmp_path / "syn"), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "using the folder's manifest" in err and "using the folder's subject info" in err
    # subject and posture from the manifest, not from the file name
    assert [t.id for t in load_trials(out)] == ["S01/P2/right/S01_P2_T01", "S01/P2/right/S01_P2_T02"]


_FIT = ["--sections", "8", "--out", "m.json"]
_EVAL = ["--model", "m.json", "--out", "metrics.json"]


@pytest.mark.parametrize(
    "argv, dest, expected",
    [
        (["fit", "t.npz", *_FIT, "--subject", "S01", "--subject", "S02", "S03"], "subject", ["S01", "S02", "S03"]),
        (["evaluate", "t.npz", *_EVAL, "--posture", "P1", "--posture", "P2"], "posture", ["P1", "P2"]),
        (["plot", "run", "--out", "f", "--subject", "S01", "--subject", "S02"], "subject", ["S01", "S02"]),
        (["fit", "t.npz", *_FIT], "subject", None),
    ],
)
def test_a_selection_given_twice_keeps_both(argv, dest, expected):
    # `--subject S01 --subject S02` once kept S02 only, and fitted half the trials without a word; the protocol's
    # options (`reproduce --sections`, ...) keep argparse's rule instead: the last one given wins, as over a run file
    assert getattr(build_parser().parse_args(argv), dest) == expected


def test_reproduce_help_shows_the_run_file_keys_as_flags():
    """`reproduce --help` lists every run-file key that is also a flag in one group, each with its range and default
    on one line (they were hidden, named only as keys in the description), and hides no option."""
    from reachirl.cli.reproduce import RUN_KEYS

    sp = _subparsers()["reproduce"]
    (group,) = [g for g in sp._action_groups if g.title == "run-file keys, also accepted as flags"]
    flags = {"methods": "--method", "progress": "--no-progress"}
    expected = {flags.get(k, "--" + k.replace("_", "-")) for k in RUN_KEYS} | {"--uncertainty"}
    assert {s for a in group._group_actions for s in a.option_strings} == expected
    for a in group._group_actions:
        assert a.help not in (None, argparse.SUPPRESS) and "default" in a.help and len(a.help) < 120, a.help
    assert not [a.dest for a in sp._actions if a.help == argparse.SUPPRESS]  # --set included
    text = sp.format_help()
    words = " ".join(text.split())
    for flag in expected:
        assert flag in text
    assert "--n-train N training trials per posture, 0 to 1000000 (default 10; --quick 3; 0: all)" in words
    assert "--set KEY=VALUE a run-file key" in words
    assert len(text.splitlines()) < 120  # a screenful or two, not a listing
    args = build_parser().parse_args(["reproduce", "--n-train", "0", "--no-progress", "--method", "moirl", "kkt"])
    assert (args.key_n_train, args.key_progress, args.key_methods) == (0, False, ["moirl", "kkt"])


@pytest.mark.parametrize("value", ["5", "19", "1001", "-3", "abc"])
def test_a_bad_number_of_weight_samples_is_refused_with_the_range_it_has(value, tmp_path, capsys):
    # `reproduce --uncertainty 1001` (or abc) said "expected an integer in [0, 1000]", and 5, which that range
    # holds, passed the flag to be refused later in other words: the range is 0 (none) or 20 to 1000, as `fit`'s
    # (whose 0 was refused, though MOIRL(uncertainty=0) and a run file's `uncertainty = 0` mean none)
    for command in (["reproduce", "--quick", "--out", str(tmp_path / "r")], ["fit", "t.npz", "--sections", "8"]):
        with pytest.raises(SystemExit) as e:
            main([*command, "--uncertainty", value, "--out", str(tmp_path / "m.json")])
        assert e.value.code == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "an integer in [20, 1000], got" in err, err
        assert "0 (none) or " in err
    assert build_parser().parse_args(["reproduce", "--uncertainty", "0"]).uncertainty == 0
    fit = ["fit", "t.npz", "--sections", "8", "--uncertainty", "0", "--out", "m.json"]
    assert build_parser().parse_args(fit).uncertainty == 0


@pytest.mark.parametrize(
    ("flag", "value", "choices"),
    [
        ("--cv", "foo", "'rest', 'other-side'"),
        ("--train-side", "up", "'right', 'left'"),
        ("--rollout", "x", "'per_task', 'per_demo', 'mean'"),
    ],
)
def test_a_protocol_name_outside_its_list_is_refused_naming_the_flag(flag, value, choices, tmp_path, capsys):
    # "cv must be 'rest' or 'other-side', got 'foo'" named the run-file key, not the flag the user typed
    with pytest.raises(SystemExit) as e:
        main(["reproduce", "--quick", flag, value, "--out", str(tmp_path / "r")])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err == f"reachirl reproduce: error: argument {flag}: invalid choice: '{value}' (choose from {choices})"
    assert not (tmp_path / "r").exists()


def test_a_manifest_or_an_unnamed_marker_says_which_option_takes_it(tmp_path, capsys):
    from recordings import synth

    folder = synth(tmp_path / "v", ("P2",))
    np.savez(tmp_path / "s.npz", a=np.zeros(3))
    out = ["--out", str(tmp_path / "t.npz")]
    cases = [
        # the manifest among the recordings read as an angle file: "no 'time' column"
        (
            [str(folder / "manifest.csv")],
            r"manifest\.csv: a manifest \(columns: .*\), not a recording: give it as "
            r"--manifest, or give the folder that holds it$",
        ),
        # the recordings without their folder's truth.json: the built-in names are not the file's
        (
            sorted(str(p) for p in folder.glob("*.trc"))[:1],
            r"marker 'shoulder' \(shoulder\) not found .*; name the "
            r"recording's own with --markers shoulder=A,elbow=B,wrist=C,fingertip=D, or choose another --markerset$",
        ),
        ([str(folder), "--markers", "shoulder=SHO,elbow=ELB"], r"--markers lacks the fingertip: give joint=MARKER"),
        (
            [str(folder), "--subject-info", str(tmp_path / "s.npz")],
            r"s\.npz: is a ZIP or NPZ archive \(a trials "
            r"file is one\), expected text$",
        ),
    ]
    for args, match in cases:
        assert main(["preprocess", *args, *out]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert all(line.startswith("note: ") for line in err[:-1]), err  # the folder's manifest and truth, noted
        assert re.search(match, err[-1]), err[-1]
    assert not (tmp_path / "t.npz").exists()
