"""Run files (``RUN.toml``): the options of a ``reproduce`` or ``fit`` run, read with :mod:`tomllib`.

A run file holds top-level keys (the protocol's and the run's options, named as in
:class:`reachirl.experiments.protocol.ProtocolConfig` and ``reproduce --help``) and an ``[experimental]`` table of
:class:`reachirl.irl.options.Options` fields. ``reproduce`` writes the options it ran with as ``RUN_DIR/run.toml``,
which ``reproduce --config RUN_DIR/run.toml`` reads back to repeat the run exactly.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io import atomic_write_text

__all__ = ["dumps", "parse_assignment", "read_run_file", "write_run_file"]


def read_run_file(path: str | Path) -> dict[str, Any]:
    """The run file's keys; a file that is missing, not a regular file, not TOML or without a single key (empty,
    or comments only: a file cut short, rather than a run of every default) is an :class:`InputError` naming it
    (and the line where TOML says)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(
            "run file not found (expected a TOML file)"
            if not p.exists()
            else "not a regular file (expected a TOML run file)",
            p,
        )
    try:
        with p.open("rb") as f:
            content = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not a TOML run file: {e}", p) from None
    except UnicodeDecodeError:
        raise InputError("not a TOML run file (not UTF-8 text)", p) from None
    if not content:
        raise InputError(
            "the run file sets no option (empty, or comments only); leave --config out for the defaults", p
        )
    return content


def parse_assignment(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` of ``--set``, the value read as TOML (``n_train=0``, ``cv="other-side"``, ``postures=["P2"]``;
    a bare word is taken as a string). ``ValueError`` names what is wrong."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ValueError(f"expected KEY=VALUE, got {text[:60]!r}")
    try:
        return key, tomllib.loads(f"v = {value.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        return key, value.strip()


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"a run file holds finite numbers only, got {v}")
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise ValueError(f"a run file cannot hold {type(v).__name__} values")


def written(v: Any) -> str:
    """``v`` as a run file writes it (``true``, ``"P2"``, ``[8, 0]``, ``{merit = "state"}``); a value a run file
    cannot hold (a date, a non-finite number) as Python writes it."""
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {written(x)}" for k, x in v.items()) + "}"
    try:
        return _value(v)
    except ValueError:
        return repr(v)


def dumps(options: dict[str, Any]) -> str:
    """TOML text of ``options``: scalars and lists at the top (``None`` left out: the default), mappings as
    tables."""
    top = [f"{k} = {_value(v)}" for k, v in options.items() if v is not None and not isinstance(v, dict)]
    tables = []
    for k, v in options.items():
        if isinstance(v, dict):
            rows = [f"{kk} = {_value(vv)}" for kk, vv in v.items() if vv is not None]
            tables.append(f"\n[{k}]\n" + "\n".join(rows) + ("\n" if rows else ""))
    return "\n".join(top) + "\n" + "".join(tables)


def write_run_file(path: str | Path, options: dict[str, Any], header: str = "") -> Path:
    """Write ``options`` as TOML (atomically), with ``header`` as comment lines on top."""
    text = "".join(f"# {line}\n" for line in header.splitlines()) + dumps(options)
    atomic_write_text(path, text)
    return Path(path)
