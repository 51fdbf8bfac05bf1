"""The learned-model file (``MODEL.json``) that ``fit`` writes and ``evaluate``, ``plot`` and ``simulate`` read:
the model, its one loader (which checks the file field by field before building the model), and its
predictions of trials."""

from __future__ import annotations

import itertools
import math
import zipfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ..data.trial import Trial
from ..doc import DocSolution, ReachingTask
from ..doc.evaluation import TrialError, evaluate_trials
from ..doc.observation import predict_reach
from ..errors import InputError
from ..features import FEATURES, N_FEATURES, cost_shares
from ..io import atomic_write_json, read_json, to_jsonable
from ..validation import brief, check_file_size, check_n_nodes, not_real, require

__all__ = ["MODEL_FORMAT", "LearnedModel", "check_model_dict", "load_model", "save_model"]

MODEL_FORMAT = "reachirl-model/1"
#: a MODEL.json is a few kB (a history and a rollout at most a few MB); a larger file is not one
MAX_MODEL_BYTES = 64 * 1024**2


#: the types :func:`_read_only` and :func:`_plain` return as they are, tested first (a model holds many of them)
_LEAVES = frozenset({float, int, str, bool, type(None)})


def _read_only(obj):
    """``obj`` (JSON-like) as a read-only copy: each mapping a :class:`types.MappingProxyType`, each list, tuple
    or array a tuple, of read-only values; anything else as it is."""
    if type(obj) in _LEAVES:
        return obj
    if isinstance(obj, Mapping):
        return MappingProxyType({k: _read_only(v) for k, v in obj.items()})
    if isinstance(obj, np.ndarray):
        return _read_only(obj.tolist())
    if isinstance(obj, list | tuple):
        return tuple(_read_only(v) for v in obj)
    return obj


def _plain(obj):
    """A :func:`_read_only` value as a plain, mutable copy: mappings as dicts, tuples as lists."""
    if type(obj) in _LEAVES:
        return obj
    if isinstance(obj, Mapping):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj


@dataclass(frozen=True, eq=False)  # its own __eq__; unhashable (dataclass(eq=True) replaced __hash__ = None)
class LearnedModel:
    """Weights ``(n_windows, 7)`` (columns in FEATURES order), the DOC discretisation they were learned on, and
    free-form provenance (method, hyperparameters, history, training trials).

    The model is read-only throughout: ``weights`` is a read-only array, and ``info`` and ``uncertainty`` are
    read-only copies of what was given (each mapping a :class:`types.MappingProxyType`, each list a tuple), so
    that a model changes only by :func:`dataclasses.replace`, which checks the new one (e.g.
    ``replace(model, info={**model.info, "note": "..."})``). :meth:`to_dict` gives plain, mutable copies."""

    weights: np.ndarray
    n_nodes: int = 100
    method: str = "moirl"
    info: Mapping = field(default_factory=dict)
    uncertainty: Mapping | None = None  # weight samples and share intervals (reachirl.irl.uncertainty)

    def __post_init__(self) -> None:
        if (what := not_real(self.weights)) is not None:
            raise ValueError(f"weights must be real numbers, got {what}")
        w = np.asarray(self.weights, dtype=float)
        if w.ndim != 2 or w.shape[1] != N_FEATURES:
            raise ValueError(f"weights must have shape (n_windows, {N_FEATURES}), got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("weights must be finite and >= 0")
        w = w.copy()  # the model's own, read-only: the caller's array (an estimator's weights_) changed later, or
        w.setflags(write=False)  # the model's changed in place, would change a frozen model past these checks
        object.__setattr__(self, "weights", w)
        # read-only copies: the caller's dict changed later, or the model's changed in place, would change a frozen
        # model past the checks below
        object.__setattr__(self, "info", _read_only(self.info))
        object.__setattr__(self, "uncertainty", _read_only(self.uncertainty))
        # what load_model would refuse is refused here, so that a model saved is a model that loads
        check_model_dict(to_jsonable(self.to_dict()), "LearnedModel")

    def __eq__(self, other: object) -> bool:
        """Field by field, the weights by value (dataclass equality raised numpy's "truth value of an array ... is
        ambiguous" for two models of the same file)."""
        if other.__class__ is not self.__class__:
            return NotImplemented
        rest = ("n_nodes", "method", "info", "uncertainty")
        return np.array_equal(self.weights, other.weights) and all(getattr(self, k) == getattr(other, k) for k in rest)

    __hash__ = None  # unhashable, as a DocSolution is: equal by the value of its weights array

    def __reduce__(self):
        """Pickling and :mod:`copy` rebuild the model from plain copies (a ``MappingProxyType`` is not
        picklable)."""
        return type(self), (self.weights, self.n_nodes, self.method, _plain(self.info), _plain(self.uncertainty))

    def __repr__(self) -> str:
        """The weights, discretisation and method, with ``info`` and ``uncertainty`` summarised: in full (a
        history, a rollout, hundreds of weight samples) they made a repr of over 100,000 characters, which a
        notebook printed whole for ``load_model(path)``."""
        unc = self.uncertainty
        unc = "None" if unc is None else f"<{len(unc.get('weight_samples') or ())} weight samples>"
        return (
            f"LearnedModel(weights={self.weights!r}, n_nodes={self.n_nodes!r}, method={self.method!r}, "
            f"info=<{len(self.info)} keys>, uncertainty={unc})"
        )

    @classmethod
    def from_estimator(cls, est, trials: Sequence = ()) -> LearnedModel:
        """The model of a fitted estimator (MOIRL or a baseline), as ``reachirl fit`` writes it: with its
        provenance in ``info`` (:func:`reachirl.irl.provenance.estimator_info`), among which ``observe`` and
        ``rollout_q``, without which the model would predict unlike the estimator (uncut, from a cold start).
        The record names the trials the estimator was fitted on (their ids and fingerprint:
        :meth:`~reachirl.irl.base.WeightEstimator.fitted_trials`); ``trials``, when given, must be those, in the
        order fit took them (a ``ValueError`` otherwise: a record of other trials would misstate the fit)."""
        from .methods import METHODS
        from .provenance import estimator_info, fingerprint

        method = next((name for name, c in METHODS.items() if type(est) is c), None)
        if method is None:
            raise ValueError(f"not an estimator of reachirl.irl.methods.METHODS: {type(est).__name__}")
        est = est._as_fitted()  # as it was fitted: set_params since changes the next fit only
        # the sequence fit took (one Trial or a file name failed inside as "'Trial' object is not iterable")
        if isinstance(trials, Trial | str | PathLike) or not isinstance(trials, Iterable):
            raise TypeError(
                f"trials must be the sequence of Trial the estimator was fitted on, got a {type(trials).__name__}"
            )
        trials = list(trials)
        bad = next((t for t in trials if not isinstance(t, Trial)), None)
        if bad is not None:
            raise TypeError(
                f"trials must be the sequence of Trial the estimator was fitted on, got a {type(bad).__name__} in it"
            )
        fitted = est.fitted_trials()  # empty: fitted by a version that kept no record, which trials then gives
        if fitted and not trials:
            trials = list(fitted)
        elif fitted and (
            len(trials) != len(fitted)
            or any(a is not b and fingerprint([a]) != fingerprint([b]) for a, b in zip(trials, fitted, strict=True))
        ):
            raise ValueError(
                f"trials must be the {len(fitted)} the estimator was fitted on (the first {fitted[0].id!r}), in that "
                f"order; got {len(trials)} (the first {trials[0].id!r}): leave trials out to record the fit's own"
            )
        info = estimator_info(est, method, trials)
        unc = info.pop("uncertainty", None)
        return cls(weights=est.weights_, n_nodes=est.n_nodes, method=method, info=info, uncertainty=unc)

    def to_dict(self) -> dict:
        """The MODEL.json content (:func:`save_model` writes it), with ``info`` and ``uncertainty`` as plain,
        mutable copies (dicts and lists)."""
        return {
            "format": MODEL_FORMAT,
            "method": self.method,
            "n_windows": self.n_windows,
            "n_nodes": self.n_nodes,
            "features": list(FEATURES),
            "weights": self.weights,
            "info": _plain(self.info),
            **({} if self.uncertainty is None else {"uncertainty": _plain(self.uncertainty)}),
        }

    @property
    def n_windows(self) -> int:
        return self.weights.shape[0]

    @property
    def observe(self) -> bool:
        """Whether the fit compared its rollouts as recorded (cut at the trials' speed threshold); its predictions
        are then cut the same way."""
        return bool(self.info.get("observe", False))

    @property
    def backend(self) -> str:
        """The DOC backend the fit solved with (``info["backend"]``; ``"casadi"`` when not recorded): the one its
        predictions use unless told otherwise."""
        return str(self.info.get("backend") or "casadi")

    @property
    def rollout_q(self) -> np.ndarray | None:
        """The fit's own reach ``(n_nodes + 1, 2)`` (rad), each prediction's cold start; None when not recorded."""
        r = self.info.get("rollout_q")
        return None if r is None else np.asarray(r, dtype=float)

    @property
    def reach_features(self) -> np.ndarray | None:
        """Φ ``(n_windows, 7)`` of the fit's own reach, on which its cost shares and their intervals are computed
        (:meth:`cost_shares`); None when not recorded."""
        phi = self.info.get("reach_features")
        return None if phi is None else np.asarray(phi, dtype=float)

    def cost_shares(self) -> np.ndarray | None:
        """Each feature's share of its window's cost on the fit's own reach, ``ω·Φ`` normalised per window
        ``(n_windows, 7)``: the shares ``uncertainty["share_intervals"]`` bracket; None without
        :attr:`reach_features`."""
        phi = self.reach_features
        return None if phi is None else cost_shares(self.weights, phi)

    def predict(
        self, trial_or_task: Trial | ReachingTask, backend: str | None = None, warm_start: DocSolution | None = None
    ) -> DocSolution:
        """The DOC prediction of one trial or task under this model, as the estimator that was saved predicts it
        (``predict`` of :class:`~reachirl.irl.base.WeightEstimator`): a trial cut at its speed threshold is
        predicted as it was recorded when the fit was (:attr:`observe`), each solve starts from :attr:`rollout_q`
        moved to the task, and a task is solved on the model's :attr:`n_nodes`; on ``backend`` (default: the
        fit's, :attr:`backend`)."""
        return predict_reach(
            trial_or_task,
            self.weights,
            self.n_nodes,
            self.observe,
            backend or self.backend,
            warm_start,
            self.rollout_q,
        )

    def evaluate(
        self, trials: Sequence, backend: str | None = None, on_trial: Callable[[TrialError], None] | None = None
    ) -> list[TrialError]:
        """Each trial predicted from its own start as the model was fitted (:attr:`observe`, from
        :attr:`rollout_q`), with its RMSE: :func:`reachirl.doc.evaluation.evaluate_trials` under this model, on
        ``backend`` (default: the fit's, :attr:`backend`)."""
        return evaluate_trials(
            self.weights,
            trials,
            n_nodes=self.n_nodes,
            backend=backend or self.backend,
            on_trial=on_trial,
            observe=self.observe,
            path=self.rollout_q,
        )


def save_model(path: str | Path, model: LearnedModel) -> Path:
    """Write ``model`` as MODEL.json at ``path`` (atomically); :func:`load_model` reads it back. An estimator is
    saved through :meth:`LearnedModel.from_estimator`."""
    if not isinstance(model, LearnedModel):
        raise TypeError(
            f"save_model takes a LearnedModel (LearnedModel.from_estimator(est)), got {type(model).__name__}"
        )
    atomic_write_json(path, model.to_dict())
    return Path(path)


def check_model_dict(d, path) -> None:
    """The content of a MODEL.json, field by field, before the model is built from it; raises
    :class:`~reachirl.errors.InputError` naming the file and the field."""
    require(isinstance(d, dict), f"expected a JSON object (a reachirl model), found a {type(d).__name__}", path)
    require(d.get("format") == MODEL_FORMAT, f"not a reachirl model file (expected format {MODEL_FORMAT!r})", path)
    feats = d.get("features")
    require(
        isinstance(feats, list) and all(isinstance(f, str) for f in feats),
        f"field 'features': expected a list of the {len(FEATURES)} feature names, found {brief(feats)}",
        path,
    )
    require(list(feats) == list(FEATURES), f"feature list {feats} differs from {list(FEATURES)}", path)
    if "n_nodes" in d:
        check_n_nodes(d["n_nodes"], path, "field 'n_nodes'")
    n_nodes = int(d.get("n_nodes", 100))
    w = d.get("weights")
    require(isinstance(w, list) and len(w) > 0, f"field 'weights': expected a list of rows, found {brief(w)}", path)
    # the messages of the loops below are made only for a value that fails (a model holds thousands of values)
    for i, row in enumerate(w):
        if not (
            isinstance(row, list)
            and len(row) == len(FEATURES)
            and all(isinstance(v, int | float) and not isinstance(v, bool) for v in row)
        ):
            raise InputError(f"field 'weights', row {i}: expected {len(FEATURES)} numbers, found {brief(row)}", path)
        for j, v in enumerate(row):
            if not (math.isfinite(float(v)) and float(v) >= 0):
                raise InputError(
                    f"field 'weights', row {i}, {FEATURES[j]}: expected a finite number >= 0, found {brief(v)}", path
                )
    require(
        any(float(v) > 0 for row in w for v in row),
        "field 'weights': all weights are zero, so the DOC would have no cost to minimise",
        path,
    )
    require(len(w) <= n_nodes, f"field 'weights': {len(w)} windows do not fit in n_nodes = {n_nodes} intervals", path)
    if "n_windows" in d:
        require(
            d["n_windows"] == len(w) and not isinstance(d["n_windows"], bool),
            f"field 'n_windows' = {brief(d['n_windows'])} but 'weights' has {len(w)} rows",
            path,
        )
    for key, typ, name in (("method", str, "a string"), ("info", dict, "an object")):
        if key in d:
            require(isinstance(d[key], typ), f"field '{key}': expected {name}, found {brief(d[key])}", path)
    if "method" in d:
        from .methods import METHODS  # the estimators import this module

        require(
            d["method"] in METHODS,
            f"field 'method': expected one of {', '.join(METHODS)}, found {brief(d['method'])}",
            path,
        )
    for key in ("observe", "seed_form"):  # seed_form names the method in figures' titles: "no" is not true
        flag = d.get("info", {}).get(key)
        require(
            flag is None or isinstance(flag, bool),
            f"field 'info.{key}': expected true or false, found {brief(flag)}",
            path,
        )
    backend = d.get("info", {}).get("backend")
    require(
        backend is None or backend in ("casadi", "crocoddyl"),
        f'field \'info.backend\': expected "casadi" or "crocoddyl", found {brief(backend)}',
        path,
    )
    rollout = d.get("info", {}).get("rollout_q")
    if rollout is not None:
        ok = (
            isinstance(rollout, list)
            and len(rollout) == n_nodes + 1
            and all(isinstance(r, list) and len(r) == 2 for r in rollout)
        )
        require(
            ok,
            f"field 'info.rollout_q': expected {n_nodes + 1} rows of 2 joint angles"
            + ("" if "n_nodes" in d else " (the field 'n_nodes' is missing: 100 knots assumed)")
            + f", found {brief(rollout if not isinstance(rollout, list) else f'{len(rollout)} rows')}",
            path,
        )
        for i, r in enumerate(rollout):
            if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in r):
                raise InputError(
                    f"field 'info.rollout_q', row {i}: expected 2 finite numbers (rad), found {brief(r)}", path
                )

    phi = d.get("info", {}).get("reach_features")
    if phi is not None:
        require(
            _is_matrix(phi, len(w), _weight),
            f"field 'info.reach_features': expected {len(w)} rows of {len(FEATURES)} finite numbers >= 0 (one per "
            f"window of 'weights'), found {brief(phi)}",
            path,
        )
    edges = d.get("info", {}).get("window_edges")
    if edges is not None:
        ok = isinstance(edges, list) and len(edges) == len(w) + 1
        ok = ok and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in edges)
        require(
            ok and all(b > a for a, b in itertools.pairwise(edges)),
            f"field 'info.window_edges': expected {len(w) + 1} increasing finite numbers (the windows' edges on the "
            f"recorded reach), found {brief(edges)}",
            path,
        )
    history = d.get("info", {}).get("history")
    require(
        history is None or (isinstance(history, list) and all(isinstance(h, dict) for h in history)),
        f"field 'info.history': expected a list of objects (one per iteration), found {brief(history)}",
        path,
    )
    for i, h in enumerate(history or []):  # what the convergence figure plots: a damaged entry drew an empty plot
        for key in ("iteration", "evaluation"):
            v = h.get(key)
            if not (v is None or (isinstance(v, int) and not isinstance(v, bool) and v >= 0)):
                raise InputError(
                    f"field 'info.history', entry {i}: '{key}' expected a whole number >= 0, found {brief(v)}", path
                )
        v = h.get("merit")
        if not (v is None or (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v))):
            raise InputError(
                f"field 'info.history', entry {i}: 'merit' expected a finite number or null, found {brief(v)}", path
            )
    _check_uncertainty(d.get("uncertainty"), len(w), path)


def _is_matrix(m, rows: int, ok) -> bool:
    """Whether ``m`` is ``rows`` lists of 7 values, each passing ``ok``."""
    return (
        isinstance(m, list)
        and len(m) == rows
        and all(isinstance(r, list) and len(r) == len(FEATURES) and all(ok(v) for v in r) for r in m)
    )


def _share(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and -1e-9 <= v <= 1 + 1e-9


def _weight(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v >= 0


def _check_uncertainty(unc, n_windows: int, path) -> None:
    """The ``uncertainty`` record's arrays, where present: the samples and the intervals, one row per window."""
    if unc is None:
        return
    require(isinstance(unc, dict), f"field 'uncertainty': expected an object or null, found {brief(unc)}", path)
    for key, ok, what in (("weight_samples", _weight, "numbers >= 0"), ("share_samples", _share, "shares in [0, 1]")):
        samples = unc.get(key)
        require(
            samples is None or (isinstance(samples, list) and all(_is_matrix(m, n_windows, ok) for m in samples)),
            f"field 'uncertainty.{key}': expected a list of {n_windows} × {len(FEATURES)} matrices of {what}, "
            f"found {brief(samples)}",
            path,
        )
    n = unc.get("n_samples")
    require(
        n is None or (isinstance(n, int) and not isinstance(n, bool) and n >= 0),
        f"field 'uncertainty.n_samples': expected a count >= 0, found {brief(n)}",
        path,
    )
    for key in ("weight_samples", "share_samples"):  # K samples, as n_samples says
        samples = unc.get(key)
        require(
            n is None or samples is None or len(samples) == n,
            f"field 'uncertainty.{key}': {len(samples or ())} samples, but 'uncertainty.n_samples' says {n}",
            path,
        )
    iv = unc.get("share_intervals")
    require(
        isinstance(iv, dict)
        and _is_matrix(iv.get("low"), n_windows, _share)
        and _is_matrix(iv.get("high"), n_windows, _share)
        and _is_matrix(iv.get("determined"), n_windows, lambda v: isinstance(v, bool))
        and ("learned" not in iv or _is_matrix(iv["learned"], n_windows, lambda v: isinstance(v, bool))),
        f"field 'uncertainty.share_intervals': expected an object with 'low', 'high' ({n_windows} × "
        f"{len(FEATURES)} shares), 'determined' and, if any, 'learned' ({n_windows} × {len(FEATURES)} booleans), "
        f"found {brief(iv)}",
        path,
    )


def load_model(path: str | Path) -> LearnedModel:
    """The model in the MODEL.json at ``path``, once the file's size and every field of its content are checked
    (:func:`check_model_dict`); any problem is an :class:`~reachirl.errors.InputError` naming the file."""
    p = Path(path)
    check_file_size(p, MAX_MODEL_BYTES)
    if p.is_file() and zipfile.is_zipfile(p):  # a trials file given as the model (the two swapped)
        raise InputError("not a reachirl model file: an NPZ archive such as a trials file, expected a MODEL.json", p)
    d = read_json(p)
    check_model_dict(d, p)
    try:
        return LearnedModel(
            weights=np.asarray(d["weights"], dtype=float),
            n_nodes=int(d.get("n_nodes", 100)),
            method=str(d.get("method", "moirl")),
            info=dict(d.get("info", {})),
            uncertainty=d.get("uncertainty") if isinstance(d.get("uncertainty"), dict) else None,
        )
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"malformed model ({e})", path) from None
