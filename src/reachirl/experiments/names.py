"""The order of postures and subjects in every table and figure: numbers by value (P1, P2, …, P10); and how a
number of sections is written.

Kept apart from the tables so that drawing a figure imports neither the protocol nor the data layer.
"""

from __future__ import annotations

import re

__all__ = ["natural_key", "sections_text"]


def natural_key(name: str) -> tuple:
    """Sort key of a posture (or subject) name that orders its numbers by value: P1, P2, …, P10."""
    return tuple(
        (0, int(part), "") if part.isdigit() else (1, 0, part) for part in re.split(r"(\d+)", str(name)) if part
    )


def sections_text(n: int) -> str:
    """``"1 section"``, ``"8 sections"``."""
    return f"{n} section{'' if int(n) == 1 else 's'}"
