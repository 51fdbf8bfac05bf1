"""Compiled DOC solvers: the fatrop solvers of one number of knots (the cold one, and the warm one MO-IRL's line
searches use), compiled to C once and cached on disk.

CasADi evaluates the NLP's functions (objective, constraints, their derivatives, the Lagrangian's Hessian) in
its virtual machine. Compiled with the system C compiler (``gcc -O1``) they take about half that time, and the
solver's results are bit-identical (the same operations in the same order; tested). Compiling one solver of
one number of knots ``N`` (it serves any number of windows) takes tens of seconds of CPU and about 20 MB of
disk, so it is done only where it pays off, which the environment variable ``REACHIRL_COMPILE`` decides:

* ``auto`` (the default): a compiled solver already in the cache is used. A process that has solved
  :data:`AUTO_AFTER` cold (or :data:`AUTO_AFTER_WARM` warm) DOCs of one number of knots (a long run: an
  all-pairs study, a large evaluation) starts that solver's compilation in a background process, goes on
  solving meanwhile, and switches to the compiled solver when its file appears. Other processes that need the
  same solver wait for that file instead of compiling it again.
* ``on``: the first cold (warm) solve of a number of knots compiles the cold (warm) solver (and waits),
  unless it is cached.
* ``off``: never compile, never load.

:func:`prepare` compiles the solvers of one number of knots before any solve, side by side (``make run`` has its
own compiled so, once per machine: ``python -m reachirl.doc.compile_job prepare 100``). Compilation always runs
in a process of its own (``python -m reachirl.doc.compile_job``), because CasADi writes its sources into the
working directory: the solving process never changes its own.

The cache holds CasADi's own serialisation of the solver (no pickle) beside the library it links to, in
``<cache>/casadi-<version>/doc-<hash>/`` (``$REACHIRL_CACHE``, else ``$XDG_CACHE_HOME/reachirl``, else
``~/.cache/reachirl``). The hash covers the CasADi version, the NLP's own serialisation and the solver
options, so a change of formulation or options never loads a stale solver. That hash needs the NLP's symbolic
graph; a note in ``paths/`` remembers it under a hash of the code that builds the NLP (:func:`remembered_path`), so
that a process whose solvers are cached never builds the graph; the uncertainty's KKT functions are likewise
saved once, under such a hash, in ``fn-<hash>/`` (:func:`cached_functions`); small functions and C files are
compiled into libraries beside them (``fn-<name>-<hash>.so``: :func:`compiled_function`, :func:`compiled_library`).
A file that does not load is ignored (the virtual machine solves instead, or the functions are built; a small
library is compiled again, once), and so is a missing compiler.

Each version of that code keeps its own entries (about 20 MB a solver). Loading an entry marks it used (its
modification time); whenever a process writes a new one, the entries of every CasADi version's folder that no
process has used for :data:`KEEP_UNUSED_S` are removed (:func:`prune`): an upgrade's old solvers go, the ones in
use stay.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from ..io import atomic_path, atomic_write_text, cache_root

__all__ = [
    "AUTO_AFTER",
    "AUTO_AFTER_WARM",
    "KINDS",
    "MODES",
    "Slot",
    "cache_path",
    "cached_functions",
    "compile_or_wait",
    "compile_solver",
    "compiled_function",
    "compiled_library",
    "function_path",
    "load",
    "mode",
    "on_setting",
    "prepare",
    "prune",
    "release",
    "remember",
    "remembered_path",
    "setting",
    "start_background",
]

MODES = ("auto", "on", "off")
AUTO_AFTER = 1000  # cold solves of one NLP in one process before ``auto`` compiles it (~25 s of solving)
AUTO_AFTER_WARM = 3000  # warm solves likewise (~50 s of solving; `make run` makes about 1000 per process)
KINDS = ("cold", "warm")
# measured at N = 100: -O0 runs slower than CasADi's virtual machine; -Os compiles 54 s, not 36; -O2 and -O3
# compile 80 s, not 49, and solve no faster (warm 10.9 ms with each of -O1, -O2, -O3, interleaved in one process)
# every compiled code's: no multiply-add fused into one rounding, so that it gives the virtual machine's bits on
# processors whose baseline has such an instruction (aarch64); x86-64's has none, and its code is the same without it
# (nor -march=native: its fused multiply-adds change the bits, and a library built for one processor would crash
# another that shares the cache)
SAME_BITS = ("-ffp-contract=off",)
JIT_FLAGS = ("-O1", *SAME_BITS)
# the small functions of compiled_function: Newton's step function at N = 100 ran in 125 µs at -O3 against 155 µs at
# -O2, with the same bits
FUNCTION_FLAGS = ("-O3", *SAME_BITS)
# the C files of compiled_library, whose operations are a BLAS's: fused multiply-adds where the processor has them
# (the source's target_clones pick them at load time), as OpenBLAS's kernels fuse them (the same bits as LAPACK's)
LIBRARY_FLAGS = ("-O3", "-ffp-contract=fast")
POLL_EVERY = 50  # past its threshold, a slot looks for the background compilation's file every this many solves
STALE_LOCK_S = 900.0  # a compilation lock older than this is abandoned (its process died)
STALE_TMP_S = 86400.0  # an empty temporary file of a load older than this was left by a process that died
KEEP_UNUSED_S = 60 * 86400.0  # a solver or function no process has loaded for this long is removed (prune)
_ON_SETTING: list[Callable[[], None]] = []  # what setting() calls on both sides of its block (see on_setting)


def mode() -> str:
    """``REACHIRL_COMPILE``, one of :data:`MODES` (default ``auto``)."""
    value = os.environ.get("REACHIRL_COMPILE", "auto").strip().lower() or "auto"
    if value not in MODES:
        raise InputError(f"environment variable REACHIRL_COMPILE={value!r}: expected one of {', '.join(MODES)}")
    return value


def on_setting(forget: Callable[[], None]) -> Callable[[], None]:
    """Have :func:`setting` call ``forget`` on both sides of its block: a backend that holds solvers (the CasADi
    backend's cached NLPs) drops them, so the block's solves, and those after it, follow the mode in force.
    Returns ``forget``."""
    _ON_SETTING.append(forget)
    return forget


@contextlib.contextmanager
def setting(value: str):
    """``REACHIRL_COMPILE=value`` inside the block (benchmarks, tests), with the solvers that backends hold
    dropped on both sides (:func:`on_setting`)."""
    before = os.environ.get("REACHIRL_COMPILE")
    os.environ["REACHIRL_COMPILE"] = value
    mode()
    for forget in _ON_SETTING:
        forget()
    try:
        yield
    finally:
        for forget in _ON_SETTING:
            forget()
        if before is None:
            os.environ.pop("REACHIRL_COMPILE", None)
        else:
            os.environ["REACHIRL_COMPILE"] = before


def _options(options: dict, folder: Path | str = "<cache folder>") -> dict:
    # "link": the saved solver loads the library compiled beside it (kept: no clean-up); "embed" would write
    # the library back to its first path at every load, from every process. "directory": where CasADi puts its
    # temporary files, also the empty one it creates at every load (in the working directory by default)
    return {
        **options,
        "jit": True,
        "compiler": "shell",
        "jit_serialize": "link",
        "jit_options": {
            "flags": list(JIT_FLAGS),
            "verbose": False,
            "cleanup": False,
            "directory": os.path.join(str(folder), ""),
        },
    }


def cache_path(nlp: dict, options: dict) -> Path:
    """Where the compiled solver of ``nlp`` (CasADi's NLP dict) under ``options`` is cached."""
    import casadi as ca

    f = ca.Function("nlp", [nlp["x"], nlp["p"]], [nlp["f"], nlp["g"]])
    h = hashlib.sha256()
    h.update(ca.__version__.encode())
    h.update(f.serialize().encode())
    h.update(json.dumps(_options(options), sort_keys=True, default=str).encode())
    return _folder() / f"doc-{h.hexdigest()[:24]}" / "solver.casadi"


def _folder() -> Path:
    """The cache's folder of this CasADi version's solvers and functions."""
    import casadi as ca

    return cache_root() / f"casadi-{ca.__version__}"


def _note(recipe: str) -> Path:
    return _folder() / "paths" / f"{recipe}.txt"


def remembered_path(recipe: str, nlp: Callable[[], dict], options: dict) -> Path:
    """:func:`cache_path` of ``nlp()`` under ``options``, or the path noted under ``recipe`` (a hash of the code
    that builds the NLP and of the options; :func:`remember`) while the solver there is in the cache: the NLP's
    symbolic graph, which the hash of its serialisation needs, is built only where that code changed or the solver
    is not compiled yet (or always, with an empty ``recipe``: code that cannot be hashed)."""
    if not recipe:
        return cache_path(nlp(), options)
    note = _note(recipe)
    with contextlib.suppress(OSError, UnicodeDecodeError):
        name = note.read_text(encoding="utf-8").strip()
        path = note.parent.parent / name / "solver.casadi"
        if name.startswith("doc-") and name == Path(name).name and path.is_file():
            return path
    return cache_path(nlp(), options)


def remember(recipe: str, path: Path) -> None:
    """Note under ``recipe`` that its solver is at ``path`` (for :func:`remembered_path`); nothing if it cannot, or
    with an empty ``recipe``."""
    if not recipe:
        return
    note = _note(recipe)
    with contextlib.suppress(OSError):
        if not (note.is_file() and note.read_bytes().strip() == path.parent.name.encode()):
            note.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(note, path.parent.name + "\n", durable=False)


def cached_functions(recipe: str, build: Callable[[], dict]) -> dict:
    """``build()`` (CasADi functions by name), saved in the cache under ``recipe`` (a hash of the code that builds
    them) by the first process that builds them and loaded by the others (``fn-<recipe>/``): CasADi's own
    serialisation of the same functions, which evaluate bit for bit as built. Built every time when :func:`mode`
    is ``off``, when the code cannot be hashed (empty ``recipe``), or when a saved file does not load."""
    import casadi as ca

    if mode() == "off" or not recipe:
        return build()
    folder = _folder() / f"fn-{recipe}"
    with contextlib.suppress(Exception):  # none saved yet, or a file that does not load: built below
        names = (folder / "names.txt").read_text(encoding="utf-8").split()
        loaded = {name: ca.Function.load(str(folder / f"{name}.casadi")) for name in names}
        _used(folder)
        return loaded
    functions = build()
    with contextlib.suppress(OSError, RuntimeError):
        folder.mkdir(parents=True, exist_ok=True)
        for name, f in functions.items():
            with atomic_path(folder / f"{name}.casadi") as tmp:
                f.save(str(tmp))
        atomic_write_text(folder / "names.txt", "\n".join(functions) + "\n", durable=False)  # last: all or none
        prune()
    return functions


def load(path: Path):
    """The cached solver at ``path`` (a ``casadi.Function``), or None when there is none or it does not load."""
    import casadi as ca

    try:
        if not path.is_file():
            return None
        # each load creates an empty temporary file beside the solver, which CasADi removes when the process
        # unloads it; a process that ends abruptly (a killed worker) leaves it: remove those a day old
        for old in path.parent.glob("jit_tmp*.c"):
            with contextlib.suppress(OSError):
                st = old.stat()
                if st.st_size == 0 and time.time() - st.st_mtime > STALE_TMP_S:
                    old.unlink()
        solver = ca.Function.load(str(path))
        _used(path.parent)
        return solver
    except Exception:
        return None


def _used(path: Path) -> None:
    """Mark the cache entry ``path`` (a ``doc-`` or ``fn-`` folder, a function's library) used now, for
    :func:`prune`; nothing where the cache is read-only."""
    with contextlib.suppress(OSError):
        os.utime(path)


def prune(now: float | None = None) -> list[Path]:
    """Remove the solvers and functions (``doc-*``, ``fn-*``) of every ``casadi-<version>/`` folder of the cache
    that no process has used (:func:`_used`) for :data:`KEEP_UNUSED_S`, the notes (``paths/``) of the solvers gone,
    and ``make run``'s note that its solvers are compiled if one of them went; returns what was removed. Called
    where a new entry is written; a file that cannot be removed (another user's, in use) stays."""
    import shutil

    now = time.time() if now is None else now
    removed: list[Path] = []

    def remove(entry: Path) -> None:
        with contextlib.suppress(OSError):  # removed meanwhile by another process, or not ours to remove
            if entry.is_dir():
                shutil.rmtree(entry)
            else:
                entry.unlink()
            removed.append(entry)

    for folder in cache_root().glob("casadi-*"):
        for entry in [*folder.glob("doc-*"), *folder.glob("fn-*")]:
            with contextlib.suppress(OSError):
                if entry.suffix != ".lock" and now - entry.stat().st_mtime > KEEP_UNUSED_S:
                    remove(entry)
        if any(p.parent == folder and p.name.startswith("doc-") for p in removed):
            remove(folder / "make-run-solvers.stamp")
        for note in folder.glob("paths/*.txt"):
            with contextlib.suppress(OSError, UnicodeDecodeError):
                name = note.read_text(encoding="utf-8").strip()
                if not (name and (folder / name).is_dir()):
                    remove(note)
    return removed


def compile_solver(name: str, solver: str, nlp: dict, options: dict, path: Path):
    """Compile ``nlpsol(name, solver, nlp, options)`` into the folder of ``path`` and save the solver at
    ``path`` (last, atomically: a loader sees all or nothing); returns it.

    The saved solver links to the compiled library beside it, by absolute path. Raises RuntimeError when there
    is no working C compiler."""
    import casadi as ca

    path.parent.mkdir(parents=True, exist_ok=True)
    for stale in path.parent.glob("*"):  # an earlier, interrupted attempt's leftovers
        if stale.is_file():
            stale.unlink()
    cwd = os.getcwd()
    os.chdir(path.parent)  # CasADi writes the C source and the library into the working directory (hence a
    # process of its own: see start_background)
    try:
        f = ca.nlpsol(name, solver, nlp, _options(options, path.parent))
    except Exception as e:
        raise RuntimeError(f"compiling the DOC solver failed (is a C compiler installed?): {e}") from None
    finally:
        os.chdir(cwd)
    for obj in path.parent.glob("*.o"):
        obj.unlink()
    with atomic_path(path) as tmp:
        f.save(str(tmp))
    prune()
    return f


def _lock(path: Path) -> Path:
    return path.parent.with_name(path.parent.name + ".lock")


def release(path: Path) -> None:
    """Release the compilation lock of ``path`` (taken by :func:`start_background`)."""
    _lock(path).unlink(missing_ok=True)


def _acquire(path: Path) -> bool:
    """Take the compilation lock of ``path`` (a file beside its folder); False when another process holds it
    (or the cache is not writable). A lock older than :data:`STALE_LOCK_S` is taken over."""
    lock = _lock(path)
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
        if lock.exists() and time.time() - lock.stat().st_mtime > STALE_LOCK_S:
            lock.unlink(missing_ok=True)
        os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        return True
    except OSError:
        return False


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")


def compile_or_wait(n: int, path: Path, kind: str = "cold"):
    """The ``kind`` solver of ``n`` knots at ``path``, once compiled (by :func:`start_background`, or by the
    process already compiling it). None when it cannot be had (no compiler, unwritable cache, that process
    failed)."""
    start_background(n, path, kind)
    deadline = time.monotonic() + STALE_LOCK_S
    while _lock(path).exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    return load(path)


def start_background(n: int, path: Path, kind: str = "cold") -> bool:
    """Compile the ``kind`` solver (one of :data:`KINDS`) of ``n`` knots in a detached process unless another
    process already is; True when one was started here. The detached process releases the lock when done."""
    _check_kind(kind)
    if not _acquire(path):
        return False
    subprocess.Popen(
        [sys.executable, "-m", "reachirl.doc.compile_job", str(n), kind, str(path)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env={**os.environ, "REACHIRL_COMPILE": "off"},
    )
    return True


def prepare(slots: list[Slot]) -> dict[str, bool]:
    """Have the solver of each of ``slots`` compiled and cached where it is not yet, all at once, each in a
    process of its own (:func:`start_background`), and wait for them: ``{kind: cached}``, False where it could not
    be (no C compiler, an unwritable cache, :func:`mode` ``off``). The set-up a machine does once
    (``make run``): afterwards every process that solves loads these solvers instead of CasADi's VM."""
    if mode() == "off":
        return {slot.kind: False for slot in slots}
    paths = {slot.kind: remembered_path(slot.recipe, slot.nlp, slot.spec[2]) for slot in slots}
    cached = {kind: load(path) is not None for kind, path in paths.items()}
    for slot in slots:
        if not cached[slot.kind]:
            start_background(slot.n, paths[slot.kind], slot.kind)
    deadline = time.monotonic() + STALE_LOCK_S
    while any(_lock(p).exists() for p in paths.values()) and time.monotonic() < deadline:
        time.sleep(0.2)
    for slot in slots:  # those compiled here, loaded once to check them
        cached[slot.kind] = cached[slot.kind] or load(paths[slot.kind]) is not None
        if cached[slot.kind]:
            remember(slot.recipe, paths[slot.kind])
    return cached


class Slot:
    """The compiled ``kind`` solver (``"cold"`` or ``"warm"``) of one NLP in this process: when to load it and
    when to have it compiled (see the module docstring). ``nlp()`` builds the NLP (CasADi's dict), ``spec`` is
    ``(name, plugin, options)`` of the solver to compile and ``recipe`` a hash of the code that builds them
    (:func:`remembered_path`; empty: the NLP is built to find the solver's file)."""

    def __init__(
        self, n: int, nlp: Callable[[], dict], spec: tuple[str, str, dict], kind: str = "cold", recipe: str = ""
    ):
        _check_kind(kind)
        self.n, self.nlp, self.spec, self.kind, self.recipe = n, nlp, spec, kind, recipe
        self.solves = 0
        self._path: Path | None = None

    def get(self):
        """The compiled solver (a ``casadi.Function``) for this solve, or None: solve on the VM."""
        how = mode()
        if how == "off":
            return None
        self.solves += 1
        if self._path is None:
            self._path = remembered_path(self.recipe, self.nlp, self.spec[2])
        k, after = self.solves, AUTO_AFTER if self.kind == "cold" else AUTO_AFTER_WARM
        solver = load(self._path) if k == 1 or (k > after and k % POLL_EVERY == 0) else None
        if solver is None and how == "on" and k == 1:
            solver = compile_or_wait(self.n, self._path, self.kind)
        if solver is None and how == "auto" and k == after:
            start_background(self.n, self._path, self.kind)
        if solver is not None:
            remember(self.recipe, self._path)
        return solver


def compiled_function(f):
    """``f`` (a small ``casadi.Function``) compiled to a shared library, cached on disk beside the solvers
    (``<cache>/casadi-<version>/fn-<hash>.so``, the hash covering CasADi's version and ``f``'s serialisation) and
    loaded with ``casadi.external``; None when :func:`mode` is ``off`` or there is no working C compiler (the
    caller then evaluates ``f`` in CasADi's virtual machine). Compiling takes a fraction of a second, in a
    temporary folder (never the working directory); the library is moved into the cache atomically."""
    import casadi as ca

    if mode() == "off":
        return None
    path = function_path(f)

    def generate(folder: Path) -> Path:
        gen = ca.CodeGenerator(f"{f.name()}.c", {"with_header": False})
        gen.add(f)
        gen.generate(os.path.join(str(folder), ""))
        return folder / f"{f.name()}.c"

    try:
        return _loaded_library(path, generate, FUNCTION_FLAGS, lambda p: ca.external(f.name(), str(p)))
    except (OSError, subprocess.SubprocessError, RuntimeError):  # RuntimeError: CasADi's code generation
        return None


def function_path(f) -> Path:
    """Where :func:`compiled_function` caches the library of ``f``: the hash covers CasADi's version, ``f``'s
    serialisation and :data:`FUNCTION_FLAGS`."""
    import casadi as ca

    h = hashlib.sha256()
    h.update(ca.__version__.encode())
    h.update(f.serialize().encode())
    h.update(" ".join(FUNCTION_FLAGS).encode())
    return _folder() / f"fn-{f.name()}-{h.hexdigest()[:24]}.so"


def compiled_library(source: Path, load: Callable[[Path], object] | None = None):
    """The C file ``source`` (plain C, no Python) compiled to a shared library with :data:`LIBRARY_FLAGS` and cached
    (``<cache>/casadi-<version>/fn-<stem>-<hash>.so``, the hash covering the source and the flags): its path, or
    ``load(path)`` (e.g. a ``ctypes`` function of it; a cached file that ``load`` cannot load is compiled again,
    once); None when :func:`mode` is ``off`` or it cannot be compiled or loaded."""
    if mode() == "off":
        return None
    source = Path(source)
    h = hashlib.sha256()
    h.update(source.read_bytes())
    h.update(" ".join(LIBRARY_FLAGS).encode())
    path = _folder() / f"fn-{source.stem}-{h.hexdigest()[:24]}.so"
    try:
        return _loaded_library(path, lambda folder: source, LIBRARY_FLAGS, load or (lambda p: p))
    except (OSError, subprocess.SubprocessError):
        return None


def _loaded_library(path: Path, source: Callable[[Path], Path], flags: tuple[str, ...], load: Callable[[Path], object]):
    """``load(path)`` of the library :func:`_library` compiles into ``path`` (marked used); a cached file that does
    not load (damaged) is removed and compiled again, once. None without a C compiler or when it still does not
    load."""
    for again in (False, True):
        if not _library(path, source, flags):
            return None
        try:
            loaded = load(path)
        except (OSError, RuntimeError, AttributeError):
            if again:
                return None
            with contextlib.suppress(OSError):
                path.unlink()
            continue
        _used(path)
        return loaded
    return None


def _library(path: Path, source: Callable[[Path], Path], flags: tuple[str, ...]) -> bool:
    """Whether the shared library ``path`` is in the cache, compiled first if it is not: from the C file
    ``source(folder)`` (written into the temporary ``folder`` where it is generated), moved in atomically. False
    without a C compiler."""
    import shutil
    import tempfile

    if path.is_file():
        return True
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        return False
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        c_file = source(Path(tmp))
        lib = Path(tmp) / "lib.so"
        subprocess.run(
            [cc, *flags, "-shared", "-fPIC", "-o", str(lib), str(c_file)], check=True, capture_output=True, timeout=120
        )
        with atomic_path(path) as out:
            shutil.copyfile(lib, out)
    prune()
    return True
