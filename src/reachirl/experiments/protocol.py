"""The seed paper's protocol (§II-D): per posture, learn from one subject, cross-validate, then ISCV.

For each initial posture and each number of weight sections:

* **training**: ``n_train`` trials of the training subject chosen at random (seeded; the same trials for every
  section count), learned by MO-IRL and predicted back;
* **CV**: the training subject's other trials of that posture (``cv="rest"``), or, for data with both arms
  (UE-ADL), its reaches with the other arm, already mirrored into the right-arm convention
  (``cv="other-side"``);
* **ISCV**: every trial of that posture of the other subjects (the seed: subject 2's 20 trials).

With ``iscv="all-pairs"`` every other subject is a training subject too, in extra units
(``Unit.train_subject``; :mod:`reachirl.experiments.pairs`), and ``n_iscv`` counts trials per test subject.

Every prediction is the DOC from the trial's own arm, initial state, target and duration
(:func:`reachirl.doc.evaluation.evaluate_trials`). A unit of work is one ``(method, posture, sections)``:
:func:`run_unit` is a pure function of the unit and its trials, so it gives the same numbers in any process.
"""

from __future__ import annotations

import functools
import hashlib
import json
import re
import time
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from ..data.trial import Trial
from ..doc import BACKENDS
from ..errors import InputError
from ..features import cost_shares
from ..validation import MAX_ITER, check_n_nodes, not_real
from .datasets import fingerprint

__all__ = [
    "SETS",
    "ProtocolConfig",
    "Split",
    "Unit",
    "fit_unit",
    "make_estimator",
    "make_units",
    "run_unit",
    "split_trials",
    "unit_payload",
]

SETS = ("train", "cv", "iscv")
SET_LABELS = {"train": "Training", "cv": "CV", "iscv": "ISCV"}
METHODS = ("moirl", "maxent", "bilevel", "kkt")
ISCV_MODES = ("one", "all-pairs")
RESULT_VERSION = 3  # bump when a unit's result changes for the same inputs (invalidates checkpoints)
# 3: model_info holds the keys of the unit's MODEL.json info (backend, unit, run)


@dataclass(frozen=True)
class ProtocolConfig:
    """Every choice of the protocol. ``None`` means "decide from the data" (see :func:`split_trials`)."""

    sections: tuple[int, ...] = (1, 6, 8)
    postures: tuple[str, ...] | None = None  # None: every posture of the data
    methods: tuple[str, ...] = ("moirl",)
    seed: int = 0
    train_subject: str | None = None  # None: the first subject (sorted ids)
    train_side: str | None = None  # None: either arm
    n_train: int | None = 10  # None: every trial of the training subject (and side)
    cv: str = "rest"  # "rest" | "other-side"
    n_cv: int | None = None  # None: all of them
    n_iscv: int | None = None  # None: all of them (per posture)
    n_nodes: int = 100
    max_iter: int = 30
    tol: float | None = None  # None: MOIRL's own (1e-4; 0 in the seed's form)
    backend: str = "casadi"
    iscv: str = "one"  # "one": learn from train_subject only | "all-pairs": learn from every subject in turn
    seed_form: bool = False  # the paper's MO-IRL exactly as written (reachirl.irl.options.SEED_FORM)
    rollout: str = "per_task"  # MO-IRL's rollouts (reachirl.irl.options.ROLLOUTS)
    experimental: dict = field(default_factory=dict)  # Options fields over the method's (reachirl.irl.options)
    uncertainty: int = 40  # weight samples per main MO-IRL fit (reachirl.irl.uncertainty); 0: none
    posture_transfer: bool = False  # also learn on every posture but one and predict the held-out one

    def __post_init__(self) -> None:
        # a single name or number is a sequence of one, as select_trials takes it: a bare string was taken letter
        # by letter (postures="P2" ran the postures "P" and "2"; methods="kkt" was an unknown method 'k'), a bare
        # number failed with a TypeError
        for name in ("sections", "postures", "methods"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, str | bytes) or not isinstance(v, Iterable)):
                object.__setattr__(self, name, (v,))
        if (what := not_real(list(self.sections))) is not None:
            raise InputError(f"--sections must be positive integers, got {what}")
        for name in ("seed", "n_train", "n_cv", "n_iscv", "n_nodes", "max_iter", "tol", "uncertainty"):
            if isinstance(getattr(self, name), bool | np.bool_):  # a results.json's "n_train": true is not 1
                raise InputError(f"{name} must be a number, got {getattr(self, name)!r}")
        # whole numbers by name: 1.5 sections were read as 1, a text count or a seed of -1 failed in the units
        if any(isinstance(s, float | np.floating) and not float(s).is_integer() for s in self.sections):
            raise InputError(f"--sections must be positive integers, got {list(self.sections)}")
        for name, lo, hi in (
            ("seed", 0, 2**32 - 1),
            ("max_iter", 1, MAX_ITER),
            ("n_train", 1, None),
            ("n_cv", 1, None),
            ("n_iscv", 1, None),
        ):
            v = getattr(self, name)
            if v is None and name.startswith("n_"):
                continue
            if not isinstance(v, int | np.integer) or v < lo or (hi is not None and v > hi):
                expected = f"in [{lo}, {hi}]" if hi is not None else f">= {lo}"
                raise InputError(f"{name} must be an integer {expected}, got {v!r}")
        object.__setattr__(self, "n_nodes", check_n_nodes(self.n_nodes))
        if self.backend not in BACKENDS:
            raise InputError(f"backend must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
        secs = tuple(int(s) for s in self.sections)
        if not secs or any(s < 1 for s in secs):
            raise InputError(f"--sections must be positive integers, got {list(self.sections)}")
        if any(s > self.n_nodes for s in secs):
            raise InputError(f"--sections {max(secs)} exceeds the {self.n_nodes} DOC intervals")
        object.__setattr__(self, "sections", tuple(dict.fromkeys(secs)))
        if self.iscv not in ISCV_MODES:
            raise InputError(f"--iscv must be one of {', '.join(ISCV_MODES)}, got {self.iscv!r}")
        from ..irl.options import ROLLOUTS, check_windows, resolve_options

        if self.rollout not in ROLLOUTS:
            raise InputError(f"rollout must be one of {', '.join(ROLLOUTS)}, got {self.rollout!r}")
        try:  # the method's options are checked where they are defined
            # the fewest windows is the strictest: an index they lack, or every one of them frozen
            check_windows(resolve_options(self.seed_form, self.experimental), min(secs))
        except (ValueError, TypeError) as e:
            raise InputError(f"experimental: {e}") from None
        for name in ("tol", "uncertainty"):  # a numpy number is the number it holds (seed, max_iter, ... took them)
            if isinstance(getattr(self, name), np.integer | np.floating):
                object.__setattr__(self, name, getattr(self, name).item())
        if self.tol is not None and not (isinstance(self.tol, int | float) and 0 <= self.tol < 0.5):
            raise InputError(f"tol must be a number in [0, 0.5), got {self.tol!r}")
        if not (isinstance(self.uncertainty, int) and (self.uncertainty == 0 or 20 <= self.uncertainty <= 1000)):
            raise InputError(
                f"uncertainty must be 0 (none) or a number of samples from 20 to 1000, got {self.uncertainty!r}"
            )
        if self.cv not in ("rest", "other-side"):
            raise InputError(f"cv must be 'rest' or 'other-side', got {self.cv!r}")
        for m in self.methods:
            if m not in METHODS:
                raise InputError(f"unknown method {m!r}; expected one of {', '.join(METHODS)}")
        if self.train_side not in (None, "right", "left"):
            raise InputError(f"train side must be right or left, got {self.train_side!r}")
        if self.postures is not None:
            object.__setattr__(self, "postures", tuple(self.postures))
        object.__setattr__(self, "methods", tuple(dict.fromkeys(self.methods)))

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Split:
    posture: str
    train: tuple[Trial, ...]
    cv: tuple[Trial, ...]
    iscv: tuple[Trial, ...]

    def sets(self) -> dict[str, tuple[Trial, ...]]:
        return {"train": self.train, "cv": self.cv, "iscv": self.iscv}

    @functools.cached_property
    def identity(self) -> dict[str, dict]:
        """Each set's trials as a unit's fingerprint records them: their :func:`fingerprint` (``"data"``) and ids
        (``"ids"``). Made once per split: every section count's unit asks for it, and a study's split holds
        hundreds of trials."""
        sets = self.sets()
        return {
            "data": {k: fingerprint(v) for k, v in sets.items()},
            "ids": {k: [t.id for t in v] for k, v in sets.items()},
        }


@dataclass(frozen=True)
class Unit:
    """One task: learn ``method`` with ``sections`` windows on ``split``'s training trials and evaluate."""

    method: str
    posture: str
    sections: int
    seed: int
    n_nodes: int
    max_iter: int
    tol: float
    backend: str
    estimator_options: tuple = ()  # sorted (key, value) pairs, hashable
    train_subject: str | None = None  # None: the protocol's training subject; else an all-pairs unit

    @property
    def key(self) -> str:
        if self.held_out_posture is not None:
            return f"{self.method}-xfer-{_safe(self.held_out_posture)}-s{self.sections}"
        key = f"{self.method}-{_safe(self.posture)}-s{self.sections}"
        return key if self.train_subject is None else f"{key}-t{_safe(self.train_subject)}"

    held_out_posture: str | None = None  # a posture-transfer unit: learn on every other posture, predict this one

    @property
    def observe(self) -> bool:
        """Whether the unit fits and predicts trials as they were recorded (its estimator's ``observe``)."""
        return unit_observes(self.method, self.estimator_options)

    @property
    def split_key(self):
        """The key of this unit's :class:`Split` in the ``splits`` mapping: the posture, (posture, subject), or
        ("xfer", held-out posture)."""
        if self.held_out_posture is not None:
            return ("xfer", self.held_out_posture)
        return self.posture if self.train_subject is None else (self.posture, self.train_subject)

    @property
    def is_main(self) -> bool:
        """Whether the unit is one of the main table's (not an all-pairs or posture-transfer unit)."""
        return self.train_subject is None and self.held_out_posture is None

    def fingerprint(self, split: Split) -> str:
        """What the unit's result depends on: its parameters and its trials."""
        payload = json.dumps(
            {
                "v": RESULT_VERSION,
                "code": code_fingerprint(self.method, self.backend),
                "unit": {
                    k: v
                    for k, v in asdict(self).items()
                    if not (k in ("train_subject", "held_out_posture") and v is None)
                },
                **split.identity,
            },
            sort_keys=True,
            default=str,
        )
        return hashlib.sha256(payload.encode()).hexdigest()[:16]


# Where a unit runs: what it imports, directly or not, is what its numbers depend on (:func:`code_fingerprint`).
_UNIT_ENTRIES = ("experiments/truth_solves.py", "experiments/protocol.py")
_RELATIVE_IMPORT = re.compile(r"^[ \t]*from[ \t]+(\.+)([\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#]+)", re.M)
_PACKAGE_ROOT = Path(__file__).resolve().parent.parent


def source_closure(entries: Iterable[str], skip: Iterable[str] = ()) -> list[str]:
    """reachirl's modules (paths below the package, e.g. ``"doc/newton.py"``) that the modules ``entries`` import
    by relative imports, at the top or inside a function, directly or through each other, with their packages'
    ``__init__.py``; none whose path starts with one of ``skip``."""
    skip = tuple(skip)
    seen: set[str] = set()
    todo = list(entries)
    while todo:
        rel = todo.pop()
        if rel in seen or rel.startswith(skip) or not (_PACKAGE_ROOT / rel).is_file():
            continue
        seen.add(rel)
        pkg = PurePosixPath(rel).parent
        todo += [f"{p}/__init__.py" for p in (pkg, *pkg.parents) if str(p) != "."]
        for dots, module, names in _RELATIVE_IMPORT.findall((_PACKAGE_ROOT / rel).read_text(encoding="utf-8")):
            base = pkg
            for _ in range(len(dots) - 1):
                base = base.parent
            target = base.joinpath(*module.split(".")) if module else base
            names = re.sub(r"#[^\n]*", "", names).strip("()")  # a parenthesised list may hold comments
            for sub in ["", *(n.split(" as ")[0].strip() for n in names.split(","))]:
                path = target / sub if sub else target
                todo += [f"{path}.py", f"{path}/__init__.py"]
    return sorted(seen)


def sources_hash(names: Iterable[str]) -> str:
    """A hash of the modules ``names`` (paths below the package), each its path and its source, in that order."""
    h = hashlib.sha256()
    for name in names:
        h.update(name.encode())
        h.update((_PACKAGE_ROOT / name).read_bytes())
    return h.hexdigest()[:16]


def source_fingerprint(entries: Iterable[str], skip: Iterable[str] = ()) -> str:
    """:func:`sources_hash` of :func:`source_closure` ``(entries, skip)``: any edit to a module they use changes it."""
    return sources_hash(source_closure(entries, skip))


@functools.lru_cache(maxsize=16)
def code_fingerprint(method: str = "moirl", backend: str = "casadi") -> str:
    """A hash of the source of every module a unit's result depends on (:func:`source_closure` of the modules a
    unit runs in), so that a checkpoint made by other code is not reused. Left out: the other DOC backends' modules
    (CasADi's stays: the uncertainty's sensitivities use it), the data sets' loaders (a unit's trials enter by their
    own fingerprint) and, for MO-IRL, the baselines'."""
    skip = ["experiments/datasets.py", *(f"doc/{b}" for b in BACKENDS if b not in (backend, "casadi"))]
    if method == "moirl":
        skip.append("irl/baselines/")
    return source_fingerprint(_UNIT_ENTRIES, skip)


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def _rng(seed: int, posture: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(posture.encode())]))


def _pick(trials: list[Trial], n: int | None, rng: np.random.Generator) -> tuple[list[Trial], list[Trial]]:
    """``n`` trials at random (kept in file order) and the rest."""
    if n is None or n >= len(trials):
        return list(trials), []
    idx = np.sort(rng.choice(len(trials), size=int(n), replace=False))
    chosen = set(idx.tolist())
    return [trials[i] for i in idx], [t for i, t in enumerate(trials) if i not in chosen]


def resolve_postures(trials: Sequence[Trial], config: ProtocolConfig) -> list[str]:
    available = sorted({t.posture for t in trials})
    if config.postures is None:
        return available
    unknown = [p for p in config.postures if p not in available]
    if unknown:
        raise InputError(f"unknown posture(s) {', '.join(unknown)}; the data have {', '.join(available)}")
    return list(config.postures)


def resolve_train_subject(trials: Sequence[Trial], config: ProtocolConfig) -> str:
    subjects = sorted({t.subject for t in trials})
    if config.train_subject is None:
        return subjects[0]
    if config.train_subject not in subjects:
        raise InputError(f"unknown training subject {config.train_subject!r}; the data have {', '.join(subjects)}")
    return config.train_subject


def split_trials(trials: Sequence[Trial], posture: str, config: ProtocolConfig) -> Split:
    """The training / CV / ISCV trials of one posture (the same for every section count and method)."""
    subject = resolve_train_subject(trials, config)
    rng = _rng(config.seed, posture)
    mine = [t for t in trials if t.posture == posture and t.subject == subject]
    others = [t for t in trials if t.posture == posture and t.subject != subject]
    if config.cv == "other-side":
        side = config.train_side or "right"
        pool = [t for t in mine if t.side == side]
        train, _ = _pick(pool, config.n_train, rng)
        cv = [t for t in mine if t.side != side]
    else:
        pool = [t for t in mine if config.train_side is None or t.side == config.train_side]
        train, cv = _pick(pool, config.n_train, rng)
    if not train:
        side = config.train_side or ("right" if config.cv == "other-side" else None)
        sides = sorted({t.side for t in mine})
        raise InputError(
            f"posture {posture}: no training trials of subject {subject!r}"
            + ("" if side is None else f" ({side} arm; its trials of this posture: {', '.join(sides) or 'none'})")
        )
    cv, _ = _pick(cv, config.n_cv, rng)
    if config.iscv == "all-pairs":  # n_iscv per test subject, so every pair has trials
        iscv = [
            t
            for s in sorted({t.subject for t in others})
            for t in _pick([t for t in others if t.subject == s], config.n_iscv, rng)[0]
        ]
    else:
        iscv, _ = _pick(others, config.n_iscv, rng)
    return Split(posture, tuple(train), tuple(cv), tuple(iscv))


def make_units(postures: Sequence[str], config: ProtocolConfig, pair_subjects: Sequence[str] = ()) -> list[Unit]:
    """Every ``(method, posture, sections)``, the costliest (most sections) first for load balancing; with
    ``pair_subjects`` (``--iscv all-pairs``), also every such unit learned from each of those subjects; with
    ``config.posture_transfer`` (and several postures), one unit per held-out posture."""
    opts = {m: _method_options(m, config) for m in config.methods}
    main = {m: _with_uncertainty(opts[m], config) for m in config.methods}  # the main units' fits only
    units = [
        Unit(
            m,
            p,
            s,
            config.seed,
            config.n_nodes,
            config.max_iter,
            config.tol,
            config.backend,
            main[m] if subj is None else opts[m],
            subj,
        )
        for s in sorted(config.sections, reverse=True)
        for subj in (None, *pair_subjects)
        for m in config.methods
        for p in postures
    ]
    if config.posture_transfer and len(postures) > 1:
        units += [
            Unit(m, p, s, config.seed, config.n_nodes, config.max_iter, config.tol, config.backend, opts[m], None, p)
            for s in sorted(config.sections, reverse=True)
            for m in config.methods
            for p in postures
        ]
    return units


def transfer_splits(splits: dict, postures: Sequence[str]) -> dict:
    """Leave-one-posture-out splits, keyed ``("xfer", posture)``: learn on the training trials of every other
    posture (one cost shared by all), predict the held-out posture's trials of the training subject (``cv``: its
    training and CV trials) and of the other subjects (``iscv``)."""
    out = {}
    if len(postures) < 2:
        return out
    for held in postures:
        train = tuple(t for p in postures if p != held for t in splits[p].train)
        own = (*splits[held].train, *splits[held].cv)
        out[("xfer", held)] = Split(held, train, own, splits[held].iscv)
    return out


def _method_options(method: str, config: ProtocolConfig) -> tuple:
    """The unit options of ``method``: ``rollout``, ``seed_form``, ``experimental`` and ``uncertainty`` for MO-IRL
    and the estimators built on it (MaxEnt); bilevel and KKT fit whole reaches with their own defaults. Sorted
    ``(key, value)`` pairs, ``experimental`` as sorted pairs too (hashable)."""
    from ..irl.methods import METHODS, builds_on_moirl
    from ..irl.options import resolve_options

    if not builds_on_moirl(method):
        return ()
    # an experimental option at the method's own value changes nothing: left out, so that a table that spells out
    # a default keys the same units (and resumes them) as one that leaves it out
    defaults = getattr(METHODS[method], "_option_defaults", None)
    base = resolve_options(config.seed_form, None, defaults)
    changed = {
        k: v
        for k, v in config.experimental.items()
        if getattr(resolve_options(config.seed_form, {k: v}, defaults), k) != getattr(base, k)
    }
    opts = {
        "rollout": config.rollout,
        "seed_form": config.seed_form,
        "experimental": tuple(sorted((str(k), _hashable(v)) for k, v in changed.items())),
    }
    return tuple(sorted(opts.items()))


def _with_uncertainty(options: tuple, config: ProtocolConfig) -> tuple:
    """A MO-IRL unit's options with ``uncertainty`` (and its seed) when the run asks for weight samples."""
    if not options or not config.uncertainty:
        return options
    return tuple(
        sorted({**dict(options), "uncertainty": int(config.uncertainty), "random_state": int(config.seed)}.items())
    )


def _hashable(v):
    return tuple(_hashable(x) for x in v) if isinstance(v, list | tuple) else v


def estimator_kwargs(options) -> dict:
    """A unit's ``estimator_options`` (pairs, or a mapping) as the estimator's keyword arguments; ``experimental``
    (pairs or a mapping) as a dict."""
    opts = dict(options)
    if "experimental" in opts:
        opts["experimental"] = dict(opts["experimental"] or {})
    return opts


def unit_observes(method: str, estimator_options) -> bool:
    """Whether a unit of ``method`` with these options fits and predicts trials as they were recorded."""
    from ..irl.methods import METHODS as AVAILABLE
    from ..irl.moirl import MOIRL
    from ..irl.options import resolve_options

    cls = AVAILABLE.get(method)
    if cls is None or not issubclass(cls, MOIRL):
        return False
    opts = estimator_kwargs(estimator_options)
    return bool(resolve_options(opts.get("seed_form", False), opts.get("experimental"), cls._option_defaults).observe)


def make_estimator(unit: Unit):
    """The estimator of ``unit.method`` from :func:`reachirl.irl.methods.make_estimator`: MO-IRL or a baseline
    with the same API (``fit(trials)`` → ``weights_``; optionally ``history_``, ``n_doc_solves_``,
    ``n_doc_failures_``). Only the hyperparameters its constructor takes are passed, and the unit's ``max_iter``
    to MO-IRL and MaxEnt only (bilevel's own ``max_iter``, ``reachirl fit --max-iter``'s, is not the run's)."""
    import inspect

    from ..irl.methods import METHODS as AVAILABLE
    from ..irl.methods import builds_on_moirl
    from ..irl.methods import make_estimator as factory

    if unit.method not in AVAILABLE:
        raise InputError(f"method {unit.method!r} is not available; choose one of {', '.join(AVAILABLE)}")
    wanted = {
        "n_nodes": unit.n_nodes,
        "max_iter": unit.max_iter,
        "backend": unit.backend,
        **({} if unit.tol is None else {"tol": unit.tol}),
        **estimator_kwargs(unit.estimator_options),
    }
    params = inspect.signature(AVAILABLE[unit.method].__init__).parameters
    if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
        wanted = {k: v for k, v in wanted.items() if k in params}
    if not builds_on_moirl(unit.method):  # the run's max_iter is MO-IRL's: bilevel stops at its DOC-solve budget
        wanted.pop("max_iter", None)
    return factory(unit.method, unit.sections, **wanted)


def _history(est) -> list[dict]:
    keep = (
        "iteration",
        "merit",
        "alpha",
        "tries",
        "accepted",
        "doc_solves",
        "doc_failures",
        "doc_recovered",
        "wall_time",
    )
    out = []
    for rec in getattr(est, "history_", []) or []:
        out.append({k: rec[k] for k in keep if k in rec})
    return out


def run_unit(unit: Unit, split: Split) -> dict:
    """Fit on ``split.train`` and predict every trial of every set. Pure: same inputs, same result.

    Returns a JSON-able ``"result"`` dict (weights, history, per-trial RMSEs, counts, times) and ``"arrays"``
    (predictions and the demonstrations on the DOC's knots, float32, for the figures).
    """
    return unit_payload(unit, split, *fit_unit(unit, split))


def fit_unit(unit: Unit, split: Split) -> tuple[object, float]:
    """``unit``'s estimator fitted on ``split.train``, and the fit's wall time (s)."""
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    est = make_estimator(unit)
    t0 = time.perf_counter()
    est.fit(list(split.train))
    return est, time.perf_counter() - t0


def unit_payload(unit: Unit, split: Split, est, fit_time: float) -> dict:
    """:func:`run_unit`'s result from the fitted ``est`` (:func:`fit_unit`): every set's trials predicted."""
    from ..doc.evaluation import evaluate_trials, summarise

    w = np.asarray(est.weights_, dtype=float)
    path = est.rollout_path()  # each prediction starts from the fit's own reach, moved to the trial
    phi = np.mean([t.features(unit.n_nodes, unit.sections) for t in split.train], axis=0)
    reach = est.reach_features()
    sets, arrays = {}, {}
    eval_time, eval_fail, eval_solves = 0.0, 0, 0
    for name, trials in split.sets().items():
        t1 = time.perf_counter()
        errs = evaluate_trials(w, list(trials), unit.n_nodes, backend=unit.backend, observe=unit.observe, path=path)
        eval_time += time.perf_counter() - t1
        eval_solves += len(errs)
        eval_fail += sum(not e.converged for e in errs)
        sets[name] = {"trials": [e.to_dict() for e in errs], "summary": summarise(errs) if errs else None}
        if errs and unit.is_main:  # all-pairs and posture-transfer units keep their RMSEs only
            demos = [t.resample(unit.n_nodes + 1) for t in trials]
            arrays[f"{name}/t"] = np.stack([e.prediction.t for e in errs]).astype(np.float32)
            arrays[f"{name}/pred_q"] = np.stack([e.prediction.q for e in errs]).astype(np.float32)
            arrays[f"{name}/pred_qd"] = np.stack([e.prediction.qd for e in errs]).astype(np.float32)
            arrays[f"{name}/pred_tau"] = np.stack([e.prediction.tau for e in errs]).astype(np.float32)
            arrays[f"{name}/demo_t"] = np.stack([d.t for d in demos]).astype(np.float32)  # each on its own time
            arrays[f"{name}/demo_q"] = np.stack([d.q for d in demos]).astype(np.float32)
            arrays[f"{name}/demo_qd"] = np.stack([d.qd for d in demos]).astype(np.float32)
            arrays[f"{name}/demo_tau"] = np.stack([d.tau[:-1] for d in demos]).astype(np.float32)
            arrays[f"{name}/ids"] = np.array([t.id for t in trials], dtype=str)
            arrays[f"{name}/sides"] = np.array([t.side for t in trials], dtype=str)
    model_info = None
    if hasattr(est, "get_params"):
        from ..irl.provenance import estimator_info

        model_info = estimator_info(est, unit.method, list(split.train))
        model_info.pop("uncertainty", None)  # the result's own, below
        model_info["unit"] = unit.key  # and "run", the run folder, from the coordinator (runner.run_units)
    result = {
        "key": unit.key,
        "model_info": model_info,
        "uncertainty": getattr(est, "uncertainty_", None),
        "unit": asdict(unit),
        "fingerprint": unit.fingerprint(split),
        "weights": w.tolist(),
        "demo_features": phi.tolist(),
        "reach_features": None if reach is None else reach.tolist(),
        # the shares the uncertainty's intervals bracket: on the fit's own reach (on the demonstrations for a
        # method that keeps no reach)
        "cost_shares": cost_shares(w, phi if reach is None else reach).tolist(),
        "cost_shares_on": "demonstrations" if reach is None else "fit_reach",
        "history": _history(est),
        "n_iter": int(getattr(est, "n_iter_", len(_history(est)) - 1)),
        "stop_reason": None if (why := getattr(est, "stop_reason_", None)) is None else str(why),  # as MODEL.json
        "flag": getattr(est, "flag_", None),
        "warnings": list(getattr(est, "warnings_", [])),
        "smoothness": getattr(est, "smoothness_", None),
        "fit": {
            "time_s": fit_time,
            "doc_solves": int(getattr(est, "n_doc_solves_", 0)),
            "doc_failures": int(getattr(est, "n_doc_failures_", 0)),
            "doc_recovered": int(getattr(est, "n_doc_recovered_", 0)),
        },
        "evaluation": {"time_s": eval_time, "doc_solves": eval_solves, "doc_failures": eval_fail},
        "sets": sets,
    }
    return {"result": result, "arrays": arrays}
