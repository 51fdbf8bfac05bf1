"""MO-IRL's method options: one frozen set, checked in one place.

:class:`MOIRL` takes a dozen parameters a researcher sets. Everything else about the method is an
:class:`Options` field: the defaults are reachirl's method (what ``reachirl fit``, ``reachirl reproduce`` and
``MOIRL()`` learn), :data:`SEED_FORM` is the seed paper's method exactly as written, and ``experimental``
(a mapping of field names to values, on the estimator or in a run file's ``[experimental]`` table) overrides
single fields. ``docs/method.md`` gives each departure from the paper with its evidence; ``docs/design-notes.md``
the measurements behind the variants that stay off.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from ..validation import not_real

__all__ = ["ROLLOUTS", "SEED_FORM", "Options", "departures", "resolve_options"]

ROLLOUTS = ("per_task", "per_demo", "mean")
"""``per_task``: one rollout per (subject, posture) of the demonstrations, from their mean start, target and
duration; ``per_demo``: one per demonstration; ``mean``: one for all of them (the seed's, for one task)."""


@dataclass(frozen=True)
class Options:
    """Every choice of the MO-IRL iteration that :class:`~reachirl.irl.moirl.MOIRL` does not take as a parameter.

    * ``observe``: rollouts of demonstrations cut at a fingertip-speed threshold are the rest-to-rest DOC seen
      between their own threshold crossings (:mod:`reachirl.doc.observation`); ``False``: the DOC over the trial's
      duration, at rest at both ends (the seed).
    * ``merit``: ``"normalised"`` divides each state channel by the demonstrations' spread; ``"state"`` is the
      seed's full-state error.
    * ``scaling``: ``"demo"`` solves the subproblem in normalised coordinates with a bounded multiplicative step
      (trust region ``max_ratio``); ``None`` is the seed's raw subproblem (``Δω ≥ −(1 − 10⁻³) ω``, ``β``).
    * ``beta``, ``w0``, ``alpha0``, ``shrink``, ``max_tries``: the seed's regulariser, initial weight and α
      line search.
    * ``min_step``: no DOC is solved for a try that moves no weight by this fraction; ``line_search_stop``: the
      search ends after a try no better than the longer one before it.
    * ``fallback`` (``"merit"`` or ``None``), ``fallback_tol``, ``merit_model`` (``"probes"`` or
      ``"gauss-newton"``): the step on a model of the merit when the likelihood's lowers none.
    * ``frozen_windows``: windows whose weights stay at ``ω₀`` (occlusion).
    * ``warm_newton``: the line search's warm solves (the same reach under new weights) by exact Newton on the
      knots from the previous solution (:mod:`reachirl.doc.newton`), fatrop where Newton cannot vouch for its
      answer (the CasADi backend); ``False``: every warm solve by fatrop.
    * Variants measured and kept off: ``smoothness`` (a number or ``"cv"``), ``cv_folds``, ``feature_cutoff``,
      ``memory``, ``use_gamma``, ``l1``, ``n_suffixes``, ``acceptance`` (``"merit"``, ``"either"``,
      ``"multimodal"``), ``armijo_c1``, ``curvature_c2``.
    """

    observe: bool = True
    merit: str = "normalised"
    scaling: str | None = "demo"
    beta: float = 1e-10
    w0: float = 0.05
    alpha0: float = 1.0
    shrink: float = 0.25
    max_tries: int = 10
    max_ratio: float = 10.0
    min_step: float = 1e-3
    line_search_stop: bool = True
    fallback: str | None = "merit"
    fallback_tol: float = 0.01
    merit_model: str = "probes"
    frozen_windows: tuple[int, ...] = ()
    smoothness: float | str = 0.0
    cv_folds: int = 3
    feature_cutoff: float | None = None
    memory: int | None = 1
    use_gamma: bool = True
    l1: float = 0.0
    n_suffixes: int = 0
    acceptance: str = "merit"
    armijo_c1: float = 1e-4
    curvature_c2: float = 0.9
    warm_newton: bool = True

    def __post_init__(self) -> None:
        for f in fields(self):  # a numpy scalar (np.True_, np.int64(5)) is the Python value it stands for
            if isinstance(v := getattr(self, f.name), np.generic):
                object.__setattr__(self, f.name, v.item())
        object.__setattr__(self, "frozen_windows", _window_indices(self.frozen_windows))
        _check(self)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def resolve_options(
    seed_form: bool = False, experimental: Mapping[str, Any] | None = None, defaults: Mapping[str, Any] | None = None
) -> Options:
    """The options of a fit: reachirl's method (or :data:`SEED_FORM`), then a class's ``defaults`` (MaxEnt keeps
    every trajectory), then ``experimental``. Unknown names raise ``ValueError`` naming the valid ones."""
    if seed_form not in (True, False):
        raise ValueError(f"seed_form must be True or False, got {seed_form!r}")
    base = SEED_FORM if seed_form else Options()
    changes = {**dict(defaults or {}), **dict(experimental or {})}
    for key in ("fallback", "feature_cutoff", "memory", "scaling"):  # TOML has no null: "" stands for None
        if changes.get(key) == "":
            changes[key] = None
    unknown = sorted(set(changes) - set(FIELDS))
    if unknown:
        raise ValueError(f"unknown experimental option(s) {', '.join(unknown)}; valid: {', '.join(FIELDS)}")
    return replace(base, **changes) if changes else base


def departures(options: Options, rollout: str, tol: float, method_defaults: Mapping | None = None) -> list[str]:
    """Each way the fit's method departs from the seed paper's, in words (empty for the seed's form).
    ``method_defaults``: the options that define a method built on MO-IRL's iteration (MaxEnt's ``memory=None``),
    which are that method, not a departure of the fit."""
    out = []
    if options.observe:
        out.append(
            "observed rollouts: each rollout is the rest-to-rest DOC seen between its own crossings of the "
            "demonstrations' onset threshold, as they were recorded"
        )
    if options.merit == "normalised":
        out.append("normalised merit: each state channel divided by the demonstrations' spread")
    if options.scaling == "demo":
        out.append(
            f"scale-free steps: the subproblem in normalised coordinates, a multiplicative step with a trust "
            f"region of at most x{options.max_ratio:g} per iteration; ω₀ = {options.w0:g} and β in those "
            f"coordinates (the weights start with every feature at the same share of each window's demonstrated "
            f"cost, not at {options.w0:g} each; β weighs the log-step)"
        )
    if options.fallback == "merit":
        out.append(
            f"merit fallback: when the likelihood's step lowers no merit, a step on a {options.merit_model} "
            f"model of the merit, accepted if it gains {100 * options.fallback_tol:g} %"
        )
    if tol > 0:
        out.append(f"acceptance threshold: a step must lower the merit by more than {tol:g} (relative)")
    if options.min_step > 0 or options.line_search_stop:
        out.append(
            "shorter line search: no solve for a try that moves no weight by "
            f"{100 * options.min_step:g} %, and the search ends after a try no better than the longer one"
        )
    if rollout == "per_task":
        out.append("one rollout per task (subject, posture) from the task's mean start, target and duration")
    elif rollout == "per_demo":
        out.append("one rollout per demonstration, from its own start, target and duration")
    base = replace(Options() if options.scaling == "demo" else SEED_FORM, **dict(method_defaults or {}))
    for name in (
        "smoothness",
        "feature_cutoff",
        "memory",
        "use_gamma",
        "l1",
        "n_suffixes",
        "acceptance",
        "frozen_windows",
        "warm_newton",
    ):
        if getattr(options, name) != getattr(base, name):
            out.append(f"experimental {name} = {getattr(options, name)!r}")
    return out


def check_windows(options: Options, n_windows: int) -> None:
    """The options that name windows against a fit of ``n_windows``: ``ValueError`` naming the option."""
    frozen = sorted(set(options.frozen_windows))
    if any(k >= n_windows for k in frozen):
        raise ValueError(f"frozen_windows {frozen} must be windows 0 to {n_windows - 1}")
    if len(frozen) == n_windows:
        raise ValueError(f"frozen_windows {frozen} freezes all {n_windows} window(s): no weight is left to learn")


_INTEGERS = ("memory", "max_tries", "cv_folds", "n_suffixes")
_NUMBERS = (
    "fallback_tol",
    "shrink",
    "armijo_c1",
    "curvature_c2",
    "w0",
    "alpha0",
    "beta",
    "max_ratio",
    "min_step",
    "smoothness",
    "feature_cutoff",
    "l1",
    *_INTEGERS,
)
"""The options that take a number (``_INTEGERS``: a whole one)."""


def _check(o: Options) -> None:
    """Every option's range; ``ValueError`` names the option, the expected values and the value given."""

    def need(ok: bool, msg: str) -> None:
        if not ok:
            raise ValueError(msg)

    for name in _NUMBERS:  # a boolean passes as 0 or 1 in a comparison, and "got True" does not say what is wrong
        v = getattr(o, name)
        kind = "an integer" if name in _INTEGERS else "a number"
        need(not isinstance(v, bool | np.bool_), f"{name} must be {kind}, not a boolean (got {v!r})")
        # text is no number ("0.05" would pass float() and then fail a comparison); smoothness may be "cv"
        need(not isinstance(v, str) or name == "smoothness", f"{name} must be {kind}, not text (got {v!r})")
    need(isinstance(o.observe, bool), f"observe must be True or False, got {o.observe!r}")
    need(isinstance(o.warm_newton, bool), f"warm_newton must be True or False, got {o.warm_newton!r}")
    need(o.merit in ("state", "normalised"), f"merit must be 'state' or 'normalised', got {o.merit!r}")
    need(o.scaling in ("demo", None), f"scaling must be 'demo' or None, got {o.scaling!r}")
    need(o.fallback in ("merit", None), f"fallback must be 'merit' or None, got {o.fallback!r}")
    need(
        o.merit_model in ("gauss-newton", "probes"),
        f"merit_model must be 'gauss-newton' or 'probes', got {o.merit_model!r}",
    )
    need(
        o.acceptance in ("merit", "either", "multimodal"),
        f"acceptance must be 'merit', 'either' or 'multimodal', got {o.acceptance!r}",
    )
    need(_finite(o.fallback_tol) and 0 <= o.fallback_tol < 1, f"fallback_tol must be in [0, 1), got {o.fallback_tol}")
    need(
        not (o.scaling == "demo" and (not o.use_gamma or o.l1)),
        "use_gamma=False and l1 apply to the seed's raw form only: pass scaling=None",
    )
    need(
        not (o.observe and o.acceptance == "multimodal"),
        "acceptance='multimodal' compares whole rollouts' torques: not with observe=True",
    )
    need(
        o.memory is None or (_integer(o.memory) and o.memory >= 1),
        f"memory must be >= 1 or None, got {o.memory}",
    )
    need(_finite(o.shrink) and 0 < o.shrink < 1, f"shrink must be in (0, 1), got {o.shrink}")
    need(
        _finite(o.armijo_c1) and _finite(o.curvature_c2) and 0 < o.armijo_c1 < o.curvature_c2 < 1,
        f"need 0 < armijo_c1 < curvature_c2 < 1 (Wolfe conditions), got {o.armijo_c1} and {o.curvature_c2}",
    )
    need(_integer(o.max_tries) and o.max_tries >= 1, f"max_tries must be an integer >= 1, got {o.max_tries}")
    need(_finite(o.w0) and o.w0 > 0, f"need w0 > 0 (weights stay > 0), got {o.w0}")
    need(_finite(o.alpha0) and 0 < o.alpha0 <= 1, f"need 0 < alpha0 <= 1, got {o.alpha0}")
    need(_finite(o.beta) and o.beta >= 0, f"beta must be >= 0, got {o.beta}")
    need(_finite(o.max_ratio) and o.max_ratio > 1, f"max_ratio must be > 1, got {o.max_ratio}")
    need(_finite(o.min_step) and 0 <= o.min_step < 1, f"min_step must be in [0, 1), got {o.min_step}")
    need(isinstance(o.line_search_stop, bool), f"line_search_stop must be True or False, got {o.line_search_stop!r}")
    need(all(k >= 0 for k in o.frozen_windows), f"frozen_windows must be window indices >= 0, got {o.frozen_windows}")
    if isinstance(o.smoothness, str):
        need(o.smoothness == "cv", f"smoothness must be a number >= 0 or 'cv', got {o.smoothness!r}")
    else:
        need(
            _finite(o.smoothness) and o.smoothness >= 0,
            f"smoothness must be a number >= 0 or 'cv', got {o.smoothness!r}",
        )
    need(_integer(o.cv_folds) and o.cv_folds >= 2, f"cv_folds must be >= 2 (an integer), got {o.cv_folds}")
    need(
        o.feature_cutoff is None or (_finite(o.feature_cutoff) and o.feature_cutoff > 0),
        f"feature_cutoff must be a frequency > 0 (Hz) or None, got {o.feature_cutoff}",
    )
    need(_integer(o.n_suffixes) and o.n_suffixes >= 0, f"n_suffixes must be an integer >= 0, got {o.n_suffixes}")
    need(_finite(o.l1) and o.l1 >= 0, f"l1 must be >= 0, got {o.l1}")
    need(isinstance(o.use_gamma, bool), f"use_gamma must be True or False, got {o.use_gamma!r}")


def _window_indices(v) -> tuple[int, ...]:
    """``frozen_windows`` as a tuple of ints: a boolean (``[true, 1]`` of a run file) or a fraction among them is
    refused, not cast to 1 or truncated."""
    ks = [k.item() if isinstance(k, np.generic) else k for k in v] if isinstance(v, Iterable | np.ndarray) else v
    what = repr(v) if isinstance(v, str) or ks is v else not_real(ks)
    if what is None and not all(_integer(k) for k in ks):
        what = repr(ks)
    if what is not None:
        raise ValueError(f"frozen_windows must be a list of window indices (integers), got {what}")
    return tuple(ks)


def _integer(x) -> bool:
    """An int (a boolean is none)."""
    return isinstance(x, int | np.integer) and not isinstance(x, bool)


def _finite(x) -> bool:
    """A finite real number (a boolean is none: ``beta = true`` is no weight)."""
    if isinstance(x, bool | np.bool_):
        return False
    try:
        return bool(np.isfinite(float(x)))
    except (TypeError, ValueError):
        return False


SEED_FORM = Options(observe=False, merit="state", scaling=None, min_step=0.0, line_search_stop=False, fallback=None)
"""The seed paper's MO-IRL as written: the raw subproblem with ``β``, ``ω₀ = 0.05``, the α search (1, ×0.25,
10 tries) accepting any fall of the full-state merit, no other step, the DOC over each trial's duration."""

FIELDS = tuple(f.name for f in fields(Options))
