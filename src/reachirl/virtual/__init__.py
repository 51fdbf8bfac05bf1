"""Virtual subjects on Berret et al. 2011's protocol, with known (ground-truth) time-varying cost weights.

A virtual subject is an :class:`~reachirl.arm.ArmModel` drawn from Berret's population. Each of its reaches
is the DOC solution (:func:`reachirl.solve_doc`) of the reach from one of Berret's five initial postures to
a vertical bar, under the subject's true weights jittered for that trial. The reaches are then "recorded":
markers at 100 Hz placed by the arm's kinematics, in a lab frame, with noise and rest before and after, and
written as TRC, C3D or MOT files with a manifest, a subject-info CSV and ``truth.json``.

**Population** (Berret et al. 2011, PLoS Comput Biol 7(10) e1002183): height 1.76 ± 0.06 m, mass 69.9 ± 8.4 kg,
16 of 20 male. Each subject is male with probability 0.8; height and mass are drawn around sex-specific means
chosen so that the mixture has Berret's mean (men +2 cm / +2.1 kg, women −8 cm / −8.4 kg, within-sex SD 5 cm /
7.5 kg, clipped at ±2.5 SD). Segment lengths are Dumas 2007's mean lengths scaled by height over the table's
reference stature, each times ``exp(N(0, 0.03))`` (about 3 % individual variation).

**Initial postures.** Berret gives them as ``[elbow; shoulder]`` in degrees: P1 [0; 90], P2 [−90; 90], P3
[−120; 120], P4 [−90; 30], P5 [−80; 140]. We read both angles as measured from the *forward horizontal* in a
frame seen from the subject's other side (clockwise in reachirl's x-forward/y-up frame), so ``q1 =
−shoulder`` and ``q2 = −elbow``: a negative Berret elbow angle is then flexion, and 90° at the shoulder is
the arm hanging down. This is the only simple reading under which all five are sensible starts for a reach
to a bar at 85–95 % of arm length (see :func:`berret_to_model` and ``docs/figures/berret_postures.png``):

* P1 arm hanging straight down; P2 upper arm down, forearm horizontal forward (the classic 90° elbow); P3
  upper arm 30° behind the vertical, forearm horizontal forward; P4 upper arm 30° below the horizontal
  forward, forearm 60° above it; P5 upper arm 50° behind the vertical, forearm pointing down-forward (hand
  beside the hip).
* Every fingertip starts short of the bar (x ≤ 0.5 m against a bar at ≥ 0.6 m).
* The other common reading (shoulder from the downward vertical) makes P1 a straight horizontal
  arm with the fingertip at x = L, beyond the bar (physically through it), which cannot be a start posture.
* It matches the seed paper's remark that P3 and P5 need "more activity in joint space" for a small
  fingertip motion: they are the two postures with the upper arm behind the trunk.

**Ground-truth weights** (8 windows): ``ω_{s,j} = RELATIVE_IMPORTANCE[s, j] / FEATURE_SCALE[j]``.
``FEATURE_SCALE`` is the typical size of each feature per window (its mean over windows and postures on
reference reaches; see :func:`typical_feature_scales`), so ``RELATIVE_IMPORTANCE`` says how much each cost
matters in each window on a common footing. In the spirit of the seed's findings, joint acceleration
dominates the first and the last windows and energy, torque change, torque and geodesic matter mid-movement;
the deceleration phase is smoother than the acceleration phase, which moves the peak speed earlier (Berret:
0.42 of the movement).

**Trial-to-trial variability:** each weight times ``exp(N(0, 0.2))``, initial joint angles + ``N(0, 3°)``,
duration from Berret's mean ± SD per posture. A trial whose DOC fails is redrawn (and counted).

**Recording:** the DOC horizon is ``duration / 0.92`` so the 5 %-of-peak-speed movement time matches
Berret's duration. Markers ``SHO`` (acromion, the shoulder centre), ``ELB`` (elbow), ``WRI`` (wrist centre:
the forearm length along segment 2) and ``FTP`` (fingertip) at 100 Hz, in a lab frame with Z up (as Vicon)
and the movement plane rotated 2–5° about Z; the shoulder sits at a per-subject lab position (± a few mm per
trial). Gaussian noise of 1–2 mm SD (per subject) on every coordinate; 0.3–0.6 s of still posture before and
after the reach. C3D files keep the lab axes (Z up); TRC files use OpenSim's axes (Y up:
``(X, Y, Z)_trc = (X, Z, −Y)_lab``), so each format follows its own standard. MOT files hold ``q1``, ``q2`` in
degrees (reachirl's convention) with 0.2° noise. The preprocess command reads the markers with
``--markers shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP``.

Randomness: every draw derives from ``numpy.random.SeedSequence(seed, spawn_key=...)`` keyed by (subject) or
(subject, posture, trial), so files do not depend on how trials are scheduled over processes.

The modules: :mod:`.population` (subjects, postures, true weights), :mod:`.recording` (one reach solved and
recorded), :mod:`.likeness` (human-likeness measures), :mod:`.files` (the data set on disk and the cached built-in
data set) and :mod:`.plots` (the posture figure).
"""

from ..io import cache_root
from .files import GENERATOR_VERSION, SynthResult, builtin_dataset_dir, generate
from .likeness import (
    BERRET_HUMAN_LIKENESS,
    format_human_likeness,
    human_likeness,
    reach_metrics,
    typical_feature_scales,
)
from .plots import plot_postures
from .population import (
    BERRET_DURATIONS_S,
    BERRET_POSTURES_DEG,
    FEATURE_SCALE,
    MOVEMENT_FRACTION,
    N_WINDOWS,
    POSTURES,
    RELATIVE_IMPORTANCE,
    SynthSubject,
    berret_to_model,
    draw_subject,
    nominal_weights,
    posture_q,
)
from .recording import (
    FORMATS,
    MARKERS,
    SynthConfig,
    SynthTrial,
    knot_trials,
    one_cost_trials,
    simulate_trial,
    to_opensim_axes,
)

__all__ = [
    "BERRET_DURATIONS_S",
    "BERRET_HUMAN_LIKENESS",
    "BERRET_POSTURES_DEG",
    "FEATURE_SCALE",
    "FORMATS",
    "GENERATOR_VERSION",
    "MARKERS",
    "MOVEMENT_FRACTION",
    "N_WINDOWS",
    "POSTURES",
    "RELATIVE_IMPORTANCE",
    "SynthConfig",
    "SynthResult",
    "SynthSubject",
    "SynthTrial",
    "berret_to_model",
    "builtin_dataset_dir",
    "cache_root",
    "draw_subject",
    "format_human_likeness",
    "generate",
    "human_likeness",
    "knot_trials",
    "nominal_weights",
    "one_cost_trials",
    "plot_postures",
    "posture_q",
    "reach_metrics",
    "simulate_trial",
    "to_opensim_axes",
    "typical_feature_scales",
]
