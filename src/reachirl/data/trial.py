"""A trial (one reach, from onset to offset, on the subject's planar arm) and the trials file format.

The trials file is one NPZ: the arrays of every trial under ``"<index>/<field>"`` and a ``meta.json`` entry with
the scalar fields and each trial's :class:`~reachirl.arm.ArmModel`. It never holds a pickle. Packed
(``save_trials(..., packed=True)``, the trials cache's): each field's arrays end to end under ``"<field>"``, with
``n_samples`` per trial: a handful of entries instead of six per trial, read ten times faster.
"""

from __future__ import annotations

import json
import re
import zipfile
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from ..arm import ArmModel
from ..errors import InputError
from ..features import euler_knots
from ..io import atomic_write_bytes, npz_bytes
from ..validation import brief, not_real, number

__all__ = [
    "TRIALS_FORMAT",
    "Trial",
    "is_trials_header",
    "load_trials",
    "save_trials",
    "select_trials",
    "trial_from_knots",
    "trial_from_solution",
]


def _spline(t: np.ndarray, y: np.ndarray):
    """scipy's cubic spline through ``y (n, k)`` at ``t``, along axis 0."""
    # imported here: scipy.interpolate imports scipy.optimize, which the command's own process never needs
    from scipy.interpolate import CubicSpline

    return CubicSpline(t, y, axis=0)


TRIALS_FORMAT = "reachirl-trials/1"
#: the ``format`` of a trials file's header in every version of it, :data:`TRIALS_FORMAT` and those before and after
_ANY_TRIALS_FORMAT = re.compile(r"reachirl-trials/[0-9]+")
_ARRAYS = ("t", "q", "qd", "qdd", "tau")
#: rad: no joint of an arm turns two whole turns (a reach's angles lie within ±3 rad): beyond, they are in degrees
MAX_JOINT_ANGLE_RAD = 4.0 * np.pi


@dataclass(frozen=True)
class Trial:
    """One reach. Time ``t (n,)`` starts at 0 (the onset) and ends at ``duration`` (the offset).

    ``onset_threshold`` says how the reach was cut from its recording: where the fingertip speed crosses that
    fraction of its peak (:func:`reachirl.data.segmentation.detect_onset_offset`), so the trial starts and ends
    moving; ``None`` for a trial that was not cut (a DOC solution, a file from before the field existed).

    ``q``, ``qd``, ``qdd``, ``tau`` have shape ``(n, 2)`` (rad, rad/s, rad/s², N·m; an angle beyond
    :data:`MAX_JOINT_ANGLE_RAD`, two turns, is refused as degrees; ``tau`` from inverse
    dynamics on ``arm``). ``x0 = (q1, q2, q̇1, q̇2)`` is the state at onset and ``target_x`` the fingertip's x at
    offset (m). ``side`` is the arm that moved (``"right"``/``"left"``); left arms are already mirrored into the
    right-arm convention.
    """

    subject: str
    posture: str
    trial_id: str
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    target_x: float
    arm: ArmModel
    side: str = "right"
    source: str = ""
    x0: np.ndarray = field(default=None)  # type: ignore[assignment]  # defaults to (q[0], qd[0])
    onset_threshold: float | None = None  # cut where the fingertip speed crosses this × its peak; None: not cut

    def __post_init__(self) -> None:
        where = self.source or f"trial {self.subject}/{self.posture}/{self.trial_id}"
        t = _floats("t", self.t, where).reshape(-1)
        n = t.shape[0]
        if n < 4:
            raise InputError(f"a trial needs at least 4 samples, got {n}", where)
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise InputError("time must be finite and strictly increasing", where)
        t = t - t[0]  # a new array: the caller's is neither kept nor changed
        t.setflags(write=False)
        object.__setattr__(self, "t", t)
        for name in ("q", "qd", "qdd", "tau"):
            a = _floats(name, getattr(self, name), where)
            if a.shape != (n, 2):
                raise InputError(f"{name} has shape {a.shape}, expected ({n}, 2)", where)
            if not np.all(np.isfinite(a)):
                raise InputError(f"{name} contains NaN or infinite values", where)
            a = a.copy()
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        # a copy, read-only like the other arrays: the caller's array changed later must not change the trial
        x0 = np.r_[self.q[0], self.qd[0]] if self.x0 is None else _floats("x0", self.x0, where).reshape(-1).copy()
        if x0.shape != (4,) or not np.all(np.isfinite(x0)):
            raise InputError(f"x0 must be 4 finite numbers (q1, q2, qd1, qd2), got shape {x0.shape}", where)
        for name, angles in (("q", self.q), ("x0's angles", x0[:2])):  # degrees are refused here, not in a solve
            worst = float(np.max(np.abs(angles)))
            if worst > MAX_JOINT_ANGLE_RAD:
                raise InputError(
                    f"{name} must be in radians, got {worst:.4g} at most: beyond any joint's "
                    f"{MAX_JOINT_ANGLE_RAD / (2 * np.pi):g} turns ({MAX_JOINT_ANGLE_RAD:.4g} rad; degrees?)",
                    where,
                )
        x0.setflags(write=False)
        object.__setattr__(self, "x0", x0)
        if not isinstance(self.arm, ArmModel):
            raise InputError(f"arm must be an ArmModel, got {type(self.arm).__name__}", where)
        try:
            target_x = number(self.target_x)
        except (TypeError, ValueError):
            raise InputError(f"target_x must be a number (m), got {brief(self.target_x)}", where) from None
        if not np.isfinite(target_x) or abs(target_x) > self.arm.length:
            raise InputError(f"target_x {target_x} m is unreachable by an arm {self.arm.length:.3f} m long", where)
        object.__setattr__(self, "target_x", target_x)
        if self.side not in ("right", "left"):
            raise InputError(f"side must be 'right' or 'left', got {self.side!r}", where)
        for name in ("subject", "posture", "trial_id", "source"):
            object.__setattr__(self, name, str(getattr(self, name)))
        for name in ("subject", "posture", "trial_id"):  # the parts of the trial's id, and of file names
            v = getattr(self, name)
            if "/" in v or not v.isprintable():
                raise InputError(
                    f"{name} {v!r} must not contain '/' (it separates the parts of a trial's id) or a control "
                    "character (a line break, a tab)",
                    where,
                )
        th = self.onset_threshold
        if th is not None:
            if isinstance(th, bool) or not isinstance(th, int | float | np.number) or not 0.0 < float(th) < 1.0:
                raise InputError(f"onset_threshold must be a fraction in (0, 1) or None, got {th!r}", where)
            object.__setattr__(self, "onset_threshold", float(th))

    def __eq__(self, other: object) -> bool:
        """Field by field, arrays by their values: dataclass equality compared the arrays with ``==``, and two
        equal trials (a file loaded twice) raised numpy's "truth value of an array ... is ambiguous" in ``==``
        and ``in``."""
        if other.__class__ is not self.__class__:
            return NotImplemented
        for f in fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not np.array_equal(a, b):
                    return False
            elif a != b:
                return False
        return True

    def __hash__(self) -> int:
        """From the trial's id and duration (equal trials have equal ones): a trial can be a set member or a key."""
        return hash((self.id, self.duration))

    # ------------------------------------------------------------------ derived
    @property
    def duration(self) -> float:
        return float(self.t[-1])

    @property
    def target(self) -> float:
        """The reach's target, the bar's x: ``target_x`` (m) under the name the project's design gives it in its
        data path (``Trial (q, q̇, q̈, τ, x0, target, duration, subject, posture)``; design.md, which is not
        docs/design-notes.md)."""
        return self.target_x

    @property
    def id(self) -> str:
        return f"{self.subject}/{self.posture}/{self.side}/{self.trial_id}"

    @property
    def state(self) -> np.ndarray:
        """``(n, 4)`` state ``(q1, q2, q̇1, q̇2)``."""
        return np.hstack([self.q, self.qd])

    def q_at(self, n_points: int) -> np.ndarray:
        """The joint angles on ``n_points`` equally spaced samples (cubic spline), ``(n_points, 2)``: the ``q``
        of :meth:`resample`, without its velocities and torques. Read-only, and computed once per number of
        points: a study compares each trial with many fits' predictions on the same knots."""
        n_points = int(n_points)
        kept = self.__dict__.setdefault("_q_at", {})  # beside the fields: not compared, not a field of replace()
        q = kept.get(n_points)
        if q is None:
            q = _spline(self.t, self.q)(np.linspace(0.0, self.duration, n_points))
            q.setflags(write=False)
            if len(kept) < 8:
                kept[n_points] = q
        return q

    def resample(self, n_points: int) -> Trial:
        """The same reach on ``n_points`` equally spaced samples (cubic spline; torques re-derived)."""
        t_new = np.linspace(0.0, self.duration, n_points)
        q = self.q_at(n_points)
        qd = _spline(self.t, self.qd)(t_new)
        qdd = _spline(self.t, self.qdd)(t_new)
        tau = self.arm.inverse_dynamics(q, qd, qdd)
        return replace(self, t=t_new, q=q, qd=qd, qdd=qdd, tau=tau)

    def knots(self, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q (N+1,2), qd (N+1,2), tau (N,2))`` on the DOC's ``N = n_nodes`` intervals, computed exactly as the
        DOC computes its own: ``q_k`` on the knots (cubic spline of the filtered angles), the semi-implicit Euler
        velocities ``q̇_k = (q_k − q_{k−1})/dt`` (``q̇_0`` from ``x0``), the Euler accelerations
        ``q̈_k = (q̇_{k+1} − q̇_k)/dt`` and the inverse-dynamics torques ``τ_k = M(q_k) q̈_k + b(q_k, q̇_k)``.

        A DOC solution stored as a trial (:func:`trial_from_solution`) gives back its own ``q``, ``q̇`` and ``τ``
        exactly, so its features are the DOC's own. Demonstrations enter MO-IRL's features and merit this way.
        """
        n = int(n_nodes)
        dt = self.duration / n
        return euler_knots(self.arm, self.q_at(n + 1), dt, self.x0[2:])

    def lowpass(self, cutoff_hz: float, order: int = 4) -> Trial:
        """The same reach with its angles low-passed again (zero-lag Butterworth of ``order`` at ``cutoff_hz``,
        scipy's ``sosfiltfilt`` on a uniform grid at the trial's own mean rate) and ``q̇``, ``q̈``, ``τ``
        re-derived. For features of derivatives up to the third order (``τ̇``), which amplify the noise that the
        recording's position filter leaves; the initial state keeps its velocity."""
        from scipy.signal import butter, sosfiltfilt  # here: scipy.signal costs every command 0.4 s to import

        n = self.t.shape[0]
        fs = (n - 1) / self.duration
        if not 0 < cutoff_hz < fs / 2:
            raise ValueError(f"cutoff must be in (0, {fs / 2:g}) Hz for a trial sampled at {fs:g} Hz, got {cutoff_hz}")
        t = np.linspace(0.0, self.duration, n)
        q = _spline(self.t, self.q)(t)
        sos = butter(order, cutoff_hz, fs=fs, output="sos")
        q = sosfiltfilt(sos, q, axis=0, padtype="odd", padlen=min(n - 1, 3 * (2 * len(sos) + 1)))
        spline = _spline(t, q)
        qd, qdd = spline(t, 1), spline(t, 2)
        return replace(
            self, t=t, q=q, qd=qd, qdd=qdd, tau=self.arm.inverse_dynamics(q, qd, qdd), x0=np.r_[q[0], self.x0[2:]]
        )

    def knot_state(self, n_nodes: int) -> np.ndarray:
        """The state ``(q1, q2, q̇1, q̇2)`` on the DOC's knots, ``(N+1, 4)``, as :meth:`knots` defines it."""
        q, qd, _ = self.knots(n_nodes)
        return np.hstack([q, qd])

    def features(self, n_nodes: int, n_windows: int) -> np.ndarray:
        """Φ of this demonstration per window, ``(n_windows, 7)``, on the DOC's discretisation."""
        from ..features import windowed_features

        q, qd, tau = self.knots(n_nodes)
        return windowed_features(self.arm, q, qd, tau, self.duration / n_nodes, n_windows)


def _floats(name: str, v, where: str) -> np.ndarray:
    """``v`` as an array of floats; anything else (text, ragged rows, complex numbers whose imaginary part a cast
    would drop, booleans) is an :class:`InputError` naming ``name``."""
    if (what := not_real(v)) is not None:
        raise InputError(f"{name} must be an array of real numbers, got {what}", where)
    try:
        return np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of numbers, got {brief(v)}", where) from None


# ---------------------------------------------------------------------- file format
def is_trials_header(header) -> bool:
    """Whether ``header`` (a parsed ``meta.json`` entry) is a reachirl trials file's, of this version of the format
    or another (``reachirl-trials/<N>``: a file an older reachirl wrote is one, though :func:`load_trials` reads
    only :data:`TRIALS_FORMAT`)."""
    fmt = header.get("format") if isinstance(header, dict) else None
    return isinstance(fmt, str) and _ANY_TRIALS_FORMAT.fullmatch(fmt) is not None


def save_trials(path: str | Path, trials: Sequence[Trial], packed: bool = False) -> Path:
    """Write trials to ``path`` exactly (one NPZ), atomically; ``packed``: each field's arrays end to end (see the
    module docstring). What :func:`load_trials` would refuse is refused here (:class:`InputError` naming the
    trial), so that a file saved is a file that loads."""
    trials = list(trials)
    if not trials:
        raise ValueError("no trials to save")
    bad = next((tr for tr in trials if not isinstance(tr, Trial)), None)
    if bad is not None:
        raise TypeError(f"save_trials takes a sequence of Trial, got a {type(bad).__name__}")
    _check_file_trials(trials, path)
    if packed:
        arrays = {name: np.concatenate([getattr(tr, name) for tr in trials]) for name in _ARRAYS}
        arrays["x0"] = np.stack([tr.x0 for tr in trials])
        arrays["n_samples"] = np.array([tr.t.size for tr in trials], dtype=np.int64)
    else:
        arrays = {f"{i}/{name}": getattr(tr, name) for i, tr in enumerate(trials) for name in (*_ARRAYS, "x0")}
    meta = [
        {
            "subject": tr.subject,
            "posture": tr.posture,
            "trial_id": tr.trial_id,
            "side": tr.side,
            "source": tr.source,
            "target_x": tr.target_x,
            "arm": tr.arm.to_dict(),
            "onset_threshold": tr.onset_threshold,
        }
        for tr in trials
    ]
    header = {"format": TRIALS_FORMAT, "n_trials": len(trials), "trials": meta}
    if packed:
        header["layout"] = "packed"
    arrays["meta.json"] = np.frombuffer(json.dumps(header, sort_keys=True).encode("utf-8"), dtype=np.uint8)
    path = Path(path)
    atomic_write_bytes(path, npz_bytes(arrays))
    return path


def load_trials(path: str | Path) -> list[Trial]:
    """Read a trials file written by :func:`save_trials`; any problem raises :class:`InputError` naming it."""
    from ..io import check_regular_file
    from ..validation import check_npz_file
    from .checks import check_trial_meta

    path = check_regular_file(path)  # a FIFO or a device would block or never end
    if not zipfile.is_zipfile(path):
        raise InputError("not a trials file (expected the NPZ written by `reachirl preprocess`)", path)
    check_npz_file(path)  # sizes, dtypes and CRCs, before any array is read
    _check_entries(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            files = set(z.files)
            if "meta.json" not in files:
                raise InputError("not a reachirl trials file (no meta.json entry)", path)
            header = json.loads(bytes(z["meta.json"]).decode("utf-8"))
            if not isinstance(header, dict) or header.get("format") != TRIALS_FORMAT:
                found = header.get("format") if isinstance(header, dict) else type(header).__name__
                again = "; run `reachirl preprocess` again to rewrite it" if is_trials_header(header) else ""
                raise InputError(f"unsupported format {found!r}, expected {TRIALS_FORMAT!r}{again}", path)
            if not isinstance(header.get("trials"), list):
                raise InputError("meta.json: field 'trials' must be a list", path)
            declared = header.get("n_trials", len(header["trials"]))
            if declared != len(header["trials"]):
                raise InputError(
                    f"meta.json: 'n_trials' is {declared!r} but 'trials' lists {len(header['trials'])} (a damaged "
                    "or hand-edited file)",
                    path,
                )
            layout = header.get("layout", "per-trial")
            if layout not in ("per-trial", "packed"):
                raise InputError(f"meta.json: unknown layout {brief(layout)} (expected 'packed' or none)", path)
            arrays_of = (_packed if layout == "packed" else _per_trial)(z, files, len(header["trials"]), path)
            out = []
            arms: dict = {}  # one ArmModel per subject's arm, shared by its trials
            for i, m in enumerate(header["trials"]):
                check_trial_meta(m, i, path)
                arrays = arrays_of(i)
                out.append(
                    _trial_in_file(
                        path,
                        i,
                        m,
                        lambda m=m, arrays=arrays: Trial(
                            subject=m["subject"],
                            posture=m["posture"],
                            trial_id=m["trial_id"],
                            side=m.get("side", "right"),
                            source=m.get("source", ""),
                            target_x=m["target_x"],
                            arm=_arm_in_file(m["arm"], arms),
                            onset_threshold=m.get("onset_threshold"),
                            **arrays,
                        ),
                    )
                )
    except InputError:
        raise
    except (zipfile.BadZipFile, OSError, EOFError, zlib.error) as e:
        raise InputError(f"not a readable NPZ trials file ({e})", path) from None
    except (KeyError, TypeError, ValueError, AttributeError, RecursionError, json.JSONDecodeError) as e:
        raise InputError(f"malformed trials file ({type(e).__name__}: {str(e)[:120]})", path) from None
    if not out:
        raise InputError("the file holds no trials", path)
    _check_file_trials(out, path)
    return out


def _check_file_trials(trials: Sequence[Trial], path: object) -> None:
    """What a trials file holds, checked on saving and on loading: each trial can be planned by the DOC
    (:func:`~reachirl.data.checks.check_trial_physics`, :func:`~reachirl.data.checks.check_start_and_target`),
    and their ids are unique."""
    from .checks import check_start_and_target, check_trial_physics

    seen: dict[str, int] = {}
    for i, tr in enumerate(trials):
        check_trial_physics(tr, i, path)
        check_start_and_target(tr, path, f"trial {i} ({tr.id})")
        if tr.id in seen:  # its predictions, exports and METRICS rows would be told apart by nothing
            raise InputError(f"trial {i} has the id {tr.id!r} of trial {seen[tr.id]}; ids must be unique", path)
        seen[tr.id] = i


def _per_trial(z, files: set[str], n_trials: int, path: Path):
    """Trial ``i``'s arrays of a per-trial trials file ``z`` (``"<i>/<field>"``), as a function of ``i``."""

    def arrays_of(i: int) -> dict:
        missing = [n for n in (*_ARRAYS, "x0") if f"{i}/{n}" not in files]
        if missing:
            raise InputError(f"trial {i} lacks arrays {missing}", path)
        return {n: z[f"{i}/{n}"] for n in (*_ARRAYS, "x0")}

    return arrays_of


def _packed(z, files: set[str], n_trials: int, path: Path):
    """Trial ``i``'s arrays of a packed trials file ``z`` (read once, checked against ``n_samples``), as a
    function of ``i``."""
    missing = [n for n in (*_ARRAYS, "x0", "n_samples") if n not in files]
    if missing:
        raise InputError(f"packed trials file lacks arrays {missing}", path)
    counts = z["n_samples"]
    if counts.shape != (n_trials,) or counts.dtype.kind not in "iu" or np.any(counts < 0):
        raise InputError(f"n_samples must be {n_trials} counts (one per trial), got {brief(counts)}", path)
    total = int(counts.sum())
    cols = {n: z[n] for n in (*_ARRAYS, "x0")}
    for n, shape in (("t", (total,)), *((n, (total, 2)) for n in _ARRAYS[1:]), ("x0", (n_trials, 4))):
        if cols[n].shape != shape:
            rows = "one row per trial" if n == "x0" else "n_samples' sum of rows"
            raise InputError(f"array {n} has shape {cols[n].shape}, expected {shape} ({rows})", path)
    starts = np.concatenate([[0], np.cumsum(counts)]).tolist()
    return lambda i: {n: cols[n][starts[i] : starts[i + 1]] for n in _ARRAYS} | {"x0": cols["x0"][i]}


def _arm_in_file(d: dict, arms: dict) -> ArmModel:
    """A trial's arm from its entry in a trials file (the same object as an earlier trial's with the same entry,
    kept in ``arms``): the arm's own refusal (a length in millimetres) is an :class:`InputError`, for
    :func:`_trial_in_file` to name the file and the trial."""
    key = tuple(d.items())
    if key not in arms:
        try:
            arms[key] = ArmModel.from_dict(d)
        except ValueError as e:
            raise InputError(str(e)) from None
    return arms[key]


def _trial_in_file(path: Path, i: int, meta: dict, make) -> Trial:
    """``make()``, a trial of the file ``path``; its errors name that file and the trial (not the recording
    the trial was once made from, which its ``source`` holds)."""
    try:
        return make()
    except InputError as e:
        ident = "/".join(str(meta.get(k, "?")) for k in ("subject", "posture", "side", "trial_id"))
        raise InputError(e.reason, path, f"trial {i} ({ident})") from None


def _check_entries(path: Path) -> None:
    """A trials file's zip entries are unique (zip allows a name twice, and numpy would read only the last)."""
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    seen: set[str] = set()
    for n in names:
        if n in seen:
            raise InputError(f"entry {n} appears twice in the archive; which one holds the trial is ambiguous", path)
        seen.add(n)


def select_trials(
    trials: Sequence[Trial],
    *,
    subjects: Sequence[str] | None = None,
    postures: Sequence[str] | None = None,
    sides: Sequence[str] | None = None,
    path: object | None = None,
) -> list[Trial]:
    """The trials of the given subjects, postures and arms (``None``: any), in their order.

    A value that none of the trials left by the choices before it has (subject, then posture, then side) raises
    :class:`InputError` naming ``path`` (the trials file) and what those trials hold, so the result is never
    empty. A single name (``subjects="S01"``) is that one name, and a value is compared as text, as a trial holds
    it (``postures=[2]`` is posture ``"2"``)."""
    out, applied = list(trials), []
    for field_name, values in (("subject", subjects), ("posture", postures), ("side", sides)):
        if values is None:
            continue
        if isinstance(values, str) or not isinstance(values, Iterable):
            values = [values]
        wanted = list(dict.fromkeys(str(v) for v in values))
        have = sorted({getattr(t, field_name) for t in out})
        unknown = [v for v in wanted if v not in have]
        if unknown:
            among = f" among those of {' and '.join(applied)}" if applied else ""
            shown = ", ".join(h if h else "''" for h in have)
            raise InputError(
                f"no trial of {field_name} {', '.join(unknown)}{among}; they have {field_name} {shown}", path
            )
        out = [t for t in out if getattr(t, field_name) in wanted]
        applied.append(f"{field_name} {', '.join(wanted)}")
    return out


def trial_from_knots(
    arm: ArmModel,
    t: np.ndarray,
    q: np.ndarray,
    target_x: float,
    subject: str = "virtual",
    posture: str = "",
    trial_id: str = "0",
    side: str = "right",
    source: str = "",
) -> Trial:
    """A trial from a knot path ``q (N+1, 2)`` at times ``t``, read as the DOC reads it: Euler velocities
    ``q̇_k = (q_k − q_{k−1})/dt`` (0 at the start), Euler accelerations, inverse-dynamics torques.

    For a DOC solution these are exactly its own velocities and torques (used for virtual subjects and tests).
    """
    try:
        t, q = np.asarray(t, dtype=float), np.asarray(q, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"trial_from_knots: t and q must be numbers ({e})") from None
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"trial_from_knots: t must be a 1-D array of at least 3 times, got shape {t.shape}")
    if q.shape != (t.size, 2):
        raise ValueError(f"trial_from_knots: q must have shape ({t.size}, 2), one (q1, q2) per time, got {q.shape}")
    dt = np.diff(t)[:, None]
    qd = np.vstack([np.zeros(2), np.diff(q, axis=0) / dt])
    qdd = np.diff(qd, axis=0) / dt
    qdd = np.vstack([qdd, qdd[-1:]])
    return Trial(
        subject=subject,
        posture=posture,
        trial_id=trial_id,
        t=t,
        q=q,
        qd=qd,
        qdd=qdd,
        tau=arm.inverse_dynamics(q, qd, qdd),
        target_x=target_x,
        arm=arm,
        side=side,
        source=source,
    )


def trial_from_solution(
    sol,
    arm: ArmModel,
    target_x: float,
    subject: str = "virtual",
    posture: str = "",
    trial_id: str = "0",
    side: str = "right",
    source: str = "",
) -> Trial:
    """A trial holding a DOC solution's trajectory: its torque on every interval is ``sol.tau`` exactly."""
    return trial_from_knots(arm, sol.t, sol.q, target_x, subject, posture, trial_id, side, source)
