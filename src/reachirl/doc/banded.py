"""The banded linear solve of the Newton methods on the knots (:mod:`.newton`, :mod:`.interior`): LAPACK's
``dgbsv`` (an LU factorisation with partial pivoting on LAPACK's band storage), for one right-hand side.

A Newton step at N = 100 factorises about 300 unknowns with a half-bandwidth of 10, and LAPACK's unblocked
``dgbtf2`` spends most of its time in the BLAS calls it makes column by column (about 90 µs). ``banded_lu.c`` does
the same operations in the same order in one loop (about 30 µs), compiled once per machine into the cache
(:func:`reachirl.doc.compiled.compiled_library`); with the fused multiply-adds of OpenBLAS's kernels, its answers
are LAPACK's to the last bit. Where it is not compiled (:func:`reachirl.doc.compiled.mode` ``off``, no C compiler),
SciPy's ``dgbsv`` solves.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import threading
from pathlib import Path

import numpy as np
from scipy.linalg.lapack import dgbsv

from . import compiled

__all__ = ["SOURCE", "lapack_only", "native", "solve"]

SOURCE = Path(__file__).with_name("banded_lu.c")

_lock = threading.Lock()
_lapack_only = False  # lapack_only()'s switch


def _library():
    """The compiled solve (a ``ctypes`` function), or None where it is not to be used or cannot be made."""
    return None if _lapack_only or compiled.mode() == "off" else _loaded()


@contextlib.contextmanager
def lapack_only():
    """Within the block, SciPy's ``dgbsv`` solves even where the compiled loop is available (``reachirl bench
    predict`` times the two in one run)."""
    global _lapack_only
    before, _lapack_only = _lapack_only, True
    try:
        yield
    finally:
        _lapack_only = before


@functools.lru_cache(maxsize=1)
def _loaded():
    """The compiled library's function, loaded once per process (compiled again, once, where the cached file is
    damaged: :func:`reachirl.doc.compiled.compiled_library`)."""
    with _lock:
        return compiled.compiled_library(SOURCE, _bind)


def _bind(path: Path):
    f = ctypes.CDLL(str(path)).reachirl_band_solve
    f.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
    f.restype = ctypes.c_int
    return f


def native() -> bool:
    """Whether :func:`solve` runs the compiled loop (else SciPy's ``dgbsv``)."""
    return _library() is not None


def solve(kl: int, ku: int, ab: np.ndarray, b: np.ndarray) -> int:
    """Solve ``A x = b`` in place: ``ab (2·kl + ku + 1, n)``, ``A`` in LAPACK's band storage (its first ``kl`` rows
    the factorisation's fill-in), overwritten by the factors; ``b (n,)`` by ``x``. Both float64, ``ab``
    Fortran-ordered and ``b`` contiguous. Returns LAPACK's ``info``: 0, or ``j > 0`` where the ``j``-th pivot is
    exactly zero (``b`` is then left unsolved)."""
    n = ab.shape[1]
    if ab.shape[0] != 2 * kl + ku + 1 or b.shape != (n,):
        raise ValueError(f"band storage {ab.shape} and right-hand side {b.shape} do not fit kl={kl}, ku={ku}")
    if ab.dtype != np.float64 or b.dtype != np.float64 or not ab.flags.f_contiguous or not b.flags.c_contiguous:
        raise ValueError("the band storage must be Fortran-ordered float64 and the right-hand side contiguous float64")
    f = _library()
    if f is None:
        _, _, x, info = dgbsv(kl, ku, ab, b, overwrite_ab=True, overwrite_b=True)
        if x is not b:
            b[:] = x
        return int(info)
    info = int(f(n, kl, ku, ab.ctypes.data, b.ctypes.data))
    if info < 0:
        raise MemoryError(f"no memory for the pivots of a banded LU of {n} unknowns")
    return info
