"""The background compilation of one CasADi DOC solver: ``python -m reachirl.doc.compile_job N KIND PATH``, which
:func:`reachirl.doc.compiled.start_background` starts in a detached process. It builds the NLP of ``N`` knots
(:mod:`reachirl.doc.casadi`), compiles its ``KIND`` solver to ``PATH`` (:func:`reachirl.doc.compiled.compile_solver`)
and releases the compilation lock, whatever happens."""

from __future__ import annotations

import sys
from pathlib import Path

from .casadi import build_nlp
from .compiled import cache_path, compile_solver, release

__all__ = ["main"]


def main(argv: list[str]) -> int:
    """Compile the solver ``argv = [N, KIND, PATH]`` names; 0 when it was compiled, 1 otherwise (among others when
    PATH is not where this version of the code caches that solver)."""
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


if __name__ == "__main__":  # pragma: no cover - run as a detached process by start_background
    sys.exit(main(sys.argv[1:]))
