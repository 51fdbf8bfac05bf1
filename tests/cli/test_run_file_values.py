"""A run file's bad values: exit 2 and one line naming the run file (not an internal error), and the option
checks that once let a wrong value through."""

import pytest

from reachirl.cli import main
from reachirl.irl.options import resolve_options


def _run_file(tmp_path, text: str):
    path = tmp_path / "run.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("table", "match"),
    [
        ("frozen_windows = [0, 1]", "frozen_windows [0, 1] freezes all 2 window(s): no weight is left to learn"),
        ("frozen_windows = [7]", "frozen_windows [7] must be windows 0 to 1"),
        ("warm_newton = 1", "warm_newton must be True or False, got 1"),
        ("armijo_c1 = 2.0", "need 0 < armijo_c1 < curvature_c2 < 1"),
        # read as [1, 0] (freezing every window) before booleans among numbers were refused
        (
            "frozen_windows = [true, 0]",
            "frozen_windows must be a list of window indices (integers), got a boolean (true) among the numbers, at "
            "[0]",
        ),
        ("max_tries = true", "max_tries must be an integer, not a boolean (got True)"),
        ("beta = true", "beta must be a number, not a boolean (got True)"),  # it read "beta must be >= 0, got True"
    ],
)
def test_fit_refuses_a_bad_experimental_value_naming_the_run_file(tiny_trials, tmp_path, capsys, table, match):
    cfg = _run_file(tmp_path, f"[experimental]\n{table}\n")
    out = tmp_path / "m.json"
    code = main(["fit", str(tiny_trials), "--sections", "2", "--nodes", "20", "--config", str(cfg), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and not out.exists()
    assert len(err.splitlines()) == 1 and err.startswith(f"reachirl fit: error: {cfg}: [experimental]:")
    assert match in err, err


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('cv = "foo"', "cv must be 'rest' or 'other-side', got 'foo'"),
        ('rollout = "sideways"', "rollout must be one of"),
        ("methods = []", "methods: "),
        ("[experimental]\nfrozen_windows = [0]", "freezes all 1 window"),
        (
            "[experimental]\nfrozen_windows = [false]",
            "frozen_windows must be a list of window indices (integers), got booleans",
        ),
    ],
)
def test_reproduce_names_the_run_file_a_bad_value_came_from(tmp_path, capsys, text, match):
    cfg = _run_file(tmp_path, text + "\n")
    args = ["reproduce", "--quick", "--sections", "1", "--config", str(cfg), "--out", str(tmp_path / "run")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{cfg}: " in err and match in err, err
    assert not (tmp_path / "run" / "results.json").exists()


def test_an_empty_sections_list_is_refused_not_taken_for_the_default(tmp_path, capsys):
    """methods = [] and postures = [] were refused; sections = [] ran the default 1, 6 and 8 in silence."""
    cfg = _run_file(tmp_path, "sections = []\n")
    assert main(["reproduce", "--quick", "--config", str(cfg), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(f"{cfg}: sections: expected a list of section counts, each 1 or more; got []"), err
    assert not (tmp_path / "run").exists()


def test_a_flag_that_overrides_the_run_file_is_not_blamed_on_it(tmp_path, capsys):
    cfg = _run_file(tmp_path, 'cv = "rest"\n')
    args = ["reproduce", "--quick", "--config", str(cfg), "--set", "cv=foo", "--out", str(tmp_path / "run")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert "cv must be 'rest' or 'other-side'" in err and str(cfg) not in err


def test_booleans_are_booleans():
    with pytest.raises(ValueError, match="observe must be True or False, got 0"):
        resolve_options(experimental={"observe": 0})
