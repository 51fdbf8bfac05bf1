"""The compiled knot of the Crocoddyl backend (``doc/crocoddyl/knot.cpp``): the Python knot's numbers, bit for
bit; the same solves; built once into the cache; the Python knot where it cannot be built."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from reachirl import ReachingTask
from reachirl.features import N_FEATURES

cb = pytest.importorskip("reachirl.doc.crocoddyl")
native = pytest.importorskip("reachirl.doc.crocoddyl.native")

FIELDS = ("cost", "xnext", "Fx", "Fu", "Lx", "Lu", "Lxx", "Lxu", "Luu", "g", "Gx", "Gu")


@pytest.fixture(scope="module")
def compiled():
    if native.knot_class() is cb.KnotModel:
        pytest.fail(f"the compiled knot did not build here: {native.status()}")
    return native.knot_class()


def _problems(arm, n=30, n_windows=2):
    return [cb.build_problem(arm, n, n_windows, cb.CsqpOptions(compiled_knots=c)) for c in (True, False)]


@pytest.mark.parametrize("exact_hessian", [False, True])
def test_compiled_knot_computes_the_python_knots_numbers_bit_for_bit(arm, rng, compiled, exact_hessian):
    task = ReachingTask(arm, np.deg2rad([10.0, 95.0]), 0.9 * arm.length, 0.7, 30)
    c, p = _problems(arm)
    w = rng.uniform(0.05, 2.0, (2, N_FEATURES))
    w[1, [3, 6]] = 0.0  # energy and torque change off in the second window: their branches are skipped
    for prob in (c, p):
        prob.update(task, w)
        for m in prob.running:
            m.exact_hessian = exact_hessian
    assert isinstance(c.running[0], compiled) and isinstance(p.running[0], cb.KnotModel)
    for k in (0, 7, 29, "terminal"):
        mc, mp = (c.terminal, p.terminal) if k == "terminal" else (c.running[k], p.running[k])
        for _ in range(3):
            x = np.r_[rng.uniform(-1, 1.5, 2), rng.uniform(-3, 3, 2), rng.uniform(-5, 5, 2)]
            u = rng.uniform(-8, 8, 2)
            dc, dp = mc.createData(), mp.createData()
            args = (x,) if k == "terminal" else (x, u)
            for m, d in ((mc, dc), (mp, dp)):
                m.calc(d, *args)
                m.calcDiff(d, *args)
            for f in FIELDS:
                a, b = np.asarray(getattr(dc, f)), np.asarray(getattr(dp, f))
                assert np.array_equal(a, b), f"knot {k}: {f} differs by {np.max(np.abs(a - b)) if a.size else 0}"


def test_a_process_that_builds_the_compiled_knots_first_solves_as_the_python_knots_do(arm):
    """Before anything else in a process, problems of C++ knots only evaluate them over Crocoddyl's OpenMP
    threads, which moved the solution by 1e-7 rad; the problem is held to one thread, so the solves match."""
    code = textwrap.dedent(
        """
        import numpy as np
        from reachirl import ArmModel, ReachingTask
        from reachirl.doc import crocoddyl as cb
        arm = ArmModel.from_anthropometrics(1.76, 70.0, "M")
        task = ReachingTask(arm, np.deg2rad([-60.0, 90.0]), 0.95 * arm.length, 0.7, 100)
        w = np.array([[1.1, 0.2, 2.5, 0.004, 0.02, 0.1, 0.05]])
        c = cb.solve(task, w)  # the compiled knots' problem is the process's first
        p = cb.solve(task, w, options=cb.CsqpOptions(compiled_knots=False))
        prob = cb.build_problem(arm, 100, 1)
        print(type(prob.running[0]).__name__, prob.problem.nthreads, c.iterations == p.iterations,
              float(np.max(np.abs(c.q - p.q))))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["CompiledKnotModel", "1", "True", "0.0"], out.stdout + out.stderr
    assert "Warning" not in out.stderr


def test_the_cached_knot_is_loaded_without_compiling(compiled, monkeypatch):
    def no_compiler(*a, **k):
        raise AssertionError("compiled again")

    monkeypatch.setattr(native.subprocess, "run", no_compiler)
    path = native._build(native._cache_dir())
    assert path.is_file() and path.parent.parent.name.startswith("crocoddyl-")


@pytest.mark.parametrize(
    ("cxx", "message"),
    [("/nonexistent/g++", "no C\\+\\+ compiler"), ("false", "g\\+\\+ failed: \\(no output\\)")],
)
def test_a_knot_that_cannot_be_built_raises_naming_why(tmp_path, monkeypatch, cxx, message):
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    monkeypatch.setenv("CXX", cxx)
    with pytest.raises(OSError, match=message):
        native._build(native._cache_dir())
    assert not any(p.suffix == ".so" for p in tmp_path.rglob("*"))  # nothing half-written left in the cache


def test_without_a_compiler_problems_are_built_with_the_python_knot(arm, tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    monkeypatch.setenv("CXX", "/nonexistent/g++")
    native._compiled_or_python.cache_clear()
    try:
        assert native.knot_class() is cb.KnotModel
        assert native.status() == "Python (compiled knot unavailable: no C++ compiler (g++, or $CXX) on the PATH)"
        assert "using the Python knot" in caplog.text
    finally:
        native._compiled_or_python.cache_clear()
