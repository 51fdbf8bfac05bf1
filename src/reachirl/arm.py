"""The planar two-link arm: shoulder q1, elbow q2, in the sagittal plane.

Convention (SI units, radians):

* x forward, y up, shoulder at the origin, gravity along -y.
* q1 is the upper arm's angle from +x, counter-clockwise positive (-pi/2 hangs down).
* q2 is the elbow angle relative to the upper arm, 0 straight, positive in flexion.
* Segment 2 is the forearm with the hand lumped on (the wrist is frozen); its tip, the
  fingertip, is ``l2`` from the elbow.

Dynamics are the textbook closed form ``tau = M(q) qdd + b(q, qd) + g(q)``; :meth:`ArmModel.pinocchio_model`
builds the same arm in Pinocchio, and the tests check the two agree to 1e-9.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .validation import brief, number

__all__ = ["DEFAULT_QD_MAX", "DEFAULT_Q_LOWER", "DEFAULT_Q_UPPER", "DUMAS_2007", "ArmModel", "sex_key"]

#: the joints' range of motion (rad), (q1, q2): the shoulder from full extension behind the body to well overhead
#: (-150° to 120°), the elbow from slight hyper-extension to full flexion (-5° to 160°). A reach's default joint
#: limits (:class:`reachirl.doc.task.ReachingTask`) and the range a recorded start must lie in.
DEFAULT_Q_LOWER = (np.deg2rad(-150.0), np.deg2rad(-5.0))
DEFAULT_Q_UPPER = (np.deg2rad(120.0), np.deg2rad(160.0))
#: a reach's default bound on each joint's speed (rad/s), (q1, q2)
DEFAULT_QD_MAX = (10.0, 10.0)

# Dumas, Cheze & Verriest 2007, J Biomech 40:543-553: (mass % of body mass, CoM % of length from the proximal
# joint along the segment, radius of gyration about the CoM r_zz % of length (z: the medio-lateral axis, about
# which sagittal flexion turns) and mean segment length (m). Segment definitions:
# * upper arm: glenohumeral (shoulder) joint centre → elbow joint centre;
# * forearm: elbow joint centre → wrist joint centre;
# * hand: wrist joint centre → tip of the 3rd finger. Dumas' primary hand length ends at the midpoint of the 2nd
#   and 5th metacarpal heads (M 80 mm, F 71 mm; CoM 83.9 % / 76.8 %, r_zz 56 % / 58 %); the fingertip rows used
#   here (M 189 mm, F 167 mm; CoM 35.7 % / 32.7 %, r_zz 24 % / 25 %) are the same parameters re-expressed on the
#   longer length (men: CoM 67.1 vs 67.5 mm from the wrist, radius 44.8 vs 45.4 mm), and the fingertip is the
#   end-effector, so the lengths measured from markers are the fingertip ones.
DUMAS_2007 = {
    "M": {
        "upper_arm": (2.4, 45.2, 32.0, 0.271),
        "forearm": (1.7, 41.7, 27.0, 0.253),
        "hand": (0.6, 35.7, 24.0, 0.189),  # wrist centre to 3rd fingertip
    },
    "F": {
        "upper_arm": (2.2, 45.4, 33.0, 0.243),
        "forearm": (1.3, 41.1, 25.0, 0.247),
        "hand": (0.5, 32.7, 25.0, 0.167),
    },
}
# Stature the mean lengths above belong to; default lengths are scaled by height / this.
_REFERENCE_HEIGHT_M = {"M": 1.77, "F": 1.64}


def sex_key(text) -> str | None:
    """The key of Dumas 2007's tables for a sex as written in a subject table: ``"M"`` for M or male, ``"F"`` for F or
    female (any case), ``None`` for anything else."""
    return {"M": "M", "MALE": "M", "F": "F", "FEMALE": "F"}.get(str(text).strip().upper())


#: what a subject's stature (m), body mass (kg) and arm segment length (m) may be (closed ranges: the ends included)
STATURE_RANGE_M = (0.5, 2.6)
BODY_MASS_RANGE_KG = (10.0, 300.0)
SEGMENT_RANGE_M = (0.02, 1.0)
#: a subject's arm segment lengths (m), as the columns of a subject-info file and the arguments of
#: :meth:`ArmModel.from_anthropometrics` name them
SEGMENT_COLUMNS = ("upper_arm_m", "forearm_m", "hand_m")

#: where a stature, body mass or segment length out of its range (above) lands when written in another unit
_SLIPS = {
    "height": ((50.0, 260.0, "centimetres"), (500.0, 2600.0, "millimetres")),
    "mass": ((10_000.0, 300_000.0, "grams"),),
    "length": ((2.0, 100.0, "centimetres"), (100.0, 1000.0, "millimetres")),
}


def unit_slip(value: float, quantity: str) -> str:
    """The words for the unit a subject's ``quantity`` (``"height"``, ``"mass"`` or ``"length"``) was likely written
    in when ``value`` is out of its range in SI units, such as ``"; in centimetres?"`` for a stature of 172; ``""``
    when no unit fits (a typo, not a unit)."""
    return next((f"; in {unit}?" for lo, hi, unit in _SLIPS[quantity] if lo <= value < hi), "")


#: kg/m²: what a subject's body-mass index, ``mass_kg / height_m²``, may be (closed range): adults range from about 13
#: (severe thinness) to the 50s (class III obesity), and health records' cleaning takes a BMI below 12 or above 60
#: as a slip. A mass in pounds is 2.2 times its kilograms: for a BMI of 27 or more it reads above 60 and is refused
#: (below, :data:`BMI_NOTE` notes it); a mass in stones (6.35 kg) reads below 12
BMI_RANGE = (12.0, 60.0)
#: kg/m²: a BMI within :data:`BMI_RANGE` but this high or higher is rare (about 1 adult in 100): the subject-info
#: reader notes the mass it would be in pounds, and takes it as written
BMI_NOTE = 45.0
#: kg: a pound and a stone, the units a body mass slips into
POUND_KG, STONE_KG = 0.45359237, 6.35029318


def bmi_problem(height_m: float, mass_kg: float) -> str | None:
    """What is wrong with a subject's ``height_m`` and ``mass_kg`` together (each in its range): a body-mass index
    out of :data:`BMI_RANGE`, such as ``"mass_kg 160.0 and height_m 1.6 give a body-mass index of 62.5 kg/m², not
    a person's (12-60); mass_kg in pounds (72.6 kg)?"``; ``None`` within."""
    bmi = mass_kg / height_m**2
    lo, hi = BMI_RANGE
    if lo <= bmi <= hi:
        return None
    unit, factor = ("pounds", POUND_KG) if bmi >= hi else ("stones", STONE_KG)
    kg = mass_kg * factor
    slip = f"; mass_kg in {unit} ({kg:.1f} kg)?" if lo < kg / height_m**2 < hi else "; check both columns"
    return (
        f"mass_kg {mass_kg} and height_m {height_m} give a body-mass index of {bmi:.1f} kg/m², not a person's "
        f"({lo:g}-{hi:g}){slip}"
    )


def bmi_note(height_m: float, mass_kg: float) -> str | None:
    """A note on a BMI in range but :data:`BMI_NOTE` or higher (the mass it would be in pounds), or ``None``."""
    bmi = mass_kg / height_m**2
    if not BMI_NOTE <= bmi <= BMI_RANGE[1]:
        return None
    return (
        f"mass_kg {mass_kg} and height_m {height_m} give a body-mass index of {bmi:.1f} kg/m², rare: if the mass is "
        f"in pounds it is {mass_kg * POUND_KG:.1f} kg (taken as {mass_kg} kg)"
    )


#: a subject's columns: (their range, what they hold, the range as said, the quantity of :func:`unit_slip`)
_COLUMNS = {
    "height_m": (STATURE_RANGE_M, "a stature in metres", "0.5-2.6", "height"),
    "mass_kg": (BODY_MASS_RANGE_KG, "a body mass in kg", "10-300", "mass"),
    **{c: (SEGMENT_RANGE_M, "a segment length in metres", "0.02-1.0", "length") for c in SEGMENT_COLUMNS},
}


def anthropometry_problem(column: str, value: float) -> str | None:
    """What is wrong with a subject's ``column`` (``height_m``, ``mass_kg`` or a segment's ``upper_arm_m``,
    ``forearm_m``, ``hand_m``) of ``value``, in the words a subject-info file and
    :meth:`ArmModel.from_anthropometrics` both say, such as ``"height_m 172.0 is not a stature in metres (0.5-2.6);
    in centimetres?"``; ``None`` when it lies in its range."""
    (lo, hi), what, said, quantity = _COLUMNS[column]
    if lo <= value <= hi:
        return None
    return f"{column} {value} is not {what} ({said}){unit_slip(value, quantity)}"


#: m: no segment of a human arm is this long (a forearm is about 0.25 m): a longer one is in millimetres
MAX_SEGMENT_LENGTH_M = 3.0


def _same_rows(where: str, **arrays: np.ndarray) -> None:
    """The arrays of one call (``q``, ``q̇``, ...) hold as many pairs each: a ``ValueError`` naming ``where`` and
    the shapes otherwise (numpy broadcast a single pair, or failed on its own terms)."""
    shapes = {name: a.shape for name, a in arrays.items()}
    if len(set(shapes.values())) > 1:
        said = ", ".join(f"{name} {shape}" for name, shape in shapes.items())
        raise ValueError(f"ArmModel.{where}: the arrays must have one shape, got {said}")


def _pairs(where: str, name: str, v) -> np.ndarray:
    """``v`` as floats of shape ``(..., 2)``, one pair (q1, q2), (x, y) or (τ1, τ2) along the last axis; any other
    shape, or what is not numbers, is a ``ValueError`` naming ``where``, ``name`` and the shape or value (a
    joints-first ``(2, n)`` array, or three columns, was read silently by its first two columns)."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"ArmModel.{where}: {name} must be numbers of shape (..., 2), got {brief(v)}") from None
    if a.ndim == 0 or a.shape[-1] != 2:
        raise ValueError(f"ArmModel.{where}: {name} must have shape (..., 2), one pair per row, got {a.shape}")
    return a


@dataclass(frozen=True)
class ArmModel:
    """A planar two-link arm in SI units (a segment longer than :data:`MAX_SEGMENT_LENGTH_M` is refused: millimetres).

    ``c1``/``c2`` are the CoM distances from each segment's proximal joint and ``i1``/``i2`` the inertias about
    the CoM (about the axis normal to the plane).
    """

    l1: float
    l2: float
    m1: float
    m2: float
    c1: float
    c2: float
    i1: float
    i2: float
    gravity: float = 9.81

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            # text ("0.3", of a CSV or a form) is no number here, as in Trial and PreprocessOptions: float() took it
            if isinstance(v, str | bytes) or np.iscomplexobj(v):
                raise ValueError(f"ArmModel.{f.name} must be a number, got {brief(v)} ({type(v).__name__})")
            try:
                v = number(v)
            except (TypeError, ValueError):
                raise ValueError(f"ArmModel.{f.name} must be a number, got {brief(v)} ({type(v).__name__})") from None
            if not np.isfinite(v):
                raise ValueError(f"ArmModel.{f.name} must be finite, got {v}")
            object.__setattr__(self, f.name, v)
        for name in ("l1", "l2", "m1", "m2", "i1", "i2"):
            if getattr(self, name) <= 0:
                raise ValueError(f"ArmModel.{name} must be > 0, got {getattr(self, name)}")
        for name in ("l1", "l2"):  # in millimetres a forearm is hundreds of "metres": refused here, not in a solve
            if getattr(self, name) > MAX_SEGMENT_LENGTH_M:
                raise ValueError(
                    f"ArmModel.{name} must be in metres, got {getattr(self, name):g}: longer than any arm segment "
                    f"({MAX_SEGMENT_LENGTH_M:g} m; millimetres?)"
                )
        if not 0 <= self.c1 <= self.l1 or not 0 <= self.c2 <= self.l2:
            raise ValueError(f"ArmModel CoM must lie on its segment: c1={self.c1}, c2={self.c2}")
        if self.gravity < 0:
            raise ValueError(f"ArmModel.gravity must be >= 0, got {self.gravity}")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_anthropometrics(
        cls,
        height_m: float,
        mass_kg: float,
        sex: str,
        upper_arm_m: float | None = None,
        forearm_m: float | None = None,
        hand_m: float | None = None,
    ) -> ArmModel:
        """Build the arm from Dumas 2007 tables.

        Missing segment lengths default to Dumas' mean lengths scaled by ``height_m`` over the reference stature.
        The hand (wrist centre to fingertip) is lumped onto the forearm with the parallel-axis theorem, so
        ``l2 = forearm_m + hand_m`` and the fingertip is the end-effector.
        """

        def number(name: str, v, unit: str) -> float:  # text, None or an array names the field, not float()
            if isinstance(v, bool):
                raise TypeError(f"{name} must be a number ({unit}), got {v!r}")
            try:
                return float(v)
            except (TypeError, ValueError):
                error = ValueError if isinstance(v, str) else TypeError  # float()'s own kinds of error
                raise error(f"{name} must be a number ({unit}), got {brief(v)}") from None

        key = sex_key(sex)
        if key is None:
            raise ValueError(f"sex must be 'M' or 'F' (or 'male', 'female'), got {sex!r}")
        height_m, mass_kg = number("height_m", height_m, "m"), number("mass_kg", mass_kg, "kg")
        for column, value in (("height_m", height_m), ("mass_kg", mass_kg)):
            problem = anthropometry_problem(column, value)  # in a subject-info file's words
            if problem is not None:
                raise ValueError(problem)
        problem = bmi_problem(height_m, mass_kg)
        if problem is not None:
            raise ValueError(problem)
        table = DUMAS_2007[key]
        scale = height_m / _REFERENCE_HEIGHT_M[key]

        def segment(name: str, length: float | None) -> tuple[float, float, float, float]:
            mass_pct, com_pct, r_pct, mean_len = table[name]
            length = mean_len * scale if length is None else number(f"{name}_m", length, "m")
            problem = anthropometry_problem(f"{name}_m", length)
            if problem is not None:
                raise ValueError(problem)
            m = mass_pct / 100.0 * mass_kg
            return length, m, com_pct / 100.0 * length, m * (r_pct / 100.0 * length) ** 2

        l1, m1, c1, i1 = segment("upper_arm", upper_arm_m)
        lf, mf, cf, i_f = segment("forearm", forearm_m)
        lh, mh, ch, i_h = segment("hand", hand_m)
        ch += lf  # hand CoM measured from the elbow
        m2 = mf + mh
        c2 = (mf * cf + mh * ch) / m2
        i2 = i_f + mf * (cf - c2) ** 2 + i_h + mh * (ch - c2) ** 2
        return cls(l1=l1, l2=lf + lh, m1=m1, m2=m2, c1=c1, c2=c2, i1=i1, i2=i2)

    @property
    def length(self) -> float:
        """Total arm length ``l1 + l2`` (shoulder to fingertip, arm straight)."""
        return self.l1 + self.l2

    def to_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict) -> ArmModel:
        return cls(**{f.name: d[f.name] for f in fields(cls) if f.name in d})

    # ------------------------------------------------------------------ kinematics
    def fk(self, q: np.ndarray) -> np.ndarray:
        """Fingertip position, ``(..., 2)`` from ``q`` of shape ``(..., 2)``."""
        q = _pairs("fk", "q", q)
        q1, q12 = q[..., 0], q[..., 0] + q[..., 1]
        return np.stack(
            [self.l1 * np.cos(q1) + self.l2 * np.cos(q12), self.l1 * np.sin(q1) + self.l2 * np.sin(q12)], axis=-1
        )

    def elbow(self, q: np.ndarray) -> np.ndarray:
        """Elbow position ``(..., 2)``."""
        q = _pairs("elbow", "q", q)
        return self.l1 * np.stack([np.cos(q[..., 0]), np.sin(q[..., 0])], axis=-1)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Fingertip Jacobian ``dP/dq``, shape ``(..., 2, 2)``."""
        q = _pairs("jacobian", "q", q)
        q1, q12 = q[..., 0], q[..., 0] + q[..., 1]
        s1, c1, s12, c12 = np.sin(q1), np.cos(q1), np.sin(q12), np.cos(q12)
        J = np.empty((*q.shape[:-1], 2, 2))
        J[..., 0, 0] = -self.l1 * s1 - self.l2 * s12
        J[..., 0, 1] = -self.l2 * s12
        J[..., 1, 0] = self.l1 * c1 + self.l2 * c12
        J[..., 1, 1] = self.l2 * c12
        return J

    def fingertip_velocity(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Fingertip velocity ``J(q) qd``, shape ``(..., 2)``."""
        return np.einsum("...ij,...j->...i", self.jacobian(q), _pairs("fingertip_velocity", "qd", qd))

    def fingertip_speed(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Fingertip speed ``‖J(q) q̇‖``, shape ``(...)``: ``√(q̇ᵀ JᵀJ q̇)``, where ``JᵀJ`` depends on the elbow angle
        only (one cosine per sample instead of the Jacobian's four sines and cosines)."""
        q, qd = _pairs("fingertip_speed", "q", q), _pairs("fingertip_speed", "qd", qd)
        c = self.l1 * self.l2 * np.cos(q[..., 1])
        w1, w12 = qd[..., 0], qd[..., 0] + qd[..., 1]  # the upper arm's and the forearm's absolute angular rates
        return np.sqrt(np.maximum(self.l1**2 * w1**2 + self.l2**2 * w12**2 + 2.0 * c * w1 * w12, 0.0))

    def ik(self, p: np.ndarray, elbow_up: bool = False) -> np.ndarray:
        """Two-link inverse kinematics of the fingertip, ``(..., 2)`` -> ``(..., 2)``.

        The default branch has the elbow flexed (``q2 >= 0``), the human one. Berret 2011's equation:
        ``q1 = atan2(y, x) - acos((x²+y²+l1²-l2²) / (2 l1 r))``, ``q2 = pi - acos((l1²+l2²-r²) / (2 l1 l2))``.
        Raises ``ValueError`` when a point is out of reach.
        """
        p = _pairs("ik", "p", p)
        r2 = p[..., 0] ** 2 + p[..., 1] ** 2
        r = np.sqrt(r2)
        tol = 1e-9
        if np.any(r > self.l1 + self.l2 + tol) or np.any(r < abs(self.l1 - self.l2) - tol):
            bad = np.flatnonzero(np.ravel((r > self.l1 + self.l2 + tol) | (r < abs(self.l1 - self.l2) - tol)))
            raise ValueError(
                f"fingertip out of reach of an arm of lengths {self.l1:.3f}+{self.l2:.3f} m at sample(s) "
                f"{bad[:5].tolist()} (distance {np.ravel(r)[bad[0]]:.3f} m)"
            )
        cos_inner = np.clip((self.l1**2 + self.l2**2 - r2) / (2 * self.l1 * self.l2), -1.0, 1.0)
        q2 = np.pi - np.arccos(cos_inner)
        cos_a = np.clip((r2 + self.l1**2 - self.l2**2) / (2 * self.l1 * np.maximum(r, 1e-12)), -1.0, 1.0)
        q1 = np.arctan2(p[..., 1], p[..., 0]) - np.arccos(cos_a)
        if elbow_up:
            q1, q2 = q1 + 2 * np.arccos(cos_a), -q2
        return np.stack([q1, q2], axis=-1)

    # ------------------------------------------------------------------ dynamics (closed form)
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia ``M(q)``, shape ``(..., 2, 2)``."""
        q = _pairs("mass_matrix", "q", q)
        cq2 = np.cos(q[..., 1])
        a = self.i1 + self.i2 + self.m1 * self.c1**2 + self.m2 * (self.l1**2 + self.c2**2)
        b = self.m2 * self.l1 * self.c2
        d = self.i2 + self.m2 * self.c2**2
        M = np.empty((*q.shape[:-1], 2, 2))
        M[..., 0, 0] = a + 2 * b * cq2
        M[..., 0, 1] = M[..., 1, 0] = d + b * cq2
        M[..., 1, 1] = d
        return M

    def coriolis(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Coriolis and centrifugal torques ``C(q, qd) qd``, shape ``(..., 2)``."""
        q, qd = _pairs("coriolis", "q", q), _pairs("coriolis", "qd", qd)
        _same_rows("coriolis", q=q, qd=qd)
        h = self.m2 * self.l1 * self.c2 * np.sin(q[..., 1])
        return np.stack([-h * (2 * qd[..., 0] * qd[..., 1] + qd[..., 1] ** 2), h * qd[..., 0] ** 2], axis=-1)

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """Gravity torques ``g(q)`` (the torque needed to hold still), shape ``(..., 2)``."""
        q = _pairs("gravity_torque", "q", q)
        c1, c12 = np.cos(q[..., 0]), np.cos(q[..., 0] + q[..., 1])
        g2 = self.gravity * self.m2 * self.c2 * c12
        g1 = self.gravity * (self.m1 * self.c1 + self.m2 * self.l1) * c1 + g2
        return np.stack([g1, g2], axis=-1)

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Non-linear effects ``b = C(q, qd) qd + g(q)`` (Pinocchio's ``nle``)."""
        return self.coriolis(q, qd) + self.gravity_torque(q)

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """``tau = M(q) qdd + b(q, qd)``, vectorised over leading axes (the three of one shape)."""
        q, qd, qdd = (_pairs("inverse_dynamics", n, v) for n, v in (("q", q), ("qd", qd), ("qdd", qdd)))
        _same_rows("inverse_dynamics", q=q, qd=qd, qdd=qdd)
        return np.einsum("...ij,...j->...i", self.mass_matrix(q), qdd) + self.bias(q, qd)

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """``qdd = M(q)^-1 (tau - b(q, qd))``, vectorised over leading axes (the three of one shape)."""
        q, qd, tau = (_pairs("forward_dynamics", n, v) for n, v in (("q", q), ("qd", qd), ("tau", tau)))
        _same_rows("forward_dynamics", q=q, qd=qd, tau=tau)
        rhs = tau - self.bias(q, qd)
        return np.linalg.solve(self.mass_matrix(q), rhs[..., None])[..., 0]

    # ------------------------------------------------------------------ Pinocchio
    def pinocchio_model(self):
        """The same arm as a Pinocchio model: two revolute-Z joints, a ``fingertip`` frame, gravity along -y."""
        import pinocchio as pin

        model = pin.Model()
        model.name = "reachirl_arm"
        model.gravity.linear = np.array([0.0, -self.gravity, 0.0])
        j1 = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "shoulder")
        model.appendBodyToJoint(j1, _planar_inertia(self.m1, self.c1, self.i1), pin.SE3.Identity())
        j2 = model.addJoint(j1, pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([self.l1, 0.0, 0.0])), "elbow")
        model.appendBodyToJoint(j2, _planar_inertia(self.m2, self.c2, self.i2), pin.SE3.Identity())
        model.addFrame(pin.Frame("upper_arm", j1, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
        model.addFrame(
            pin.Frame("fingertip", j2, 0, pin.SE3(np.eye(3), np.array([self.l2, 0.0, 0.0])), pin.FrameType.OP_FRAME)
        )
        for i in range(2):  # the limits do not enter the dynamics; keep them wide
            model.lowerPositionLimit[i], model.upperPositionLimit[i] = -2 * np.pi, 2 * np.pi
        return model


def _planar_inertia(mass: float, com_x: float, izz: float):
    """A body whose CoM lies on its x axis with inertia ``izz`` about z through the CoM.

    The x/y inertias are set to ``izz`` as well: they never act in planar motion about z, but keep the tensor
    physically valid (triangle inequality).
    """
    import pinocchio as pin

    return pin.Inertia(mass, np.array([com_x, 0.0, 0.0]), np.diag([izz * 0.5, izz * 0.5, izz]))
