"""The compilation of CasADi DOC solvers, in processes of their own.

* ``python -m reachirl.doc.compile_job N KIND PATH``: the background compilation of one solver, which
  :func:`reachirl.doc.compiled.start_background` starts in a detached process. It builds the NLP of ``N`` knots
  (:mod:`reachirl.doc.casadi`), compiles its ``KIND`` solver to ``PATH``
  (:func:`reachirl.doc.compiled.compile_solver`) and releases the compilation lock, whatever happens.
* ``python -m reachirl.doc.compile_job prepare N``: the cold and warm solvers of ``N`` knots compiled side by side
  where they are not cached yet (:func:`reachirl.doc.casadi.prepare`), one line said of each; ``make run``'s
  set-up. Exit 0 either way (without them, solves run on CasADi's VM), 2 for a bad ``REACHIRL_COMPILE``."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import InputError
from .casadi import build_nlp, prepare
from .compiled import cache_path, compile_solver, release

__all__ = ["main"]


def main(argv: list[str]) -> int:
    """Compile the solver ``argv = [N, KIND, PATH]`` names; 0 when it was compiled, 1 otherwise (among others when
    PATH is not where this version of the code caches that solver); ``argv = ["prepare", N]``: 0, or 2 for a bad
    ``REACHIRL_COMPILE``."""
    if argv[:1] == ["prepare"]:
        return _prepare(int(argv[1]))
    n, kind, path = int(argv[0]), argv[1], Path(argv[2])
    try:
        nlp = build_nlp(n)
        name, solver, options = nlp.slots[kind].spec
        if cache_path(nlp.nlp, options) != path:  # another version of the code asked: do not cache under its name
            return 1
        compile_solver(name, solver, nlp.nlp, options, path)
        return 0
    except Exception:
        return 1
    finally:
        release(path)


def _prepare(n: int) -> int:
    try:
        cached = prepare(n)
    except InputError as e:  # REACHIRL_COMPILE set to what it cannot be
        print(f"error: {e}", file=sys.stderr)
        return 2
    off = "not compiled (no C compiler, an unwritable cache or REACHIRL_COMPILE=off): CasADi's VM solves"
    for kind, ok in cached.items():
        print(f"the {kind} DOC solver of {n} knots: {'compiled, cached' if ok else off}")
    return 0


if __name__ == "__main__":  # pragma: no cover - run as a process of its own (start_background, make run)
    sys.exit(main(sys.argv[1:]))
