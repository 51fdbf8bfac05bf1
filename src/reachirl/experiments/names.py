"""The order of postures and subjects in every table and figure: numbers by value (P1, P2, …, P10); and how a
number of sections, a fit's method and its DOC backend are written in titles.

Kept apart from the tables so that drawing a figure imports neither the protocol nor the data layer.
"""

from __future__ import annotations

import re

__all__ = ["backend_text", "method_text", "natural_key", "sections_text"]

#: the DOC backend a title leaves unsaid (the default), to keep titles short
DEFAULT_BACKEND = "casadi"

#: the convergence figure's title (plot_convergence's own, and a run's with its backend after it)
CONVERGENCE_TITLE = "MO-IRL convergence (accepted steps)"


def natural_key(name: str) -> tuple:
    """Sort key of a posture (or subject) name that orders its numbers by value: P1, P2, …, P10."""
    return tuple(
        (0, int(part), "") if part.isdigit() else (1, 0, part) for part in re.split(r"(\d+)", str(name)) if part
    )


def sections_text(n: int) -> str:
    """``"1 section"``, ``"8 sections"``."""
    return f"{n} section{'' if int(n) == 1 else 's'}"


def backend_text(backend: str | None) -> str:
    """``" on crocoddyl"``: the DOC backend as a title says what was solved on it; ``""`` for CasADi (the default)
    or when not known."""
    return "" if backend in (None, DEFAULT_BACKEND) else f" on {backend}"


def method_text(method: str, backend: str | None = None, seed_form: bool = False) -> str:
    """A fit's method as a title names it, with what departs from the defaults in brackets: ``"moirl"``,
    ``"moirl (seed form, crocoddyl)"`` (CasADi, the default backend, goes unsaid)."""
    extra = [w for w, on in (("seed form", seed_form), (backend, backend not in (None, DEFAULT_BACKEND))) if on]
    return method + (f" ({', '.join(map(str, extra))})" if extra else "")
