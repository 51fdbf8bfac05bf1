"""Argument types shared by the subcommands: bad values become argparse's one-line usage error (exit 2)."""

from __future__ import annotations

import argparse
from collections.abc import Callable


def _checked(convert: Callable[[str], float], ok: Callable[[float], bool], expected: str,
             trim: int | None = None) -> Callable[[str], float]:
    """A parser: ``convert(text)``, refused with ``expected {expected}, got …`` when it fails or ``ok`` is
    False. The message echoes the value, or with ``trim`` the text cut to that many characters."""

    def parse(text: str):
        try:
            v = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text[:trim]!r}") from None
        if not ok(v):  # False for NaN in every range below
            raise argparse.ArgumentTypeError(f"expected {expected}, got {v if trim is None else text[:trim]}")
        return v

    return parse


def int_at_least(lo: int) -> Callable[[str], int]:
    """An integer ``>= lo``."""
    return _checked(int, lambda v: v >= lo, f"an integer >= {lo}")


def float_in(lo: float, hi: float) -> Callable[[str], float]:
    """A number in ``[lo, hi)``."""
    return _checked(float, lambda v: lo <= v < hi, f"a number in [{lo}, {hi})")


positive_int = int_at_least(1)
non_negative_int = int_at_least(0)


def int_in(lo: int, hi: int) -> Callable[[str], int]:
    """An integer in ``[lo, hi]`` (the limits go in the option's help)."""
    return _checked(int, lambda v: lo <= v <= hi, f"an integer in [{lo}, {hi}]", trim=40)


def number_in(lo: float, hi: float) -> Callable[[str], float]:
    """A finite number in ``[lo, hi]`` (NaN and infinities are refused)."""
    return _checked(float, lambda v: lo <= v <= hi, f"a number in [{lo:g}, {hi:g}]", trim=40)


def add_selection(p: argparse.ArgumentParser, what: str) -> None:
    """``--subject``, ``--posture`` and ``--side``: which trials of the trials file ``what`` (e.g. "fit")."""
    p.add_argument("--subject", nargs="+", metavar="ID", default=None,
                   help=f"{what} only these subjects' trials (default: every subject)")
    p.add_argument("--posture", nargs="+", metavar="NAME", default=None,
                   help=f"{what} only the trials of these postures (default: every posture)")
    p.add_argument("--side", choices=("right", "left"), default=None,
                   help=f"{what} only the trials of this arm (default: both)")


def chosen_trials(args: argparse.Namespace, trials: list) -> tuple[list, dict | None]:
    """Those of ``trials`` (read from the file ``args.trials``, which an error names) that ``--subject/--posture
    /--side`` choose (:func:`reachirl.data.trial.select_trials`), and those choices as its keywords (``None``
    when none was given: every trial)."""
    from ..data.trial import select_trials

    chosen = {"subjects": args.subject, "postures": args.posture, "sides": None if args.side is None else [args.side]}
    if all(v is None for v in chosen.values()):
        return trials, None
    return select_trials(trials, **chosen, path=args.trials), chosen
