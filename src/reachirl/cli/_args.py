"""Argument types shared by the subcommands: bad values become argparse's one-line usage error (exit 2)."""

from __future__ import annotations

import argparse
from collections.abc import Callable


def int_at_least(lo: int) -> Callable[[str], int]:
    """An integer ``>= lo``."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {lo}, got {text!r}") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"expected an integer >= {lo}, got {v}")
        return v

    return parse


def float_in(lo: float, hi: float) -> Callable[[str], float]:
    """A number in ``[lo, hi)``."""

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number in [{lo}, {hi}), got {text!r}") from None
        if not lo <= v < hi:
            raise argparse.ArgumentTypeError(f"expected a number in [{lo}, {hi}), got {v}")
        return v

    return parse


positive_int = int_at_least(1)
non_negative_int = int_at_least(0)


def int_in(lo: int, hi: int) -> Callable[[str], int]:
    """An integer in ``[lo, hi]`` (the limits go in the option's help)."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer in [{lo}, {hi}], got {text[:40]!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"expected an integer in [{lo}, {hi}], got {text[:40]}")
        return v

    return parse


def number_in(lo: float, hi: float) -> Callable[[str], float]:
    """A finite number in ``[lo, hi]`` (NaN and infinities are refused)."""

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number in [{lo:g}, {hi:g}], got {text[:40]!r}") from None
        if not lo <= v <= hi:  # False for NaN
            raise argparse.ArgumentTypeError(f"expected a number in [{lo:g}, {hi:g}], got {text[:40]}")
        return v

    return parse
