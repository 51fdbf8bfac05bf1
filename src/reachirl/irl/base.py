"""What every learner of DOC weights shares: scikit-learn-style parameters, the checks on its demonstrations,
and prediction by the DOC under the learned weights."""

from __future__ import annotations

import contextlib
import contextvars
import copy
import inspect
import logging
from collections.abc import Iterable, Iterator, Sequence
from os import PathLike

import numpy as np

from ..data.checks import check_start_and_target, check_trial_moves, check_trial_physics
from ..data.trial import Trial
from ..doc import BACKENDS, DocSolution, ReachingTask, observation
from ..errors import NotFittedError
from ..validation import check_n_nodes

__all__ = ["WeightEstimator", "caller_shows_fit_warnings", "log_fit_warning"]

_CALLER_SHOWS = contextvars.ContextVar("reachirl_caller_shows_fit_warnings", default=False)


@contextlib.contextmanager
def caller_shows_fit_warnings() -> Iterator[None]:
    """Within it (in this thread or task), a fit logs none of the warnings it records in ``warnings_``: the caller
    shows each of them itself, once (``reachirl fit`` after the fit, ``reachirl reproduce`` in its closing list of
    the units' warnings), so that none is said twice. Its other log messages (a failed solve) are logged."""
    token = _CALLER_SHOWS.set(True)
    try:
        yield
    finally:
        _CALLER_SHOWS.reset(token)


def log_fit_warning(logger: logging.Logger, msg: str) -> None:
    """Log ``msg``, a warning the fit also records in its ``warnings_``, unless the caller shows those itself
    (:func:`caller_shows_fit_warnings`)."""
    if not _CALLER_SHOWS.get():
        logger.warning(msg)


class WeightEstimator:
    """Base of MOIRL and the baselines. Subclasses store ``n_windows``, ``n_nodes`` and ``backend`` in
    ``__init__`` and set ``weights_`` in ``fit(trials, y=None)`` (``y`` ignored, scikit-learn's signature).
    :meth:`predict` and :meth:`score` before ``fit`` raise :class:`~reachirl.errors.NotFittedError`."""

    n_windows: int
    n_nodes: int
    backend: str

    def get_params(self, deep: bool = True) -> dict:
        """The constructor's parameters and their values (over the class hierarchy); scikit-learn's signature
        (``deep`` changes nothing: no parameter is an estimator), so ``sklearn.base.clone`` works."""
        names: list[str] = []
        for cls in type(self).__mro__:
            if "__init__" in cls.__dict__ and cls is not object:
                for p in inspect.signature(cls.__init__).parameters.values():
                    if p.name != "self" and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL) and p.name not in names:
                        names.append(p.name)
        return {k: getattr(self, k) for k in names if hasattr(self, k)}

    def __repr__(self) -> str:
        """``MOIRL(n_windows=4, max_iter=5)``: the class and the parameters that differ from their defaults
        (scikit-learn's), not ``<... object at 0x...>``."""
        defaults: dict = {}
        for cls in type(self).__mro__:
            if "__init__" in cls.__dict__ and cls is not object:
                for p in inspect.signature(cls.__init__).parameters.values():
                    defaults.setdefault(p.name, p.default)
        changed = [
            f"{k}={v!r}"
            for k, v in self.get_params().items()
            if defaults.get(k, inspect.Parameter.empty) is inspect.Parameter.empty or not _same(v, defaults[k])
        ]
        return f"{type(self).__name__}({', '.join(changed)})"

    def __sklearn_tags__(self):
        """scikit-learn's tags, which its model selection reads from version 1.6 on (``cross_val_score``,
        ``GridSearchCV``, ``KFold`` splits of a list of trials refused every estimator here without them): neither
        a classifier nor a regressor, ``fit`` without ``y``, demonstrations that are :class:`Trial` objects checked
        by ``fit`` itself, not a 2-D array. Only scikit-learn calls it, so only it imports scikit-learn."""
        from sklearn.utils import InputTags, Tags, TargetTags

        return Tags(
            estimator_type=None,
            target_tags=TargetTags(required=False),
            input_tags=InputTags(two_d_array=False),
            no_validation=True,
        )

    def set_params(self, **params) -> WeightEstimator:
        """Set constructor parameters (scikit-learn style); an unknown name is a ``ValueError`` naming it."""
        known = self.get_params()
        for k, v in params.items():
            if k not in known:
                raise ValueError(f"unknown parameter {k!r} of {type(self).__name__}; valid: {', '.join(known)}")
            setattr(self, k, v)
        return self

    def _check_trials(self, trials: Sequence[Trial]) -> list[Trial]:
        self.__dict__.pop("_fit_params", None)  # a new fit: until it ends, the parameters in force are its own
        if isinstance(trials, Trial | str | PathLike) or not isinstance(trials, Iterable):
            raise TypeError(
                f"fit takes a sequence of Trial (a trials file is read by reachirl.data.trial.load_trials), "
                f"got a {type(trials).__name__}"
            )
        trials = list(trials)
        if not trials:
            raise ValueError("fit needs at least one demonstration")
        if not all(isinstance(t, Trial) for t in trials):
            raise TypeError("fit takes a sequence of Trial")
        self.__dict__["_next_trials"] = tuple(trials)  # the fit's own, once it ends (_keep_fit_params)
        for i, t in enumerate(trials):  # as load_trials checks a file's: angles in degrees, a start at 1e6 rad/s
            check_trial_physics(t, i, None)
            check_start_and_target(t, None, f"trial {i} ({t.id})")
            check_trial_moves(t, f"trial {i} ({t.id})")
        for name in ("n_windows", "n_nodes"):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or isinstance(v, bool):
                raise ValueError(f"{name} must be an integer, got {v!r}")
        # the estimator's own parameter, named as such (it was refused later as "ReachingTask: n_nodes ...")
        check_n_nodes(self.n_nodes, type(self).__name__)
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be 'casadi' or 'crocoddyl', got {self.backend!r}")
        if not 1 <= self.n_windows <= self.n_nodes:
            raise ValueError(f"n_windows must be in 1..n_nodes={self.n_nodes}, got {self.n_windows}")
        return trials

    def _check_fitted(self) -> None:
        if not hasattr(self, "weights_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit(trials) first")

    def _keep_fit_params(self) -> None:
        """Remember the parameters this fit ran with (at the end of ``fit``): :meth:`_as_fitted` predicts and
        describes the fit with them, whatever ``set_params`` changes afterwards for the next fit."""
        # copies: a mapping or an array of the parameters changed in place after the fit is a change too
        self.__dict__["_fit_params"] = {k: v if callable(v) else copy.deepcopy(v) for k, v in self.get_params().items()}
        self.__dict__["_fit_trials"] = self.__dict__.pop("_next_trials", ())

    def fitted_trials(self) -> tuple[Trial, ...]:
        """The demonstrations the last successful ``fit`` learned from, in the order it was given them: the record
        a saved model keeps (:meth:`reachirl.irl.model.LearnedModel.from_estimator`)."""
        self._check_fitted()
        return self.__dict__.get("_fit_trials", ())

    def _as_fitted(self) -> WeightEstimator:
        """The fitted estimator with the parameters its fit ran with (scikit-learn style: ``set_params`` after
        ``fit`` changes the next fit, not this one's predictions): itself when they are unchanged, else a shallow
        copy holding them. Its predictions, its reach and the model saved from it are those of the fit."""
        self._check_fitted()
        params = self.__dict__.get("_fit_params")
        if params is None or all(_same(getattr(self, k, None), v) for k, v in params.items()):
            return self
        view = copy.copy(self)
        del view.__dict__["_fit_params"]
        view.__dict__.update(params)
        return view

    def reach_features(self) -> np.ndarray | None:
        """Φ ``(n_windows, 7)`` of the fit's own training reach under the learned weights (the mean over its
        rollouts), on which its cost shares ``ω·Φ`` are quoted, or ``None`` when the estimator keeps no such reach
        (then only the demonstrations' features are at hand). Not the demonstrations' Φ*: a recording's
        position noise inflates the features of second and third derivatives (joint acceleration, torque
        change) by up to two orders of magnitude, so shares on Φ* credit the weights with costs that hardly
        shape the reach they predict."""
        self._check_fitted()
        return None

    def rollout_path(self) -> np.ndarray | None:
        """The joint path ``(n_nodes + 1, 2)`` of the fit's own training rollouts under the learned weights (their
        mean), or ``None`` when the estimator has no converged rollout (KKT makes none). Predictions start cold
        from it, moved to each task (:func:`reachirl.doc.task.moved_path`)."""
        self._check_fitted()
        sols = [s for s in getattr(self, "train_solutions_", None) or () if s.converged]
        return np.mean([s.q for s in sols], axis=0) if sols else None

    def predict(self, trial_or_task: Trial | ReachingTask, warm_start: DocSolution | None = None) -> DocSolution:
        """The DOC prediction under the learned weights, from the trial's own arm, start, target and duration. An
        estimator with ``observe=True`` predicts a trial cut at a speed threshold as it was recorded
        (:mod:`reachirl.doc.observation`): the rest-to-rest DOC's own onset-to-offset part, on ``N + 1`` knots,
        whose ``cost`` is the whole DOC's optimum. A :class:`ReachingTask` is solved on the fit's ``n_nodes`` (its
        own are replaced: the weights' windows and the start path are on the fit's knots). Without
        ``warm_start`` the solve starts from :meth:`rollout_path`, moved to the task; a ``warm_start`` must be
        on the fit's knots (:func:`reachirl.doc.solve_doc` raises a ``ValueError`` otherwise)."""
        est = self._as_fitted()
        path = est.rollout_path() if warm_start is None else None
        observe = bool(getattr(est, "observe", False))
        return observation.predict_reach(
            trial_or_task, est.weights_, est.n_nodes, observe, est.backend, warm_start, path
        )

    def score(self, trials: Sequence[Trial], y=None) -> float:
        """How well the learned weights predict ``trials`` (higher is better, scikit-learn's convention): minus
        the mean joint-angle RMSE in degrees (the RMSE of q, both joints, each trial on the DOC's knots) of the
        trials whose prediction converged, as ``reachirl evaluate`` summarises it
        (:func:`reachirl.doc.evaluation.summarise`): ``-2.5`` for a mean RMSE of 2.5°. A prediction whose DOC
        failed is no answer of the model and is left out; with none converged the score is ``-inf``, the worst
        (no trials at all is a ``ValueError``).
        Each trial is predicted as :meth:`predict` predicts it. ``y`` is ignored (scikit-learn's signature: the
        demonstrations are their own targets). For held-out trials, pass trials not fitted on."""
        from ..doc.evaluation import evaluate_trials, summarise

        if isinstance(trials, Trial | str | PathLike) or not isinstance(trials, Iterable):
            raise TypeError(f"score takes a sequence of Trial, got a {type(trials).__name__}")
        est = self._as_fitted()
        errors = evaluate_trials(
            est.weights_,
            trials,
            n_nodes=est.n_nodes,
            backend=est.backend,
            observe=bool(getattr(est, "observe", False)),
            path=est.rollout_path(),
        )
        if not errors:  # nothing to score is a mistake, not a model whose every prediction failed (-inf)
            raise ValueError("score needs at least one trial to predict, got none")
        mean = summarise(errors)["rmse_deg"]["q"]["mean"]
        return -float("inf") if mean is None else -float(mean)


def _same(a, b) -> bool:
    """Whether two parameter values are the same (arrays by their content)."""
    if a is b:
        return True
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.shape(a) == np.shape(b) and bool(np.array_equal(a, b))
    try:
        return bool(a == b) and type(a) is type(b)
    except (TypeError, ValueError):
        return False
