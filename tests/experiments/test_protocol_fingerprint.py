"""A unit's checkpoint is reused only with the code it was computed by: every module a unit imports, directly or
not, is in its code fingerprint; the other backends', the baselines' (for MO-IRL) and the data loaders' are not."""

import shutil
from pathlib import Path

import pytest

import reachirl
from reachirl.experiments import protocol


@pytest.fixture
def package_copy(tmp_path, monkeypatch):
    """A copy of reachirl's sources that the fingerprint reads instead of the installed ones."""
    root = tmp_path / "reachirl"
    shutil.copytree(Path(reachirl.__file__).parent, root, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(protocol, "_PACKAGE_ROOT", root)
    return root


def _fingerprints() -> dict:
    combos = [("moirl", "casadi"), ("moirl", "crocoddyl"), ("kkt", "casadi")]
    return {c: protocol.code_fingerprint.__wrapped__(*c) for c in combos}


def _edit(root: Path, name: str) -> None:
    with open(root / name, "a", encoding="utf-8") as fh:
        fh.write("\n# edited\n")


@pytest.mark.parametrize(
    "name",
    [
        "doc/newton.py",  # the warm solves' exact Newton: imported by the CasADi backend only
        "irl/uncertainty.py",  # the uncertainty a unit computes
        "doc/sensitivity.py",
        "doc/symbolic.py",
        "irl/options.py",
        "data/checks.py",
    ],
)
def test_an_edit_to_a_module_a_unit_imports_changes_every_fingerprint(package_copy, name):
    before = _fingerprints()
    _edit(package_copy, name)
    after = _fingerprints()
    assert all(after[c] != before[c] for c in before)


@pytest.mark.parametrize(
    ("name", "changed"),
    [
        ("doc/crocoddyl/solver.py", {("moirl", "crocoddyl")}),
        ("irl/baselines/kkt.py", {("kkt", "casadi")}),
        ("experiments/datasets.py", set()),
        ("experiments/figures.py", set()),
        ("cli/reproduce.py", set()),
    ],
)
def test_an_edit_elsewhere_changes_only_the_units_that_use_it(package_copy, name, changed):
    before = _fingerprints()
    _edit(package_copy, name)
    after = _fingerprints()
    assert {c for c in before if after[c] != before[c]} == changed


def test_a_relative_import_inside_a_function_is_followed(package_copy):
    (package_copy / "irl" / "extra_helper.py").write_text("X = 1\n")
    with open(package_copy / "irl" / "moirl.py", "a", encoding="utf-8") as fh:
        fh.write("\n\ndef _uses_it():\n    from .extra_helper import X  # noqa\n\n    return X\n")
    before = _fingerprints()
    _edit(package_copy, "irl/extra_helper.py")
    assert all(v != before[c] for c, v in _fingerprints().items())


def test_a_parenthesised_import_with_comments_is_followed(package_copy):
    for name in ("extra_one", "extra_two"):
        (package_copy / "irl" / f"{name}.py").write_text("X = 1\n")
    with open(package_copy / "irl" / "moirl.py", "a", encoding="utf-8") as fh:
        fh.write("\nfrom . import (  # two helpers\n    extra_one,  # the first\n    extra_two as second,\n)\n")
    for name in ("extra_one", "extra_two"):
        before = _fingerprints()
        _edit(package_copy, f"irl/{name}.py")
        assert all(v != before[c] for c, v in _fingerprints().items())
