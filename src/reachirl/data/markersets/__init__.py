"""Marker sets: which markers give the shoulder, elbow, wrist and fingertip.

A joint is either

* ``markers``: the midpoint of markers recorded in the trial itself (one marker: the marker), or
* ``landmarks`` + ``cluster``: the midpoint of anatomical landmarks recorded only in a **static** trial,
  carried into each frame of the reach by a least-squares rigid fit of a marker cluster (the calibrated
  anatomical system technique, see :func:`reachirl.data.kinematics.cast_reconstruct`).

Presets are the JSON files of this folder (``default``, ``ue-adl``); ``{S}`` in a name is the side prefix
(``R``/``L`` for UE-ADL). :func:`parse_marker_map` builds a set from
``shoulder=A,elbow=B,wrist=C,fingertip=D`` (``B+C`` for a midpoint).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from ...errors import InputError

__all__ = [
    "JOINTS",
    "JointSpec",
    "MarkerSet",
    "available",
    "lab_axis",
    "load_markerset",
    "parse_marker_map",
    "resolve_name",
]

JOINTS = ("shoulder", "elbow", "wrist", "fingertip")
_REQUIRED = ("shoulder", "fingertip")


@dataclass(frozen=True)
class JointSpec:
    markers: tuple[str, ...] = ()
    landmarks: tuple[str, ...] = ()
    cluster: tuple[str, ...] = ()
    optional: bool = False

    @property
    def needs_static(self) -> bool:
        return bool(self.landmarks)


@dataclass(frozen=True)
class MarkerSet:
    """``joints`` maps some of :data:`JOINTS` to a :class:`JointSpec`; names may contain ``{S}``."""

    name: str
    joints: Mapping[str, JointSpec]
    side_prefix: Mapping[str, str] = field(default_factory=lambda: {"right": "", "left": ""})
    static: str | None = None  # file name pattern of the static trial beside a reach, e.g. "{subject}_static.csv"
    up: str | None = None
    description: str = ""

    def __post_init__(self) -> None:
        for j in self.joints:
            if j not in JOINTS:
                raise InputError(f"marker set {self.name!r}: unknown joint {j!r}, expected one of {JOINTS}")
        for j in _REQUIRED:
            if j not in self.joints:
                raise InputError(f"marker set {self.name!r} lacks the {j} (required: shoulder and fingertip)")
        for j, s in self.joints.items():
            if bool(s.markers) == bool(s.landmarks):
                raise InputError(f"marker set {self.name!r}: {j} needs either markers or landmarks+cluster")
            if s.landmarks and len(s.cluster) < 3:
                raise InputError(f"marker set {self.name!r}: {j}'s cluster needs at least 3 markers")

    @property
    def needs_static(self) -> bool:
        return any(s.needs_static for s in self.joints.values())

    def for_side(self, side: str) -> MarkerSet:
        """The set with ``{S}`` replaced by the side's prefix."""
        pre = self.side_prefix.get(side, "")

        def sub(names: Iterable[str]) -> tuple[str, ...]:
            return tuple(n.replace("{S}", pre) for n in names)

        joints = {
            j: JointSpec(sub(s.markers), sub(s.landmarks), sub(s.cluster), s.optional) for j, s in self.joints.items()
        }
        return MarkerSet(self.name, joints, {"right": pre, "left": pre}, self.static, self.up, self.description)


def resolve_name(name: str, available_names: Iterable[str]) -> str | None:
    """``name`` if present, else its unique case-insensitive match, else ``None``."""
    names = list(available_names)
    if name in names:
        return name
    low = [n for n in names if n.lower() == name.lower()]
    return low[0] if len(low) == 1 else None


def lab_axis(spec: str) -> np.ndarray:
    """The unit vector of a lab axis ``±x``, ``±y`` or ``±z`` (a marker set's ``up``, ``--up-axis``)."""
    s = spec.strip().lower()
    sign = -1.0 if s.startswith("-") else 1.0
    key = s.lstrip("+-")
    if key not in ("x", "y", "z"):
        raise InputError(f"axis must be one of ±x, ±y, ±z, got {spec!r}")
    v = np.zeros(3)
    v["xyz".index(key)] = sign
    return v


def _names(value, where: str, origin: str) -> tuple[str, ...]:
    """A marker set's list of marker names at ``where``, each a non-empty string."""
    if not (isinstance(value, list) and all(isinstance(n, str) and n.strip() for n in value)):
        raise InputError(f"marker set: {where} must be a list of marker names, found {_brief(value)}", origin)
    return tuple(value)


def _brief(value) -> str:
    text = json.dumps(value) if not isinstance(value, str) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _from_dict(d: Mapping, origin: str) -> MarkerSet:
    """A :class:`MarkerSet` from the parsed JSON ``d`` of ``origin``, each field checked: any problem is an
    :class:`InputError` naming ``origin`` and the field."""
    if not isinstance(d, dict):
        raise InputError(f"marker set: expected a JSON object, found {type(d).__name__}", origin)
    if not isinstance(d.get("joints"), dict):
        raise InputError(f"marker set: 'joints' must be an object of joints, found {_brief(d.get('joints'))}", origin)
    joints = {}
    for j, s in d["joints"].items():
        if not isinstance(s, dict):
            raise InputError(f"marker set: joint {j!r} must be an object, found {_brief(s)}", origin)
        unknown = set(s) - {"markers", "landmarks", "cluster", "optional"}
        if unknown:
            raise InputError(
                f"marker set: joint {j!r} has unknown key(s) {', '.join(sorted(unknown))} (expected markers, "
                "landmarks, cluster, optional)",
                origin,
            )
        optional = s.get("optional", False)
        if not isinstance(optional, bool):
            raise InputError(f"marker set: joints.{j}.optional must be true or false, found {_brief(optional)}", origin)
        joints[j] = JointSpec(
            **{k: _names(s[k], f"joints.{j}.{k}", origin) for k in ("markers", "landmarks", "cluster") if k in s},
            optional=optional,
        )
    prefix = d.get("side_prefix", {"right": "", "left": ""})
    if not (isinstance(prefix, dict) and all(k in ("right", "left") and isinstance(v, str) for k, v in prefix.items())):
        raise InputError(
            f"marker set: 'side_prefix' must map right and left to strings, found {_brief(prefix)}", origin
        )
    for key in ("name", "description", "static", "up"):
        if d.get(key) is not None and not isinstance(d[key], str):
            raise InputError(f"marker set: '{key}' must be a string, found {_brief(d[key])}", origin)
    up = d.get("up")
    if up is not None:
        try:
            lab_axis(up)
        except InputError:
            raise InputError(f"marker set: 'up' must be one of ±x, ±y, ±z, found {up!r}", origin) from None
    static = d.get("static")
    if static is not None:
        try:
            static.format(subject="S")
        except (KeyError, IndexError, ValueError):
            raise InputError(
                f"marker set: 'static' may hold only {{subject}} as a placeholder, found {static!r}", origin
            ) from None
    try:
        return MarkerSet(
            name=d.get("name") or origin,
            joints=joints,
            side_prefix=dict(prefix),
            static=static,
            up=up,
            description=d.get("description") or "",
        )
    except InputError as e:  # the set's own checks (joints, clusters) name the set; name its file too
        raise InputError(e.reason, origin) from None


def available() -> tuple[str, ...]:
    """Names of the built-in presets."""
    return tuple(sorted(p.name[:-5] for p in resources.files(__name__).iterdir() if p.name.endswith(".json")))


def load_markerset(name_or_file: str | Path) -> MarkerSet:
    """A built-in preset by name (``ue-adl``, ``default``) or a JSON file of the same layout."""
    s = str(name_or_file)
    if s in available():
        text = resources.files(__name__).joinpath(f"{s}.json").read_text(encoding="utf-8")
        return _from_dict(json.loads(text), s)
    path = Path(s)
    if not path.exists():
        raise InputError(f"no such marker set (presets: {', '.join(available())}; or give a JSON file)", s)
    from ...io import read_json

    return _from_dict(read_json(path), str(path))


def parse_marker_map(text: str) -> MarkerSet:
    """``"shoulder=A,elbow=B,wrist=C,fingertip=D"`` → a :class:`MarkerSet` (``B1+B2`` for a midpoint)."""
    joints = {}
    for part in text.split(","):
        if not part.strip():
            continue
        if "=" not in part:
            raise InputError(f"--markers: {part.strip()!r} should be joint=MARKER (joints: {', '.join(JOINTS)})")
        j, names = (x.strip() for x in part.split("=", 1))
        if j not in JOINTS:
            raise InputError(f"--markers: unknown joint {j!r}, expected one of {', '.join(JOINTS)}")
        ms = tuple(n.strip() for n in names.split("+") if n.strip())
        if not ms:
            raise InputError(f"--markers: no marker named for {j}")
        joints[j] = JointSpec(markers=ms)
    missing = [j for j in _REQUIRED if j not in joints]
    if missing:
        raise InputError(
            f"--markers lacks the {' and the '.join(missing)}: give joint=MARKER for at least the shoulder and the "
            f"fingertip (shoulder=A,elbow=B,wrist=C,fingertip=D)"
        )
    return MarkerSet(name="custom", joints=joints)
