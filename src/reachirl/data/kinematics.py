"""From markers to the planar arm: joint centres (markers, midpoints, or landmarks carried by their cluster's
rigid fit), the mirror of a left arm, the sagittal plane, the planar angles, the segment lengths and the
subject's arm."""

from __future__ import annotations

import logging
from collections.abc import Mapping

import numpy as np

from ..arm import DUMAS_2007, ArmModel
from ..errors import InputError
from .markersets import MarkerSet, resolve_name
from .options import PreprocessOptions
from .readers import MarkerData, SubjectInfo

__all__ = [
    "build_arm",
    "calibrate_static",
    "cast_reconstruct",
    "check_units",
    "estimate_lengths",
    "joint_positions",
    "kabsch",
    "mirror",
    "planar_ik_segments",
    "sagittal_basis",
]

log = logging.getLogger(__name__)


def kabsch(ref: np.ndarray, cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid transform with ``cur ≈ ref @ R.T + t``; ``ref``, ``cur`` are ``(..., k, 3)``.

    Returns ``R (..., 3, 3)`` (a proper rotation) and ``t (..., 3)``.
    """
    ref = np.asarray(ref, dtype=float)
    cur = np.asarray(cur, dtype=float)
    rc, cc = ref.mean(axis=-2, keepdims=True), cur.mean(axis=-2, keepdims=True)
    H = np.swapaxes(ref - rc, -1, -2) @ (cur - cc)  # (..., 3, 3)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    D = np.zeros(H.shape)
    D[..., 0, 0] = 1.0
    D[..., 1, 1] = 1.0
    D[..., 2, 2] = d
    R = np.swapaxes(Vt, -1, -2) @ D @ np.swapaxes(U, -1, -2)
    t = cc[..., 0, :] - np.einsum("...ij,...j->...i", R, rc[..., 0, :])
    return R, t


def cast_reconstruct(cluster: np.ndarray, ref_cluster: np.ndarray, ref_point: np.ndarray) -> np.ndarray:
    """Carry ``ref_point`` (static) into each frame by the rigid fit of ``cluster (n, k, 3)`` to ``ref_cluster
    (k, 3)``. Frames with fewer than 3 seen cluster markers give NaN."""
    cluster = np.asarray(cluster, dtype=float)
    n, k, _ = cluster.shape
    seen = np.all(np.isfinite(cluster), axis=2)
    out = np.full((n, 3), np.nan)
    full = seen.all(axis=1)
    if full.any():
        R, t = kabsch(np.broadcast_to(ref_cluster, (int(full.sum()), k, 3)), cluster[full])
        out[full] = np.einsum("nij,j->ni", R, ref_point) + t
    for i in np.flatnonzero(~full & (seen.sum(axis=1) >= 3)):
        R, t = kabsch(ref_cluster[seen[i]], cluster[i, seen[i]])
        out[i] = R @ ref_point + t
    return out


def _marker(md: MarkerData, name: str, role: str) -> np.ndarray:
    found = resolve_name(name, md.names)
    if found is None:
        raise InputError(
            f"marker {name!r} ({role}) not found{_near_names(name, md.names)}; name the recording's own with "
            "--markers shoulder=A,elbow=B,wrist=C,fingertip=D, or choose another --markerset",
            md.source,
        )
    return md[found]


def _cluster(md: MarkerData, names, joint: str) -> np.ndarray:
    """The markers ``names`` of ``joint``'s cluster, ``(n, k, 3)``: one the file does not hold is unseen in every
    frame (as one it holds empty), while 3 of them are there, which a rigid fit needs; otherwise the first missing
    one is not found (:func:`_marker`'s message)."""
    found = [resolve_name(m, md.names) for m in names]
    if sum(f is not None for f in found) < 3:
        missing = next(m for m, f in zip(names, found, strict=True) if f is None)
        _marker(md, missing, f"{joint} cluster")
    unseen = np.full((md.n_frames, 3), np.nan)
    return np.stack([unseen if f is None else md[f] for f in found], axis=1)


def _near_names(name: str, names) -> str:
    """What a "not found" message adds: the names that differ from ``name`` only in case (two or more, so none is
    taken), or the closest names (``difflib``) and then the file's markers, the first 12 of them."""
    import difflib

    names = list(names)
    same = [n for n in names if n.lower() == name.lower()]
    if len(same) > 1:
        return f": {', '.join(same)} differ from it only in case; rename all but one"
    by_lower = {n.lower(): n for n in names}
    close = [by_lower[n] for n in difflib.get_close_matches(name.lower(), list(by_lower), n=3, cutoff=0.6)]
    near = f"; did you mean {' or '.join(repr(n) for n in close)}?" if close else ""
    shown = ", ".join(names[:12]) + (" …" if len(names) > 12 else "")
    return f"{near} (markers: {shown})"


def calibrate_static(static: MarkerData, mset: MarkerSet) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """For each joint given by landmarks: ``(ref_cluster (k, 3), ref_point (3,))`` from the static trial, the
    mean
    over the frames where the cluster and the landmarks are all seen."""
    out = {}
    for joint, spec in mset.joints.items():
        if not spec.needs_static:
            continue
        cl = _cluster(static, spec.cluster, joint)
        lm = np.stack([_marker(static, m, f"{joint} landmark") for m in spec.landmarks], axis=1)
        ok = np.all(np.isfinite(cl), axis=(1, 2)) & np.all(np.isfinite(lm), axis=(1, 2))
        if not ok.any():
            raise InputError(
                f"no frame sees the {joint}'s cluster {list(spec.cluster)} and landmarks "
                f"{list(spec.landmarks)} together",
                static.source,
            )
        out[joint] = (cl[ok].mean(axis=0), lm[ok].mean(axis=(0, 1)))
    return out


def joint_positions(
    md: MarkerData, mset: MarkerSet, static: MarkerData | None = None
) -> dict[str, tuple[np.ndarray, str]]:
    """``{joint: ((n, 3) in metres, NaN where unseen; its label for messages)}`` for every joint of the
    (side-resolved) marker set, before gap filling."""
    calib = {}
    if mset.needs_static:
        if static is None:
            raise InputError(
                f"marker set {mset.name!r} needs a static trial (--static) to place the joint centres",
                md.source,
            )
        calib = calibrate_static(static, mset)
    out = {}
    for joint, spec in mset.joints.items():
        if spec.markers:
            if spec.optional and any(resolve_name(m, md.names) is None for m in spec.markers):
                continue
            arrs = [_marker(md, m, joint) for m in spec.markers]
            for m, a in zip(spec.markers, arrs, strict=True):
                if np.isnan(a).all():
                    raise InputError(f"marker {m!r} ({joint}) is empty in every frame", md.source)
            out[joint] = (np.mean(arrs, axis=0), "+".join(spec.markers))
        else:
            cl = _cluster(md, spec.cluster, joint)
            label = f"{joint} cluster {'/'.join(spec.cluster)} (fewer than 3 of its markers seen)"
            out[joint] = (cast_reconstruct(cl, *calib[joint]), label)
    return out


def mirror(points: Mapping[str, np.ndarray], lateral: np.ndarray) -> dict[str, np.ndarray]:
    """Reflect 3-D points across the plane normal to the unit vector ``lateral`` (left arm → right arm)."""
    lateral = np.asarray(lateral, dtype=float)
    P = np.eye(3) - 2 * np.outer(lateral, lateral)
    return {k: np.asarray(v) @ P.T for k, v in points.items()}


def sagittal_basis(
    rel: Mapping[str, np.ndarray],
    up: np.ndarray,
    displacement: np.ndarray,
    options: PreprocessOptions,
    forward: np.ndarray | None = None,
    source: object | None = None,
) -> np.ndarray:
    """``(3, 3)`` rows ``forward, up, normal`` of the sagittal plane.

    ``rel`` are the joint centres relative to the shoulder over the movement; ``up`` the lab's up;
    ``displacement`` the fingertip's onset→offset displacement (gives the forward sign).
    """
    up = up / np.linalg.norm(up)
    plane = options.plane
    if plane == "pca":
        pts = np.concatenate([np.asarray(v) for v in rel.values()], axis=0)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        _, s, Vt = np.linalg.svd(pts - pts.mean(axis=0), full_matrices=False)
        normal = Vt[2]
        up_p = up - (up @ normal) * normal
        tilt = np.degrees(np.arccos(min(1.0, np.linalg.norm(up_p))))
        if s[2] > options.pca_max_flatness * s[1] or tilt > options.pca_max_tilt_deg:
            log.info(
                "%s: principal plane ill-defined (singular values %s, %.0f° from vertical); using the "
                "vertical plane of the fingertip's path",
                source,
                np.round(s, 3),
                tilt,
            )
            plane = "vertical"
        else:
            up_p /= np.linalg.norm(up_p)
            fwd = np.cross(up_p, normal)
    if plane == "vertical":
        up_p = up
        fpath = np.asarray(rel["fingertip"])
        h = fpath - np.outer(fpath @ up, up)
        h = h[np.all(np.isfinite(h), axis=1)]
        _, _, Vt = np.linalg.svd(h - h.mean(axis=0), full_matrices=False)
        fwd = Vt[0] - (Vt[0] @ up) * up
        fwd /= np.linalg.norm(fwd)
    elif plane == "axes":
        up_p = up
        if forward is None:
            h = displacement - (displacement @ up) * up
            k = int(np.argmax(np.abs(h)))
            fwd = np.zeros(3)
            fwd[k] = 1.0
        else:
            fwd = forward - (forward @ up) * up
            if np.linalg.norm(fwd) < 0.5:  # ±x, ±y, ±z: the same axis as up, or its opposite
                raise InputError(
                    "--forward-axis is the up axis (or its opposite); with --plane axes it must be "
                    "a horizontal lab axis, e.g. --up-axis +y --forward-axis +x",
                    source,
                )
        fwd /= np.linalg.norm(fwd)
        along, across = abs(float(displacement @ fwd)), abs(float(displacement @ np.cross(fwd, up_p)))
        if across > along:  # the reach runs across the plane more than along it: the forward axis is the lateral
            raise InputError(
                f"the fingertip moves {across * 1000:.0f} mm across the plane of the up and forward axes (--plane "
                f"axes) and {along * 1000:.0f} mm along its forward axis, from onset to offset: is the forward axis "
                "the lab's lateral one? (check --forward-axis and --up-axis, or use --plane pca)",
                source,
            )
    if fwd @ displacement < 0:
        fwd = -fwd
    normal = np.cross(fwd, up_p)
    return np.stack([fwd, up_p, normal])


def planar_ik_segments(elbow: np.ndarray, distal: np.ndarray) -> np.ndarray:
    """``q (n, 2)`` from planar shoulder→elbow and elbow→distal vectors (shoulder at the origin).

    q1 = atan2 of the upper arm, q2 = the distal segment's angle minus q1 (both unwrapped over time, q2
    wrapped to (-π, π] at the first frame).
    """
    a1 = np.unwrap(np.arctan2(elbow[:, 1], elbow[:, 0]))
    seg = distal - elbow
    a2 = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
    q2 = a2 - a1
    q2 -= 2 * np.pi * np.round(q2[0] / (2 * np.pi))
    return np.stack([a1, q2], axis=1)


def estimate_lengths(joints: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Median 3-D distances: ``upper_arm`` (shoulder→elbow), ``forearm`` (elbow→wrist), ``elbow_fingertip``,
    ``hand`` (wrist→fingertip), ``reach`` (shoulder→fingertip), with their SDs under ``<name>_sd``, over the frames
    where both joints are seen (not NaN); a pair never seen together is left out."""
    pairs = {
        "upper_arm": ("shoulder", "elbow"),
        "forearm": ("elbow", "wrist"),
        "elbow_fingertip": ("elbow", "fingertip"),
        "hand": ("wrist", "fingertip"),
        "reach": ("shoulder", "fingertip"),
    }
    out = {}
    for name, (a, b) in pairs.items():
        if a in joints and b in joints:
            d = np.linalg.norm(joints[b] - joints[a], axis=1)
            d = d[np.isfinite(d)]
            if d.size == 0:  # never seen together (gaps longer than --max-gap on alternate sides): not measured
                continue
            out[name] = float(np.median(d))
            out[f"{name}_sd"] = float(np.std(d))
    return out


#: the unit mistake a length off by a power of ten points to (the factor that brings it to an arm's size)
_UNIT_MISTAKES = {
    3: "metres declared as mm?",
    2: "metres declared as cm?",
    1: "centimetres declared as mm?",
    -1: "millimetres declared as cm?",
    -2: "centimetres declared as metres?",
    -3: "millimetres declared as metres?",
}


def check_units(lengths: Mapping[str, float], options: PreprocessOptions, source: object) -> None:
    lo, hi = options.segment_range_m
    for name in ("upper_arm", "forearm", "reach", "elbow_fingertip"):
        if name not in lengths:
            continue
        v = lengths[name]
        if lo <= v <= hi:
            continue
        factor = round(float(np.log10(np.sqrt(lo * hi) / v))) if v > 0 else None
        why = _UNIT_MISTAKES.get(factor, "the file's units?")
        size = f"{v * 1000:.3g} mm, absurdly small" if v < lo else f"{v:.3g} m, absurdly large"
        raise InputError(
            f"units look wrong: the median {name.replace('_', ' ')} distance is {size} for an arm ({why})", source
        )


def build_arm(info: SubjectInfo, side: str, measured: Mapping[str, float] | None = None) -> ArmModel:
    """The subject's arm: sex, height, mass from ``info``; lengths from ``info`` when given, else ``measured``
    (``upper_arm``, ``forearm``, ``elbow_fingertip``), else Dumas' means scaled by height."""
    measured = measured or {}
    ua, fa, hand = info.lengths(side)
    ua = ua if ua is not None else measured.get("upper_arm")
    if fa is None and hand is None and "elbow_fingertip" in measured:
        l2 = measured["elbow_fingertip"]
        if "forearm" in measured and measured["forearm"] < l2 - 0.02:
            fa = measured["forearm"]
        else:  # split elbow→fingertip by Dumas' forearm:hand ratio
            t = DUMAS_2007[info.sex]
            fa = l2 * t["forearm"][3] / (t["forearm"][3] + t["hand"][3])
        hand = l2 - fa
    elif fa is None:
        fa = measured.get("forearm")
    try:
        return ArmModel.from_anthropometrics(
            info.height_m, info.mass_kg, info.sex, upper_arm_m=ua, forearm_m=fa, hand_m=hand
        )
    except ValueError as e:
        raise InputError(f"cannot build subject {info.subject}'s arm: {e}") from None
