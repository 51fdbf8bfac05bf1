"""How human the virtual reaches are: Berret's fingertip measures, and the typical feature scales."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..arm import ArmModel
from ..doc import ReachingTask, solve_doc
from ..features import FEATURES, feature_rates, window_index
from .population import BERRET_DURATIONS_S, MOVEMENT_FRACTION, N_WINDOWS, POSTURES, SynthSubject, posture_q
from .recording import SynthTrial, _reach_spline

BERRET_HUMAN_LIKENESS = {"peak_to_mean_speed": 1.97, "time_to_peak": 0.42}


def _reach_kinematics(arm: ArmModel, t_knots, q_knots, rate: float = 1000.0):
    spline = _reach_spline(t_knots, q_knots)
    t = np.arange(0.0, t_knots[-1], 1.0 / rate)
    q, qd = spline(t), spline(t, 1)
    p = arm.fk(q)
    v = arm.fingertip_speed(q, qd)
    return t, p, v


def reach_metrics(arm: ArmModel, t_knots: np.ndarray, q_knots: np.ndarray, threshold: float = 0.05) -> dict:
    """Berret's fingertip measures of one reach, between the crossings of ``threshold`` × peak speed.

    Returns ``duration_s``, ``peak_to_mean_speed``, ``time_to_peak`` (fraction of the movement),
    ``path_length_m``, ``peak_speed_m_s`` and ``straightness`` (path length / straight-line distance).
    """
    t, p, v = _reach_kinematics(arm, t_knots, q_knots)
    k_peak = int(np.argmax(v))
    above = v >= threshold * v[k_peak]
    on = k_peak - int(np.argmin(above[k_peak::-1])) + 1 if not above[: k_peak + 1].all() else 0
    off = k_peak + int(np.argmin(above[k_peak:])) - 1 if not above[k_peak:].all() else len(v) - 1
    dt = t[1] - t[0]
    seg = v[on : off + 1]
    path = float(np.trapezoid(seg, dx=dt))
    duration = (off - on) * dt
    chord = float(np.linalg.norm(p[off] - p[on]))
    return {
        "duration_s": duration,
        "peak_to_mean_speed": float(v[k_peak] / (path / duration)),
        "time_to_peak": (k_peak - on) * dt / duration,
        "path_length_m": path,
        "peak_speed_m_s": float(v[k_peak]),
        "straightness": path / chord if chord > 0 else float("nan"),
    }


def human_likeness(trials: Sequence[SynthTrial], subjects: Sequence[SynthSubject]) -> list[dict]:
    """Per-posture fingertip measures (mean and SD over trials) next to Berret's, plus an ``ALL`` row.

    Measures (:func:`reach_metrics`): movement duration, peak/mean speed (Berret 1.97), relative time to peak
    speed (Berret 0.42), path length and straightness. Berret's per-posture durations are in
    ``berret_duration_s``.
    """
    arms = {s.subject: s.arm for s in subjects}
    per: dict[str, list[dict]] = {}
    for tr in trials:
        per.setdefault(tr.posture, []).append(reach_metrics(arms[tr.subject], tr.t_knots, tr.q_knots))
    rows = []
    for posture in [*sorted(per), "ALL"]:
        ms = [m for p in sorted(per) for m in per[p]] if posture == "ALL" else per[posture]
        row: dict = {"posture": posture, "n": len(ms)}
        for key in ("duration_s", "peak_to_mean_speed", "time_to_peak", "path_length_m", "straightness"):
            vals = np.array([m[key] for m in ms])
            row[key] = float(vals.mean())
            row[key + "_sd"] = float(vals.std(ddof=1)) if len(vals) > 1 else 0.0
        if posture in BERRET_DURATIONS_S:
            row["berret_duration_s"] = BERRET_DURATIONS_S[posture][0]
        else:
            row["berret_duration_s"] = float(np.mean([BERRET_DURATIONS_S[p][0] for p in sorted(per)]))
        row["berret_peak_to_mean_speed"] = BERRET_HUMAN_LIKENESS["peak_to_mean_speed"]
        row["berret_time_to_peak"] = BERRET_HUMAN_LIKENESS["time_to_peak"]
        rows.append(row)
    return rows


def format_human_likeness(rows: Sequence[dict]) -> tuple[list[str], list[list[str]]]:
    """Header and cells of the compact human-likeness table (``mean±SD``, Berret's value in brackets)."""
    header = [
        "posture",
        "n",
        "duration s [Berret]",
        "peak/mean [1.97]",
        "t_peak [0.42]",
        "path m",
        "path/chord",
    ]
    cells = []
    for r in rows:
        cells.append(
            [
                str(r["posture"]),
                str(r["n"]),
                f"{r['duration_s']:.3f}±{r['duration_s_sd']:.3f} [{r['berret_duration_s']:.2f}]",
                f"{r['peak_to_mean_speed']:.2f}±{r['peak_to_mean_speed_sd']:.2f}",
                f"{r['time_to_peak']:.3f}±{r['time_to_peak_sd']:.3f}",
                f"{r['path_length_m']:.3f}±{r['path_length_m_sd']:.3f}",
                f"{r['straightness']:.3f}±{r['straightness_sd']:.3f}",
            ]
        )
    return header, cells


# ---------------------------------------------------------------------- feature scales (documentation)
def typical_feature_scales(n_nodes: int = 100) -> np.ndarray:
    """Mean Φ per window and feature over the five postures' reaches of the reference arm under pure
    joint-acceleration weights (the origin of :data:`FEATURE_SCALE`), shape ``(7,)``.

    The torque change of the onset interval (the jump from the gravity torque at rest) is left out: a reach
    under pure joint-acceleration weights starts at full acceleration, so that one jump (×28 the rest of the
    reach) says how little this reference penalises it, not how large torque changes typically are."""
    arm = ArmModel.from_anthropometrics(1.76, 69.9, "M")
    w = np.zeros((N_WINDOWS, len(FEATURES)))
    w[:, FEATURES.index("joint_acceleration")] = 1.0
    out = []
    for p in POSTURES:
        task = ReachingTask(
            arm,
            posture_q(p),
            0.95 * arm.length,
            BERRET_DURATIONS_S[p][0] / MOVEMENT_FRACTION,
            n_nodes=n_nodes,
        )
        sol = solve_doc(task, w)
        rates = feature_rates(arm, sol.q, sol.qd, sol.tau, task.dt)
        rates[0, FEATURES.index("torque_change")] = 0.0
        phi = np.zeros((N_WINDOWS, len(FEATURES)))
        np.add.at(phi, window_index(task.n_nodes, N_WINDOWS), rates * task.dt)
        out.append(phi.mean(axis=0))
    return np.mean(out, axis=0)
