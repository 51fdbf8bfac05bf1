"""What a command imports before it works: the help lists every command without importing them, a command
imports its own module only, a unit's worker leaves out scipy's statistics and signal packages, and
``reproduce``'s own process scipy's optimisation and interpolation."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from reachirl.cli import COMMANDS, SUMMARIES
from reachirl.irl.uncertainty import indistinguishable, merit_noise

_HEAVY = ("scipy.stats", "scipy.signal", "scipy.optimize", "scipy.interpolate", "casadi", "matplotlib")


def _imports_after(code: str) -> dict:
    """Run ``code`` in a fresh interpreter; the reachirl command modules and heavy packages it imported, and what
    it printed to stdout before that."""
    probe = (
        "import sys, json\n"
        f"{code}\n"
        "print(json.dumps({'commands': sorted(m for m in sys.modules if m.startswith('reachirl.cli.')), "
        f"'heavy': sorted(m for m in {_HEAVY!r} if m in sys.modules)}}))"
    )
    proc = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _main(argv: list[str]) -> str:
    return (
        "from reachirl.cli import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit as e:\n"
        "    assert e.code == 0, e.code"
    )


def test_the_help_lists_every_command_with_its_summary_and_imports_none(capsys):
    from reachirl.cli import main

    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    for name in COMMANDS:
        assert f"{name} {SUMMARIES[name]}" in out
    seen = _imports_after(_main(["--help"]))
    assert seen == {"commands": [], "heavy": []}


@pytest.mark.parametrize("command", ["reproduce", "plot"])
def test_a_command_imports_its_own_module_only(command):
    seen = _imports_after(_main([command, "--help"]))
    assert [m for m in seen["commands"] if m.rsplit(".", 1)[1] in COMMANDS] == [f"reachirl.cli.{command}"]
    assert seen["heavy"] == []


def test_an_option_before_the_command_still_selects_it(cli, tmp_path):
    proc = cli("-v", "plot", tmp_path / "missing", "--out", tmp_path / "figs")
    assert proc.returncode == 2
    assert proc.stderr.startswith("reachirl plot: error:")


def test_a_units_worker_leaves_out_scipy_stats_and_signal():
    """The modules a unit runs (``run_named_unit``: MO-IRL, its uncertainty, the DOC, the evaluation): scipy's
    statistics (0.3 s to import) and signal (0.4 s) are each imported where they are used, not by every worker."""
    seen = _imports_after(
        "import reachirl.experiments.runner, reachirl.experiments.truth_solves, reachirl.irl.moirl, "
        "reachirl.irl.uncertainty, reachirl.doc.casadi, reachirl.doc.evaluation, reachirl.experiments.datasets"
    )
    assert "scipy.stats" not in seen["heavy"] and "scipy.signal" not in seen["heavy"]
    assert "casadi" in seen["heavy"]  # the probe did import the solver's side


def test_reproduce_starts_its_units_without_scipy_optimize():
    """What ``reproduce``'s own process imports before it starts the units' workers (the command, the runner, the
    report, the data sets, the virtual subjects): not scipy.optimize and scipy.interpolate (0.25 s), which only
    the workers use; a core waits for the command's imports."""
    seen = _imports_after(
        "import reachirl.cli.reproduce, reachirl.experiments.runner, reachirl.experiments.report, "
        "reachirl.experiments.datasets, reachirl.virtual"
    )
    assert "scipy.optimize" not in seen["heavy"] and "scipy.interpolate" not in seen["heavy"]
    assert "casadi" in seen["heavy"]  # the probe did import the DOC's modules


def test_reproduce_writes_its_report_without_scipy_stats():
    """The report's paired test of section counts (:func:`reachirl.experiments.analysis.signed_rank_p`) is counted
    without scipy.stats, whose import (0.35 s) and teardown at exit (0.05 s) came at the very end of every run."""
    seen = _imports_after(
        "import reachirl.experiments.report, reachirl.experiments.analysis as a\n"
        "assert a.signed_rank_p([-0.4, -0.2, 0.1, -0.3, -0.5]) == 0.125"
    )
    assert "scipy.stats" not in seen["heavy"]


@pytest.mark.parametrize("n", [2, 3, 5, 10, 40])
def test_merit_noise_is_the_one_sided_95_percent_t_half_width(n):
    e = np.random.default_rng(n).gamma(2.0, 0.1, n)
    expected = stats.t.ppf(0.95, n - 1) * e.std(ddof=1) / np.sqrt(n)
    assert merit_noise(e) == pytest.approx(expected, rel=1e-14)


def test_indistinguishable_at_the_t_tests_critical_value():
    """A mean rise beyond the noise, with the paired t statistic just below and just above the one-sided 5 %
    critical value of Student's t with D − 1 degrees of freedom."""
    fit = np.full(6, 1.0)
    d = np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0])  # sd = √1.2 (ddof 1)
    crit = stats.t.ppf(0.95, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size)
    assert crit > merit_noise(fit)  # the noise floor (no spread in the fit's errors) decides nothing here
    assert indistinguishable(fit + d + 0.999 * crit, fit)
    assert not indistinguishable(fit + d + 1.001 * crit, fit)
