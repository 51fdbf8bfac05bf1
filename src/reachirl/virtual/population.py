"""The virtual population: Berret et al. 2011's subjects, initial postures and durations, and the ground-truth
weights (the whole design is described in :mod:`reachirl.virtual`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arm import _REFERENCE_HEIGHT_M, DUMAS_2007, ArmModel

POSTURES = ("P1", "P2", "P3", "P4", "P5")
# Berret 2011: initial postures as (elbow, shoulder) in degrees, and movement durations (mean, SD) in seconds.
BERRET_POSTURES_DEG: dict[str, tuple[float, float]] = {
    "P1": (0.0, 90.0),
    "P2": (-90.0, 90.0),
    "P3": (-120.0, 120.0),
    "P4": (-90.0, 30.0),
    "P5": (-80.0, 140.0),
}
BERRET_DURATIONS_S: dict[str, tuple[float, float]] = {
    "P1": (0.71, 0.08),
    "P2": (0.71, 0.08),
    "P3": (0.78, 0.08),
    "P4": (0.74, 0.09),
    "P5": (0.70, 0.07),
}
N_WINDOWS = 8
# 5 %-of-peak-speed movement time / DOC horizon, measured on the nominal reaches (see human_likeness).
MOVEMENT_FRACTION = 0.92

# Relative importance of each cost per window (rows: 8 equal windows of the reach; columns: FEATURES order).
RELATIVE_IMPORTANCE = np.array(
    [
        # cart_vel energy geodesic joint_acc torque_chg joint_vel torque
        [0.0, 0.000, 0.00, 1.000, 0.000, 0.0, 0.000],
        [0.0, 0.010, 0.00, 0.200, 0.005, 0.0, 0.005],
        [0.0, 0.025, 0.00, 0.050, 0.015, 0.0, 0.010],
        [0.0, 0.025, 0.15, 0.025, 0.015, 0.0, 0.010],
        [0.0, 0.025, 0.30, 0.025, 0.015, 0.0, 0.010],
        [0.0, 0.025, 0.60, 0.050, 0.015, 0.0, 0.010],
        [0.0, 0.010, 0.30, 0.200, 0.005, 0.0, 0.005],
        [0.0, 0.000, 0.00, 1.000, 0.000, 0.0, 0.000],
    ]
)
# Typical Φ per window and feature (SI units of FEATURE_UNITS), from typical_feature_scales() on the reference
# arm (1.76 m, 69.9 kg, male) under pure joint-acceleration weights, rounded to 2 significant digits.
FEATURE_SCALE = np.array([0.079, 0.45, 0.074, 7.0, 5.4, 0.48, 3.6])

_LOG_WEIGHT_SD = 0.2
_POSTURE_SD_DEG = 3.0
_MAX_RETRIES = 10


def nominal_weights(relative_importance: np.ndarray | None = None) -> np.ndarray:
    """The nominal true weights, shape ``(windows, 7)``: ``relative_importance / FEATURE_SCALE``, by default
    :data:`RELATIVE_IMPORTANCE` (8 windows, the paper's pattern)."""
    ri = RELATIVE_IMPORTANCE if relative_importance is None else np.asarray(relative_importance, dtype=float)
    return ri / FEATURE_SCALE[None, :]


def berret_to_model(elbow_deg: float, shoulder_deg: float) -> np.ndarray:
    """Berret's ``[elbow; shoulder]`` posture (degrees) to reachirl's ``(q1, q2)`` in radians.

    Both of Berret's angles are read as measured from the forward horizontal, clockwise in reachirl's frame:
    ``q1 = −shoulder``, ``q2 = −elbow`` (so 90° at the shoulder hangs down and a negative elbow is flexion).
    """
    return np.deg2rad([-float(shoulder_deg), -float(elbow_deg)])


def posture_q(posture: str) -> np.ndarray:
    if posture not in BERRET_POSTURES_DEG:
        raise ValueError(f"unknown posture {posture!r}; expected one of {POSTURES}")
    return berret_to_model(*BERRET_POSTURES_DEG[posture])


@dataclass(frozen=True)
class SynthSubject:
    """A virtual subject: anthropometrics and how its recordings sit in the lab."""

    subject: str
    sex: str
    height_m: float
    mass_kg: float
    upper_arm_m: float
    forearm_m: float
    hand_m: float
    lab_origin_mm: tuple[float, float, float]  # the shoulder's mean lab position
    plane_rotation_deg: float  # movement plane's rotation about the lab's vertical Z
    noise_mm: float  # marker noise SD

    @property
    def arm(self) -> ArmModel:
        return ArmModel.from_anthropometrics(
            self.height_m, self.mass_kg, self.sex, self.upper_arm_m, self.forearm_m, self.hand_m
        )


def _rng(seed: int, *key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=tuple(int(k) for k in key)))


def _clipped_normal(rng: np.random.Generator, mean: float, sd: float, k: float = 2.5) -> float:
    return float(mean + sd * np.clip(rng.standard_normal(), -k, k))


def draw_subject(seed: int, index: int) -> SynthSubject:
    """Subject ``index`` (0-based) of the population of ``seed``; ids are ``S01``, ``S02``, …"""
    rng = _rng(seed, 0, index)
    sex = "M" if rng.random() < 0.8 else "F"
    dh, dm = (0.02, 2.1) if sex == "M" else (-0.08, -8.4)
    height = _clipped_normal(rng, 1.76 + dh, 0.05)
    mass = _clipped_normal(rng, 69.9 + dm, 7.5)
    scale = height / _REFERENCE_HEIGHT_M[sex]
    lengths = [
        DUMAS_2007[sex][seg][3] * scale * float(np.exp(0.03 * rng.standard_normal()))
        for seg in ("upper_arm", "forearm", "hand")
    ]
    origin = (
        300.0 + 20 * rng.standard_normal(),
        600.0 + 20 * rng.standard_normal(),
        1050.0 + 30 * rng.standard_normal(),
    )
    rotation = float(rng.choice([-1.0, 1.0]) * rng.uniform(2.0, 5.0))
    noise = float(rng.uniform(1.0, 2.0))
    return SynthSubject(
        subject=f"S{index + 1:02d}",
        sex=sex,
        height_m=round(height, 4),
        mass_kg=round(mass, 2),
        upper_arm_m=round(lengths[0], 4),
        forearm_m=round(lengths[1], 4),
        hand_m=round(lengths[2], 4),
        lab_origin_mm=tuple(round(v, 2) for v in origin),
        plane_rotation_deg=round(rotation, 3),
        noise_mm=round(noise, 3),
    )


def _draw_trial_inputs(rng: np.random.Generator, posture: str, nominal: np.ndarray):
    w = nominal * np.exp(_LOG_WEIGHT_SD * rng.standard_normal(nominal.shape))
    q0 = posture_q(posture) + np.deg2rad(_POSTURE_SD_DEG) * np.clip(rng.standard_normal(2), -2.5, 2.5)
    mean, sd = BERRET_DURATIONS_S[posture]
    duration = _clipped_normal(rng, mean, sd)
    return w, q0, duration
