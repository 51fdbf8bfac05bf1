"""The compiled knot: ``knot.cpp``, the C++ twin of :class:`~reachirl.doc.crocoddyl.knots.KnotModel`, built once
per machine against the installed Crocoddyl and cached.

CSQP calls each knot's ``calc`` and ``calcDiff`` from C++ several times per SQP iteration; the compiled knot
answers without calling into Python. It does the Python knot's arithmetic in the same order (bit-identical
results) on the same inner ``IntegratedActionModelEuler`` and its built-in Crocoddyl costs and constraints.

The first problem a process builds compiles ``knot.cpp`` with ``g++`` unless it is cached, under
a file lock so that workers starting together compile it once. The cache is
``<cache>/crocoddyl-<version>/knot-<hash>/`` (``$REACHIRL_CACHE``, else ``$XDG_CACHE_HOME/reachirl``, else
``~/.cache/reachirl``); the hash covers the source, the compiler command and Python's extension suffix. Where
it cannot be built or loaded (no C++ compiler, headers missing) the Python knot is used, and :func:`status` says
why (``CsqpOptions(compiled_knots=False)`` asks for the Python knot).
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import importlib.util
import logging
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import crocoddyl

from ...io import atomic_path, cache_root
from .knots import KnotModel, KnotSettings

__all__ = ["SOURCE", "build_command", "knot_class", "status"]

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("knot.cpp")
_MODULE = "_knot"  # BOOST_PYTHON_MODULE's name in knot.cpp
_STATUS: dict[str, str] = {}


def _prefix() -> Path:
    """The folder of the installed Crocoddyl's headers and libraries (the cmeel wheels' prefix)."""
    return Path(crocoddyl.__file__).resolve().parents[4]


def build_command(source: Path, target: Path) -> list[str]:
    """The compiler command that builds ``source`` into the extension ``target``."""
    prefix = _prefix()
    lib = prefix / "lib"
    boost_python = f"boost_python{sys.version_info.major}{sys.version_info.minor}"
    return [
        os.environ.get("CXX", "g++"),
        "-O2",
        "-std=c++17",
        "-shared",
        "-fPIC",
        "-fopenmp",
        "-w",
        # Crocoddyl's and Pinocchio's exported compile definitions (their CMake targets')
        "-DPINOCCHIO_ENABLE_COMPATIBILITY_WITH_VERSION_2",
        "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
        "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
        "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
        f"-I{prefix / 'include'}",
        f"-I{prefix / 'include' / 'eigen3'}",
        f"-I{sysconfig.get_paths()['include']}",
        str(source),
        "-o",
        str(target),
        f"-L{lib}",
        f"-Wl,-rpath,{lib}",
        "-lcrocoddyl",
        f"-l{boost_python}",
    ]


def _cache_dir() -> Path:
    h = hashlib.sha256()
    h.update(SOURCE.read_bytes())
    h.update(" ".join(build_command(Path("knot.cpp"), Path(_MODULE))).encode())
    h.update(str(sysconfig.get_config_var("EXT_SUFFIX")).encode())
    return cache_root() / f"crocoddyl-{crocoddyl.__version__}" / f"knot-{h.hexdigest()[:24]}"


@contextlib.contextmanager
def _locked(folder: Path):
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _build(folder: Path) -> Path:
    """The cached extension, compiled first if it is not there."""
    target = folder / f"{_MODULE}{sysconfig.get_config_var('EXT_SUFFIX')}"
    with _locked(folder):
        if not target.exists():
            if shutil.which(os.environ.get("CXX", "g++")) is None:
                raise OSError("no C++ compiler (g++, or $CXX) on the PATH")
            with atomic_path(target, durable=False) as tmp:
                done = subprocess.run(build_command(SOURCE, tmp), capture_output=True, text=True)
                if done.returncode != 0:
                    lines = done.stderr.strip().splitlines() or ["(no output)"]
                    raise OSError(f"g++ failed: {next((x for x in lines if 'error' in x), lines[-1])}")
    return target


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(_MODULE, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _compiled_class(ext) -> type:
    class CompiledKnotModel(KnotSettings, ext.Knot):
        """:class:`~reachirl.doc.crocoddyl.knots.KnotModel` compiled: the same knot, its ``calc`` and
        ``calcDiff`` in C++ (``knot.cpp``); weights and time step are set the same way."""

        def __init__(self, inner, first: bool, terminal: bool, energy_smoothing: float):
            dam = inner.differential
            ng = int(dam.constraints.ng) if dam.constraints is not None else 0
            ext.Knot.__init__(self, inner, ng, terminal, float(energy_smoothing))
            self._settings(inner, first, ng)
            self.dt = float(inner.dt)

    return CompiledKnotModel


@functools.cache
def _compiled_or_python() -> type:
    try:
        path = _build(_cache_dir())
        cls = _compiled_class(_load(path))
    except (OSError, ImportError) as e:
        log.warning("Crocoddyl backend: the compiled knot is unavailable (%s); using the Python knot", e)
        _STATUS["knot"] = f"Python (compiled knot unavailable: {e})"
        return KnotModel
    _STATUS["knot"] = f"compiled ({path})"
    return cls


def knot_class(compiled: bool = True) -> type:
    """The knot class problems are built with: with ``compiled``, the compiled knot where it builds and loads,
    else :class:`~reachirl.doc.crocoddyl.knots.KnotModel`."""
    return _compiled_or_python() if compiled else KnotModel


def status() -> str:
    """Which knot a problem of the default options is built with in this process, and why."""
    _compiled_or_python()
    return _STATUS["knot"]
