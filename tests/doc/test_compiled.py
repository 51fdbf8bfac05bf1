"""The compiled DOC solver (reachirl.doc.compiled): same answers as CasADi's virtual machine, bit for bit, and
never in the way (a broken cache file, no compiler, a bad setting)."""

import os
import subprocess
import sys
import time

import casadi as ca
import numpy as np
import pytest

from reachirl.doc import ReachingTask, compiled, solve_doc
from reachirl.doc import casadi as cas
from reachirl.errors import InputError

N = 12  # a small shape: it compiles in a few seconds


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    cas.build_nlp.cache_clear()  # the NLP objects hold their solvers and counters
    yield tmp_path
    cas.build_nlp.cache_clear()


def _problems(arm):
    w = np.array([[0.05, 0.5, 0.05, 3.0, 0.2, 0.05, 0.5], [0.1, 0.2, 0.05, 1.0, 0.5, 0.05, 0.2]])
    w = w / np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])
    tasks = [ReachingTask(arm, np.deg2rad([a, 90.0]), 0.9 * arm.length, 0.7, n_nodes=N) for a in (-5.0, 0.0, 5.0)]
    return tasks, w


def _solve_all(tasks, w):
    """A cold solve of each task, then a warm one under weights 10 % off (as MO-IRL's line search makes)."""
    out = []
    for t in tasks:
        cold = solve_doc(t, w)
        out += [cold, solve_doc(t, w * np.array([1.1, 0.9, 1.0, 1.1, 0.9, 1.0, 1.1]), warm_start=cold)]
    return out


def test_compiled_solver_is_bit_identical_and_cached(cache, monkeypatch, arm, tmp_path_factory):
    workdir = tmp_path_factory.mktemp("cwd")
    monkeypatch.chdir(workdir)  # nothing may be written here: CasADi's temporary files go to the cache
    tasks, w = _problems(arm)
    monkeypatch.setenv("REACHIRL_COMPILE", "off")
    vm = _solve_all(tasks, w)
    assert not list(cache.rglob("solver.casadi"))

    cas.build_nlp.cache_clear()
    monkeypatch.setenv("REACHIRL_COMPILE", "on")
    first = _solve_all(tasks, w)  # compiles the cold solver at the first cold solve, the warm one at the first warm
    files = list(cache.rglob("solver.casadi"))
    assert len(files) == 2 and all(list(f.parent.glob("*.so")) for f in files), "solvers and libraries cached"
    assert {"fatrop_compiled", "fatrop_warm_compiled"} <= set(cas.build_nlp(N)._solvers)

    cas.build_nlp.cache_clear()
    t0 = time.perf_counter()
    again = _solve_all(tasks, w)  # loads the cached files, does not compile again
    assert time.perf_counter() - t0 < 5.0
    assert {"fatrop_compiled", "fatrop_warm_compiled"} <= set(cas.build_nlp(N)._solvers)
    assert not list(workdir.iterdir()), "compiling and loading leave nothing in the working directory"
    assert [s.attempts for s in vm[1::2]] == [1] * len(tasks), "the warm solves converged warm (no cold retry)"
    for a, b, c in zip(vm, first, again, strict=True):
        assert a.converged and b.converged and c.converged
        assert np.array_equal(a.q, b.q) and np.array_equal(a.q, c.q)
        assert a.cost == b.cost == c.cost and a.iterations == b.iterations == c.iterations


def test_a_cached_solver_is_found_without_building_the_nlp(cache, monkeypatch, arm):
    """A process whose compiled solvers are cached finds them from the note of the code that built them, without
    the NLP's symbolic graph; the note names the solver the graph's own hash names, and one that names no cached
    solver is not trusted."""
    tasks, w = _problems(arm)
    monkeypatch.setenv("REACHIRL_COMPILE", "on")
    first = _solve_all(tasks[:1], w)  # compiles both solvers, and notes where they are
    nlp = cas.build_nlp(N)
    paths = {k: compiled.cache_path(nlp.nlp, slot.spec[2]) for k, slot in nlp.slots.items()}
    notes = sorted((cache / f"casadi-{ca.__version__}" / "paths").glob("*.txt"))
    assert sorted(n.read_text().strip() for n in notes) == sorted(p.parent.name for p in paths.values())

    cas.build_nlp.cache_clear()
    again = _solve_all(tasks[:1], w)
    nlp = cas.build_nlp(N)
    assert "_graph" not in vars(nlp), "the compiled solvers were found without building the NLP"
    assert {"fatrop_compiled", "fatrop_warm_compiled"} <= set(nlp._solvers)
    for a, b in zip(first, again, strict=True):
        assert np.array_equal(a.q, b.q) and a.cost == b.cost

    for note in notes:  # a note naming no cached solver (another version's, a removed one): the graph decides
        note.write_text("doc-000000000000000000000000\n")
    cas.build_nlp.cache_clear()
    nlp = cas.build_nlp(N)
    assert {k: slot.get() is not None for k, slot in nlp.slots.items()} == {"cold": True, "warm": True}
    assert "_graph" in vars(nlp)
    assert {k: s._path for k, s in nlp.slots.items()} == paths


@pytest.mark.parametrize("n", [2, 5, 100])
def test_the_nlp_sizes_without_its_graph_are_the_graphs(n):
    nlp = cas._Nlp(n)
    sizes = (nlp.n_z, nlp.n_g)
    assert (nlp.nlp["x"].numel(), nlp.nlp["g"].numel()) == sizes


def test_a_broken_cache_file_is_ignored(cache, monkeypatch, arm):
    tasks, w = _problems(arm)
    monkeypatch.setenv("REACHIRL_COMPILE", "off")
    ref = solve_doc(tasks[0], w)
    cas.build_nlp.cache_clear()
    nlp = cas.build_nlp(N)
    _, _, opts = nlp.cold_solver_spec()
    path = compiled.cache_path(nlp.nlp, opts)
    path.parent.mkdir(parents=True)
    path.write_bytes(b"not a CasADi file")
    assert compiled.load(path) is None
    monkeypatch.setenv("REACHIRL_COMPILE", "auto")
    sol = solve_doc(tasks[0], w)
    assert sol.converged and np.array_equal(sol.q, ref.q)
    assert "fatrop_compiled" not in nlp._solvers


def test_no_compiler_falls_back_to_the_virtual_machine(cache, monkeypatch, arm):
    tasks, w = _problems(arm)
    monkeypatch.setenv("PATH", "")  # no gcc to be found
    monkeypatch.setenv("REACHIRL_COMPILE", "on")
    nlp = cas.build_nlp(N)
    name, plugin, opts = nlp.cold_solver_spec()
    with pytest.raises(RuntimeError, match="compiling the DOC solver failed"):
        compiled.compile_solver(name, plugin, nlp.nlp, opts, compiled.cache_path(nlp.nlp, opts))
    sol = solve_doc(tasks[0], w)
    assert sol.converged and "fatrop_compiled" not in nlp._solvers
    assert not list(cache.rglob("*.lock")), "the lock is released after a failed compilation"


def test_auto_compiles_in_the_background_after_many_solves(cache, monkeypatch, arm):
    tasks, w = _problems(arm)
    monkeypatch.setenv("REACHIRL_COMPILE", "auto")
    monkeypatch.setattr(compiled, "AUTO_AFTER", 2)
    monkeypatch.setattr(compiled, "POLL_EVERY", 1)
    nlp = cas.build_nlp(N)
    solve_doc(tasks[0], w)
    assert not list(cache.rglob("*.lock")), "one solve is not a long run"
    solve_doc(tasks[1], w)  # the AUTO_AFTER-th cold solve starts the compilation
    assert list(cache.rglob("*.lock")) or list(cache.rglob("solver.casadi"))
    deadline = time.monotonic() + 120
    while not list(cache.rglob("solver.casadi")) and time.monotonic() < deadline:
        assert "fatrop_compiled" not in nlp._solvers
        solve_doc(tasks[2], w)  # solving goes on meanwhile, on the virtual machine
        time.sleep(0.2)
    while list(cache.rglob("*.lock")) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert list(cache.rglob("solver.casadi")), "the background compilation finished"
    sol = solve_doc(tasks[2], w)
    assert sol.converged and "fatrop_compiled" in nlp._solvers


def test_bad_setting_is_an_input_error(monkeypatch, cli, tiny_trials):
    monkeypatch.setenv("REACHIRL_COMPILE", "fast")
    with pytest.raises(InputError, match=r"REACHIRL_COMPILE='fast': expected one of auto, on, off"):
        compiled.mode()
    r = cli("evaluate", "--help")
    assert r.returncode == 0
    r = cli("preprocess", str(tiny_trials), "--out", str(tiny_trials.parent / "never.npz"))
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "reachirl preprocess: error: environment variable REACHIRL_COMPILE='fast': expected one of auto, on, off"
    ]
    assert not (tiny_trials.parent / "never.npz").exists()


def test_preload_readies_the_solvers_a_solve_uses(cache, arm):
    """What a unit worker loads before its first unit: the cold and warm fatrop solvers of its number of knots
    (here on CasADi's VM), and the functions of Newton's and the interior point's steps; the solves after it use
    them."""
    from reachirl.doc import newton

    with compiled.setting("off"):
        cas.preload(N)
        nlp = cas.build_nlp(N)
        assert {"fatrop", "fatrop_warm"} <= set(nlp._solvers)
        solvers = dict(nlp._solvers)
        assert {(b.__name__, n) for b, n in newton._local.spaces} >= {
            ("_step_function", N),
            ("_minimum_band", N),
            ("_barrier_function", N),
            ("_kkt_function", N),
        }
        tasks, w = _problems(arm)
        assert all(s.converged for s in _solve_all(tasks[:1], w))
        assert all(nlp._solvers[k] is solvers[k] for k in ("fatrop", "fatrop_warm"))


def test_the_kkt_functions_are_saved_once_and_loaded_after(cache, monkeypatch):
    """The sensitivity's KKT functions: the first process builds them from the NLP and saves them; the next
    loads them without building the NLP's graph, and they evaluate bit for bit as built. A saved file that does
    not load is built again; with REACHIRL_COMPILE=off nothing is saved."""
    monkeypatch.setenv("REACHIRL_COMPILE", "auto")
    rng = np.random.default_rng(0)
    built = cas.build_nlp(N).kkt_functions()
    z, p = rng.normal(size=cas.build_nlp(N).n_z), np.abs(rng.normal(size=cas.build_nlp(N).nlp["p"].numel()))
    lam = rng.normal(size=cas.build_nlp(N).n_g)

    def values(f):
        return [np.asarray(f["H"](z, p, lam)), *(np.asarray(f[k](z, p)) for k in ("grad", "A", "B"))]

    saved = sorted(p.name for p in cache.rglob("*.casadi"))
    assert saved == ["A.casadi", "B.casadi", "H.casadi", "grad.casadi"]
    cas.build_nlp.cache_clear()
    nlp = cas.build_nlp(N)
    loaded = nlp.kkt_functions()
    assert "_graph" not in vars(nlp), "loaded, not built"
    assert all(np.array_equal(a, b) for a, b in zip(values(built), values(loaded), strict=True))

    next(cache.rglob("H.casadi")).write_bytes(b"not a CasADi file")
    cas.build_nlp.cache_clear()
    nlp = cas.build_nlp(N)
    again = nlp.kkt_functions()
    assert "_graph" in vars(nlp), "built again"
    assert all(np.array_equal(a, b) for a, b in zip(values(built), values(again), strict=True))

    for f in cache.rglob("*.casadi"):
        f.unlink()
    with compiled.setting("off"):
        cas.build_nlp(N).kkt_functions()
    assert not list(cache.rglob("*.casadi"))


@pytest.mark.parametrize("kind", ["ipopt", "fatrop"])
def test_a_virtual_machine_solver_is_saved_once_and_loaded_after(cache, monkeypatch, arm, kind):
    """The solvers CasADi's virtual machine runs (IPOPT, the fallback; fatrop before its compiled form exists):
    the first process makes one from the NLP and saves it; the next loads it and it solves bit for bit as made
    (IPOPT without building the NLP's graph; fatrop's compiled slot builds it to look for its compiled form). With
    REACHIRL_COMPILE=off nothing is saved."""
    monkeypatch.setenv("REACHIRL_COMPILE", "auto")
    tasks, w = _problems(arm)
    task = tasks[0]

    def solve_once():
        nlp = cas.build_nlp(N)
        b = nlp.bounds(task)
        x0 = np.clip(cas.initial_guess(task), b["lbx"], b["ubx"])
        x, stats, _ = cas._run(nlp, kind, {**b, "x0": x0, "p": nlp.params(task, w, 1.0)})
        assert cas._converged(stats, x)
        return nlp, x

    made_nlp, made = solve_once()
    assert "_graph" in vars(made_nlp)
    assert len(list(cache.rglob(f"doc_{kind}.casadi"))) == 1
    cas.build_nlp.cache_clear()
    with monkeypatch.context() as m:
        m.setattr(cas.ca, "nlpsol", lambda *a, **k: pytest.fail("made again, not loaded"))
        loaded_nlp, loaded = solve_once()
    if kind == "ipopt":
        assert "_graph" not in vars(loaded_nlp), "the NLP's graph built"
    assert np.array_equal(made, loaded)

    for f in cache.rglob("*.casadi"):
        f.unlink()
    cas.build_nlp.cache_clear()
    with compiled.setting("off"):
        _, off = solve_once()
    assert not list(cache.rglob("*.casadi"))
    assert np.array_equal(made, off)


def test_prepare_compiles_both_solvers_once_and_solves_load_them(cache, monkeypatch, arm):
    """``make run``'s set-up (``python -m reachirl.doc.compile_job prepare N``): both solvers compiled side by side
    into the cache, said in one line each; a run after it loads them (no compilation, the VM's answers bit for
    bit), and a second set-up compiles nothing."""
    tasks, w = _problems(arm)
    with compiled.setting("off"):
        vm = _solve_all(tasks[:1], w)
    env = {**os.environ, "REACHIRL_COMPILE": "auto"}
    cmd = [sys.executable, "-m", "reachirl.doc.compile_job", "prepare", str(N)]
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == [f"the {k} DOC solver of {N} knots: compiled, cached" for k in ("cold", "warm")]
    assert len(list(cache.rglob("solver.casadi"))) == 2 and not list(cache.rglob("*.lock"))

    monkeypatch.setenv("REACHIRL_COMPILE", "auto")
    monkeypatch.setattr(compiled, "start_background", lambda *a, **k: pytest.fail("compiled again"))
    cas.build_nlp.cache_clear()
    after = _solve_all(tasks[:1], w)
    assert {"fatrop_compiled", "fatrop_warm_compiled"} <= set(cas.build_nlp(N)._solvers)
    for a, b in zip(vm, after, strict=True):
        assert np.array_equal(a.q, b.q) and a.cost == b.cost and a.iterations == b.iterations
    cas.build_nlp.cache_clear()
    assert cas.prepare(N) == {"cold": True, "warm": True}, "already cached: nothing compiled"


def test_prepare_without_a_compiler_or_when_off_leaves_the_virtual_machine(cache, monkeypatch):
    """No C compiler: each solver said not compiled, exit 0 and no lock left behind (the run solves on CasADi's
    VM); ``REACHIRL_COMPILE=off``: nothing tried; a bad setting: exit 2 and one line."""
    cmd = [sys.executable, "-m", "reachirl.doc.compile_job", "prepare", str(N)]
    env = {k: v for k, v in os.environ.items() if k != "REACHIRL_COMPILE"}
    r = subprocess.run(cmd, env={**env, "PATH": ""}, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert [line.split(": ", 1)[1] for line in r.stdout.splitlines()] == [
        "not compiled (no C compiler, an unwritable cache or REACHIRL_COMPILE=off): CasADi's VM solves"
    ] * 2
    assert not list(cache.rglob("solver.casadi")) and not list(cache.rglob("*.lock"))

    with compiled.setting("off"):
        monkeypatch.setattr(compiled, "start_background", lambda *a, **k: pytest.fail("compiled when off"))
        assert cas.prepare(N) == {"cold": False, "warm": False}

    r = subprocess.run(cmd, env={**env, "REACHIRL_COMPILE": "fast"}, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [
        "error: environment variable REACHIRL_COMPILE='fast': expected one of auto, on, off"
    ]


def test_a_small_function_is_compiled_again_under_other_flags(cache, monkeypatch):
    """The compiler's flags are part of a small function's cache key: a library built with other flags is never
    loaded for these, and each build gives the virtual machine's bits."""
    x = ca.SX.sym("x", 3)
    f = ca.Function("reachirl_test_flags", [x], [ca.sin(x) * ca.exp(x[0]) + ca.sumsqr(x)])
    arg = np.array([0.3, -1.2, 2.5])
    libraries = []
    for flags in (compiled.FUNCTION_FLAGS, ("-O2",)):
        monkeypatch.setattr(compiled, "FUNCTION_FLAGS", flags)
        with compiled.setting("on"):
            fc = compiled.compiled_function(f)
        assert fc is not None
        assert np.array_equal(np.asarray(fc(arg)), np.asarray(f(arg)))
        libraries.append(sorted(p.name for p in cache.rglob("fn-reachirl_test_flags-*.so")))
    assert len(libraries[0]) == 1 and len(libraries[1]) == 2


def test_entries_unused_for_months_are_removed_when_a_new_one_is_written(cache):
    """Each version of the NLP's code kept its solvers (about 20 MB each) for ever. Loading an entry marks it
    used; writing a new one removes those of every CasADi version no process used for KEEP_UNUSED_S, the notes
    that named them and make run's note that its solvers are compiled, and keeps the rest."""
    old = time.time() - compiled.KEEP_UNUSED_S - 86400.0
    here, other, third = cache / f"casadi-{ca.__version__}", cache / "casadi-0.0.0", cache / "casadi-0.0.1"
    x = ca.SX.sym("x", 2)
    f = ca.Function("reachirl_test_used", [x], [ca.sumsqr(x)])
    solver = here / "doc-used" / "solver.casadi"
    solver.parent.mkdir(parents=True)
    f.save(str(solver))
    for stale in (
        here / "doc-stale",
        here / "fn-stale",
        other / "doc-stale",
        third / "fn-stale",
        here / "doc-busy.lock",
    ):
        stale.mkdir(parents=True)
        (stale / "solver.casadi").write_text("")
    (here / "fn-stale-0123.so").write_text("")
    (here / "paths").mkdir()
    for recipe, name in (("a", "doc-stale"), ("b", "doc-used"), ("c", "")):
        (here / "paths" / f"{recipe}.txt").write_text(name + "\n")
    (here / "make-run-solvers.stamp").write_text("")
    (other / "make-run-solvers.stamp").write_text("")
    (third / "make-run-solvers.stamp").write_text("")
    for entry in [*here.iterdir(), *other.iterdir(), *third.iterdir()]:
        os.utime(entry, (old, old))

    assert compiled.load(solver) is not None  # used now: kept
    assert compiled.load(here / "doc-missing" / "solver.casadi") is None
    with compiled.setting("on"):
        g = compiled.compiled_function(f)  # a new entry: the library of f, which prunes
    assert g is not None and np.isclose(float(g([1.0, 2.0])), 5.0)
    left = sorted(str(p.relative_to(cache)) for p in cache.rglob("*") if p.parent.name.startswith("casadi-"))
    assert left == sorted(
        [
            "casadi-0.0.1/make-run-solvers.stamp",  # no solver of that version went (a function did)
            f"casadi-{ca.__version__}/doc-busy.lock",  # a compilation's lock: never removed here
            f"casadi-{ca.__version__}/doc-used",
            next(str(p.relative_to(cache)) for p in here.glob("fn-reachirl_test_used-*.so")),
            f"casadi-{ca.__version__}/paths",
        ]
    ), left
    assert sorted(p.name for p in (here / "paths").iterdir()) == ["b.txt"]
    assert compiled.prune() == []  # nothing more to remove; the new library and the used solver are recent


def test_a_c_file_is_compiled_once_and_none_where_it_cannot_be(cache, monkeypatch, tmp_path):
    """compiled_library: a C file compiled into the cache once (the next call finds it), under a key of its source
    and flags; None when off, without a compiler, or for a file that does not compile (never an error)."""
    import ctypes

    src = tmp_path / "reachirl_test_add.c"
    src.write_text("double reachirl_test_add(double a, double b) { return a + b; }\n")
    with compiled.setting("on"):
        path = compiled.compiled_library(src)
        assert path is not None and path.parent == cache / f"casadi-{ca.__version__}"
        made = path.stat().st_ino  # a library written again (atomically) would be another file
        assert compiled.compiled_library(src) == path and path.stat().st_ino == made
        add = ctypes.CDLL(str(path)).reachirl_test_add
        add.argtypes, add.restype = [ctypes.c_double, ctypes.c_double], ctypes.c_double
        assert add(0.25, 2.0) == 2.25
        src.write_text("double reachirl_test_add(double a, double b) { return a - b; }\n")
        assert compiled.compiled_library(src) not in (None, path)  # another source, another library
        bad = tmp_path / "reachirl_test_bad.c"
        bad.write_text("this is not C\n")
        assert compiled.compiled_library(bad) is None
        monkeypatch.setenv("PATH", "")  # no gcc to be found
        src.write_text("double reachirl_test_add(double a, double b) { return a * b; }\n")
        assert compiled.compiled_library(src) is None
    with compiled.setting("off"):
        assert compiled.compiled_library(tmp_path / "reachirl_test_add.c") is None


def test_a_damaged_small_function_library_is_compiled_again(cache):
    """A cached library of compiled_function that does not load (another file under its name) is replaced, once,
    by a new compilation, which gives the virtual machine's bits: Newton's step is not left on the VM for ever."""
    x = ca.SX.sym("x", 2)
    f = ca.Function("reachirl_test_damaged", [x], [ca.sin(x) * ca.exp(x[1])])
    with compiled.setting("on"):
        path = compiled.function_path(f)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"not a shared library")
        fc = compiled.compiled_function(f)
    assert fc is not None and path.read_bytes() != b"not a shared library"
    arg = np.array([0.4, -0.7])
    assert np.array_equal(np.asarray(fc(arg)), np.asarray(f(arg)))
