"""What a protocol run leaves behind: the units' checkpoint files and the :class:`RunResult` that
:func:`reachirl.experiments.runner.reproduce` returns and :func:`reachirl.experiments.report.write_outputs` writes
out. Both modules import this one and never each other.

Each unit's result is ``OUT/units/<key>.json`` with its predictions in ``<key>.npz``: the NPZ is written first,
then the JSON, which marks the unit done.
"""

from __future__ import annotations

import json
import logging
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_write_bytes, atomic_write_json, npz_bytes, to_jsonable
from .no_data import annotate_no_data

__all__ = ["RunResult", "RunSummary", "content_checksum", "load_unit", "load_unit_arrays", "save_unit", "unit_paths"]


log = logging.getLogger(__name__)


@dataclass
class RunSummary:
    results: dict[str, dict]  # key -> unit result (JSON content)
    computed: list[str]
    reused: list[str]
    stopped_early: bool


@dataclass
class RunResult:
    """A finished (or stopped) protocol run: everything the report needs, nothing written yet but the units."""

    out_dir: Path
    dataset: object  # experiments.datasets.Dataset
    config: object  # experiments.protocol.ProtocolConfig
    postures: list[str]
    train_subject: str
    split_sizes: dict
    summary: RunSummary
    timing: dict = field(default_factory=dict)
    run_info: dict = field(default_factory=dict)
    pairs: dict[str, dict] = field(default_factory=dict)  # --iscv all-pairs: the other subjects' units, by key
    transfer: dict[str, dict] = field(default_factory=dict)  # --posture-transfer: the held-out postures' units

    @property
    def stopped(self) -> bool:
        return self.summary.stopped_early

    @property
    def results(self) -> dict[str, dict]:
        return self.summary.results


def is_table_unit(result: dict) -> bool:
    """Whether the unit of ``result`` is one of the run's table (not an all-pairs or posture-transfer unit)."""
    return result["unit"].get("train_subject") is None and result["unit"].get("held_out_posture") is None


def unit_paths(out_dir: Path, key: str) -> tuple[Path, Path]:
    d = Path(out_dir) / "units"
    return d / f"{key}.json", d / f"{key}.npz"


def content_checksum(res: dict) -> str:
    """SHA-256 of a unit result's JSON content without its ``checksum`` field (keys sorted, compact): it covers
    the numbers and the ``fingerprint`` of the unit's inputs, so any edit or damage shows."""
    import hashlib

    body = {k: v for k, v in res.items() if k != "checksum"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _reject_constant(name: str):
    raise ValueError(f"non-finite number {name}")


def _parse_checkpoint(path: Path) -> tuple[object, str | None]:
    """``(content, None)`` of the JSON checkpoint ``path`` (a non-finite number refused), or ``(None, what is
    wrong)``."""
    try:
        return json.loads(path.read_text(encoding="utf-8"), parse_constant=_reject_constant), None
    except (OSError, ValueError, RecursionError) as e:
        return None, f"damaged ({e})"


def read_checkpoint(path: Path, then: str):
    """The JSON content of the checkpoint ``path`` (a non-finite number refused), or ``None`` after a warning
    saying it is damaged and what happens ``then``."""
    content, problem = _parse_checkpoint(path)
    if problem is not None:
        log.warning("%s: %s; %s", path, problem, then)
    return content


def _check_unit_paths(js: Path, npz: Path) -> None:
    from ..errors import InputError

    for p in (js, npz):
        if p.exists() and not p.is_file():
            raise InputError("is not a regular file, where the unit's checkpoint goes; remove it and rerun", p)


def load_unit(out_dir: Path, key: str, fingerprint: str | None = None) -> dict | None:
    """A finished unit's result, or ``None`` (recompute it) if absent, damaged, edited (its ``checksum`` does not
    match its content), holding a non-finite number, for other inputs (other fingerprint), or if its NPZ is
    missing, damaged or not the one its JSON was written with (SHA-256); a damaged one is warned about. A folder or
    other non-file where the checkpoint goes raises :class:`~reachirl.errors.InputError` naming it."""
    res, problem = read_unit(out_dir, key, fingerprint)
    if problem is not None and not (problem[0].suffix == ".json" and problem[1] == "missing"):  # not run yet
        log.warning("%s: %s; recomputing the unit", *problem)
    return res


def read_unit(out_dir: Path, key: str, fingerprint: str | None = None) -> tuple[dict | None, tuple[Path, str] | None]:
    """``(result, None)`` for a finished unit as :func:`load_unit` reuses it; otherwise ``(None, (file, what is
    wrong))``, e.g. ``(units/<key>.json, "missing")``, or ``(None, None)`` for a unit of other inputs (another
    ``fingerprint``). Logs nothing: the caller says what follows."""
    js, npz = unit_paths(out_dir, key)
    _check_unit_paths(js, npz)
    if not js.is_file():
        return None, (js, "missing")
    res, problem = _parse_checkpoint(js)
    if problem is not None:
        return None, (js, problem)
    if not isinstance(res, dict) or res.get("key") != key:
        return None, (js, f"not a unit result of {key}")
    if fingerprint is not None and res.get("fingerprint") != fingerprint:
        return None, None
    try:
        same = res.get("checksum") == content_checksum(res)
    except (TypeError, ValueError):
        same = False
    if not same:
        return None, (js, "its content does not match its checksum (edited or damaged)")
    if res.get("has_arrays"):
        problem = _npz_problem(npz, res.get("npz_sha256"))
        if problem:
            return None, (npz, problem)
    return res, None


def _npz_problem(npz: Path, sha256: str | None) -> str | None:
    """Why a unit's NPZ cannot be reused, or ``None``."""
    import hashlib

    from ..errors import InputError
    from ..validation import check_npz_file

    if not npz.is_file():
        return "missing"
    try:
        check_npz_file(npz)
    except InputError as e:
        return e.reason
    if sha256 is not None and hashlib.sha256(npz.read_bytes()).hexdigest() != sha256:
        return "content differs from the one its JSON was written with"
    return None


def load_unit_arrays(out_dir: Path, key: str) -> dict[str, np.ndarray]:
    """A unit's predictions (``units/<key>.npz``; empty if it has none). A damaged file, or a missing one that the
    unit's JSON checkpoint says it wrote (``has_arrays``: the figures drawn from it would be left out without a
    word), is an ``InputError`` naming it: ``reproduce`` into the same folder recomputes the unit (it checks each
    checkpoint first)."""
    js, npz = unit_paths(out_dir, key)
    res, _ = _parse_checkpoint(js) if js.is_file() else (None, None)
    res = res if isinstance(res, dict) else {}
    if not npz.is_file():
        if not res.get("has_arrays"):
            return {}
        raise InputError(
            f"missing: the predictions of the run's unit {key}, which its checkpoint {js.name} says it wrote; rerun "
            f"`reachirl reproduce` into {out_dir} to recompute it",
            npz,
        )
    # another unit's predictions copied in its place were drawn under this unit's title
    problem = _npz_problem(npz, res.get("npz_sha256"))
    if problem is None:
        try:
            with np.load(npz, allow_pickle=False) as z:
                return {k: z[k] for k in z.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
            problem = f"cannot be read ({e})"
    raise InputError(f"damaged checkpoint, {problem}: rerun `reachirl reproduce` into this folder to recompute it", npz)


def save_unit(out_dir: Path, payload: dict) -> dict:
    """Write a unit's ``{"result", "arrays"}`` (NPZ first, then the JSON); returns the JSON as read back."""
    import hashlib

    res = dict(payload["result"])
    js, npz = unit_paths(out_dir, res["key"])
    _check_unit_paths(js, npz)
    res["has_arrays"] = bool(payload["arrays"])
    res = annotate_no_data(res)  # an empty split: "no_data" and its reason, never a bare null
    if payload["arrays"]:
        data = npz_bytes(dict(sorted(payload["arrays"].items())))
        res["npz_sha256"] = hashlib.sha256(data).hexdigest()  # checked before the unit is reused
        atomic_write_bytes(npz, data)
    res = to_jsonable(res)
    res["checksum"] = content_checksum(res)  # of the content as written, and of the inputs' fingerprint
    atomic_write_json(js, res)
    return json.loads(js.read_text(encoding="utf-8"))  # exactly what a resumed run would read


def check_results_file(d, path) -> None:
    """The parts of a ``results.json`` (``d``, read from ``path``) that ``plot RUN_DIR`` and ``sensitivity`` build
    on: ``data`` and ``protocol`` objects, the protocol's lists, and ``units`` a list of objects with a ``key`` and
    a ``unit`` naming its ``posture``. A damaged or hand-edited file is an :class:`InputError` naming the file and
    the field."""
    from ..validation import brief, not_real

    for key in ("data", "protocol"):
        if d.get(key) is not None and not isinstance(d[key], dict):
            raise InputError(f"field '{key}': expected an object, found {type(d[key]).__name__}", path)
    proto, units = d.get("protocol") or {}, d.get("units")

    def good_unit(u) -> bool:
        return (
            isinstance(u, dict)
            and isinstance(u.get("key"), str)
            and isinstance(u.get("unit"), dict)
            and isinstance(u["unit"].get("posture"), str)
        )

    if not (isinstance(units, list) and all(good_unit(u) for u in units)):
        bad = next((i for i, u in enumerate(units) if not good_unit(u)), None) if isinstance(units, list) else None
        where = "" if bad is None else f", unit {bad}"
        raise InputError(
            f"field 'units'{where}: expected a list of objects with a 'key' and a 'unit' with its 'posture'", path
        )
    for i, u in enumerate(units):  # the matrices plot draws: a boolean among them is no weight or share
        for key in ("weights", "cost_shares"):
            if (what := not_real(u.get(key))) is not None:
                raise InputError(f"field 'units', unit {i} ({u['key']}), '{key}': expected numbers, found {what}", path)
        _check_drawn(u, f"field 'units', unit {i} ({u['key']})", path)
    for key, kind in (("sections", int), ("methods", str), ("postures", str), ("postures_run", str)):
        v = proto.get(key)
        if v is not None and not (  # a run has at least one of each: an empty list is an edited file
            isinstance(v, list) and v and all(isinstance(x, kind) and not isinstance(x, bool) for x in v)
        ):
            what = "integers" if kind is int else "strings"
            raise InputError(f"field 'protocol.{key}': expected a non-empty list of {what}, found {brief(v)}", path)


def _check_drawn(u: dict, where: str, path) -> None:
    """The fields of a unit record that ``plot``'s figures draw as they are read (the others are read into the
    tables and the captions first, where a missing one is named): ``cost_shares`` a table of numbers with a column
    per feature, ``uncertainty.share_intervals.determined`` booleans of its shape, ``flag`` a string and
    ``history`` a list of objects whose ``iteration`` is a number; each may be null. Anything else is an
    :class:`InputError` naming the file, the unit and the field."""
    from ..features import N_FEATURES
    from ..validation import brief

    def array(v, kinds: str) -> np.ndarray | None:
        try:
            a = np.asarray(v)
        except (TypeError, ValueError):  # ragged rows
            return None
        return a if a.dtype.kind in kinds and a.ndim == 2 and a.shape[0] > 0 else None

    shares = u.get("cost_shares")
    if shares is not None and ((s := array(shares, "iuf")) is None or s.shape[1] != N_FEATURES):
        raise InputError(
            f"{where}: 'cost_shares': expected rows of {N_FEATURES} numbers (one per window), found {brief(shares)}",
            path,
        )
    if u.get("uncertainty") and shares is not None:  # its hatching
        try:
            det = u["uncertainty"]["share_intervals"]["determined"]
        except (KeyError, TypeError):
            det = None
        if (d := array(det, "b")) is None or d.shape != np.shape(shares):
            raise InputError(
                f"{where}: 'uncertainty.share_intervals.determined': expected booleans shaped as 'cost_shares' "
                f"({len(shares)} × {N_FEATURES}), found {brief(det)}",
                path,
            )
    if u.get("flag") is not None and not isinstance(u["flag"], str):
        raise InputError(f"{where}: 'flag': expected a string or null, found {brief(u['flag'])}", path)
    history = u.get("history")
    if history is not None and not (
        isinstance(history, list)
        and all(
            isinstance(h, dict)
            and (h.get("iteration") is None or type(h["iteration"]) in (int, float))  # the x axis of its merit
            for h in history
        )
    ):
        raise InputError(
            f"{where}: 'history': expected a list of objects whose 'iteration' is a number, found {brief(history)}",
            path,
        )


def protocol_config(kw: dict, path):
    """``ProtocolConfig(**kw)`` of a results file's protocol: its checks (which speak of the options that set each
    field) name the file and the field ``protocol``."""
    from .protocol import ProtocolConfig

    try:
        return ProtocolConfig(**kw)
    except (InputError, TypeError, ValueError) as e:
        reason = e.reason if isinstance(e, InputError) else str(e)
        raise InputError(f"field 'protocol': {reason}", path) from None
