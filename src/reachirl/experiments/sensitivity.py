"""Which costs does the data need? Occlusion, weight sensitivity and identifiability of a ``reproduce`` run's
fits (``reachirl sensitivity RUN_DIR --out DIR``).

For each chosen unit (by default: the run's first method, every posture, its largest section count):

* **occlusion of a feature**: MO-IRL is refitted on the same training trials with feature ``j`` removed (its
  weight is 0 in every window and never moves), and the training, CV and ISCV trials are predicted again; the
  change in each trial's RMSE of q against the full fit's is reported as a mean with a paired 95 % bootstrap
  interval over trials (seeded). A trial whose prediction's DOC failed in either fit is left out of its set's
  difference and counted (``<set>_doc_failures``): a solver failure is counted, never averaged in;
* **freezing a window**: the same with window ``s``'s weights held at ω₀ (never learned) instead;
* **weight sensitivity**: every weight ``ω_sj`` of the full fit is changed by ``±percent`` % and the training
  trials are predicted again (DOCs warm-started from the full fit's predictions): the RMSE change for ``+`` and
  ``−`` and how far the predicted path moves (RMSE between the perturbed and the unperturbed prediction, deg),
  over the trials predicted at the full fit's weights and at both changed ones (the others counted);
* **what the training data determines** (:func:`reachirl.irl.uncertainty.determination`): the weight directions
  that move the training reaches beyond the demonstrations' noise, from the Jacobian of the observed rollouts.

A feature (or window) is **needed** when its occlusion raises the held-out RMSE (CV, else ISCV, else training)
with a 95 % interval above 0; **better without** when the interval is below 0; otherwise **not needed** (the
data cannot tell the fit with it from the fit without it); a set of fewer than :data:`MIN_PAIRED` trials gives
no interval, and with no set large enough the verdict says **too few trials**. Rows of posture ``ALL`` pool the
trials of every posture. Each refit is a pure function of its inputs, run in local processes with ``workers > 1``
and checkpointed (:func:`run_sensitivity`); :mod:`reachirl.experiments.sensitivity_outputs` writes the results.
"""

from __future__ import annotations

import concurrent.futures as cf
import functools
import json
import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..features import FEATURES, N_FEATURES
from ..io import atomic_write_json, to_jsonable
from ..irl.moirl import MOIRL
from ..validation import brief
from .protocol import ProtocolConfig, Split, Unit, make_estimator, split_trials

__all__ = [
    "COLUMNS",
    "SensitivityConfig",
    "load_run",
    "run_sensitivity",
    "run_unit",
]

log = logging.getLogger(__name__)

ALL = "ALL"
COLUMNS = (
    "method",
    "posture",
    "sections",
    "analysis",
    "feature",
    "window",
    "cost_share",
    "cost_share_determined",
    "train_delta_deg",
    "train_ci_lo",
    "train_ci_hi",
    "cv_delta_deg",
    "cv_ci_lo",
    "cv_ci_hi",
    "iscv_delta_deg",
    "iscv_ci_lo",
    "iscv_ci_hi",
    "plus_delta_deg",
    "minus_delta_deg",
    "path_change_deg",
    "verdict",
    "train_doc_failures",
    "cv_doc_failures",
    "iscv_doc_failures",
)
SETS = ("train", "cv", "iscv")


@dataclass(frozen=True)
class SensitivityConfig:
    percent: float = 10.0
    sections: int | None = None  # None: the run's largest
    postures: tuple[str, ...] | None = None  # None: every posture of the run
    method: str | None = None  # None: the run's first method
    occlusion: bool = True
    sensitivity: bool = True
    n_boot: int = 2000
    seed: int = 0

    def __post_init__(self) -> None:
        if self.postures is not None:  # a posture named twice is analysed, and listed, once
            object.__setattr__(self, "postures", tuple(dict.fromkeys(self.postures)))
        if not 0 < float(self.percent) < 100:
            raise InputError(f"--percent must be in (0, 100), got {self.percent}")
        if self.sections is not None and int(self.sections) < 1:
            raise InputError(f"--sections must be a positive integer, got {self.sections}")
        if not (self.occlusion or self.sensitivity):
            raise InputError(
                "both the occlusion and the sensitivity analyses are switched off, which leaves only what the "
                "training trials determine: that is in the run's models (models/*.json, 'uncertainty.determination', "
                "unless the run was made with uncertainty 0), so nothing is analysed"
            )


# ---------------------------------------------------------------------- the run
def _run_markers(run_dir: Path) -> str | None:
    """The marker map (``--markers``) a run read its folder of recordings with, from the run's ``run.toml``
    (``results.json`` does not record it), or ``None``: the folder's own marker names. A wrong one is caught by
    the data's fingerprint."""
    import tomllib

    try:
        with open(run_dir / "run.toml", "rb") as fh:
            markers = tomllib.load(fh).get("markers")
    except (OSError, tomllib.TOMLDecodeError):
        return None
    return markers if isinstance(markers, str) else None


def load_run(run_dir: str | Path):
    """``(dataset, config, units, train_subject)`` of a finished ``reproduce`` run folder, ``units`` its
    ``results.json`` entries by key (:func:`run_unit` reads a unit's checkpoint). The data are loaded again from
    where the run found them and must have the run's fingerprint."""
    from .datasets import Dataset, fingerprint, load, preprocess_folder
    from .results import check_results_file, protocol_config

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError("no such run folder (expected the --out folder of `reachirl reproduce`)", run_dir)
    path = run_dir / "results.json"
    if not path.is_file():
        rerun = " (rerun reproduce into it to finish)" if (run_dir / "run.toml").is_file() else ""
        raise InputError(f"not a finished reproduce run: no results.json{rerun}", run_dir)
    if not (run_dir / "table.csv").is_file():  # written last: the run stopped while writing its outputs
        raise InputError("not a finished reproduce run: no table.csv (rerun reproduce into it to finish)", run_dir)
    try:
        res = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise InputError(f"unreadable ({e})", path) from None
    if not isinstance(res, dict):
        raise InputError(f"expected a JSON object (a reproduce run's results), found a {type(res).__name__}", path)
    check_results_file(res, path)
    data, proto = res.get("data") or {}, res.get("protocol") or {}
    kind, source = data.get("kind"), str(data.get("source", ""))
    if kind == "builtin":
        folder = Path(source.rsplit(": ", 1)[-1])
        if not folder.is_dir():
            raise InputError(f"the run's built-in data folder is gone ({folder}); rerun reproduce", path)
        dataset = Dataset(tuple(preprocess_folder(folder)), source, "builtin")
    elif kind in ("folder", "trials-file"):
        try:
            dataset = load(source, marker_map=_run_markers(run_dir) if kind == "folder" else None)
        except InputError as e:  # moved, removed or edited: the run's record of it is what names it
            raise InputError(f"the run's data cannot be loaded again ({e})", path) from None
    else:
        raise InputError(f"the run's data ({kind or 'unknown'}: {source}) cannot be loaded again", path)
    if data.get("fingerprint") and fingerprint(dataset.trials) != data["fingerprint"]:
        raise InputError(f"the data at {source} are not the ones the run used (fingerprint differs)", path)
    names = {f.name for f in fields(ProtocolConfig)}
    kw = {k: v for k, v in proto.items() if k in names}
    for k in ("sections", "postures", "methods"):
        if kw.get(k) is not None:
            kw[k] = tuple(kw[k])
    kw["postures"] = tuple(proto.get("postures_run") or kw.get("postures") or ())
    config = protocol_config(kw, path)
    units = {u["key"]: u for u in res.get("units", [])}
    subject = proto.get("train_subject")
    if not isinstance(subject, str) or not subject:
        raise InputError(
            f"field 'protocol': train_subject must name the run's training subject, got {brief(subject)}", path
        )
    return dataset, config, units, subject


def run_unit(run_dir: str | Path, key: str) -> dict:
    """The checkpoint ``units/<key>.json`` of a finished run's unit (as ``reproduce`` reuses it); a missing,
    damaged or edited one is an :class:`InputError` naming the file (the analysis recomputes no unit)."""
    from .results import read_unit

    res, problem = read_unit(Path(run_dir), key)
    if res is None:
        path, what = problem
        raise InputError(
            f"{what}: the checkpoint of the run's unit {key}; rerun `reachirl reproduce` into {run_dir} to "
            "recompute it",
            path,
        )
    return res


# ---------------------------------------------------------------------- constrained MO-IRL
# ---------------------------------------------------------------------- jobs (pure functions)
def _per_trial(weights, trials, n_nodes, backend, warm=None, observe=False):
    """Per-trial RMSE of the predictions (seen as recorded with ``observe``, as the run predicted them), the DOC
    solutions themselves (warm starts for the same tasks), the predictions compared (the part seen, or the
    solutions) and whether each converged (a failed one's RMSE is kept, to be left out by
    :func:`_converged_pairs`)."""
    from ..doc.evaluation import rmse_deg
    from ..doc.observation import predict

    out, sols, seens, ok = [], [], [], []
    for i, t in enumerate(trials):
        sol, seen = predict(
            t, weights, n_nodes, t.onset_threshold if observe else None, backend, None if warm is None else warm[i]
        )
        out.append(rmse_deg(seen.q, t.q_at(n_nodes + 1))[2])
        sols.append(sol)
        seens.append(seen)
        ok.append(bool(sol.converged))
    return np.array(out), sols, seens, np.array(ok, dtype=bool)


def occlusion_job(unit: Unit, split: Split, removed: tuple[int, ...], frozen: tuple[int, ...]) -> dict:
    """Refit ``unit`` on ``split.train`` with features ``removed`` / windows ``frozen`` held and predict every
    set: ``{"weights", "rmse": {set: [per trial]}, "converged": {set: [per trial]}, "flag"}``."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    base = make_estimator(unit)
    params = base.get_params()
    mask = np.ones((unit.sections, N_FEATURES), dtype=bool)
    mask[:, list(removed)] = False
    experimental = {**dict(params.get("experimental") or {}), "frozen_windows": tuple(frozen)}
    est = type(base)(
        **{**params, "feature_mask": mask if removed else None, "experimental": experimental, "uncertainty": None}
    )
    est.fit(list(split.train))
    rmse, converged = {}, {}
    for s, tr in split.sets().items():
        r, _, _, ok = _per_trial(est.weights_, list(tr), unit.n_nodes, unit.backend, observe=unit.observe)
        rmse[s], converged[s] = r.tolist(), ok.tolist()
    return {"weights": np.asarray(est.weights_).tolist(), "rmse": rmse, "converged": converged, "flag": est.flag_}


def sensitivity_job(
    weights: np.ndarray,
    trials: Sequence,
    n_nodes: int,
    backend: str,
    window: int,
    percent: float,
    observe: bool = False,
) -> dict:
    """``±percent`` % on each weight of ``window``: per feature, the per-trial RMSE for + and − (predictions
    seen as recorded with ``observe``) and the change of the prediction compared (deg; the part seen with
    ``observe``, on its own normalised time, as the RMSE compares it) against the unperturbed one, with whether
    each prediction converged (``base_converged``, ``plus_converged``, ``minus_converged``); a trial whose changed
    or unchanged prediction failed moves no path in ``displacement`` (zeros)."""
    from ..doc.evaluation import rmse_deg

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    w = np.asarray(weights, dtype=float)
    base, sols, seen, base_ok = _per_trial(w, trials, n_nodes, backend, observe=observe)
    out = {"base": base.tolist(), "base_converged": base_ok.tolist(), "features": []}
    for j in range(N_FEATURES):
        rec = {}
        for sign, name in ((1, "plus"), (-1, "minus")):
            wp = w.copy()
            wp[window, j] *= 1 + sign * percent / 100.0
            r, _, ps, ok = _per_trial(wp, trials, n_nodes, backend, warm=sols, observe=observe)
            rec[name] = r.tolist()
            rec[f"{name}_converged"] = ok.tolist()
            rec[f"path_{name}"] = [float(rmse_deg(a.q, b.q)[2]) for a, b in zip(ps, seen, strict=True)]
            if sign > 0:  # the direction the prediction moves in (every trial's knots, rad; none where a DOC failed)
                rec["displacement"] = np.concatenate(
                    [np.where(good, a.q - b.q, 0.0).ravel() for a, b, good in zip(ps, seen, ok & base_ok, strict=True)]
                )
        out["features"].append(rec)
    return out


def determination_job(unit: Unit, split: Split) -> dict:
    """The unit's fit again (deterministic: the run's weights) and what its training trials determine
    (:func:`reachirl.irl.uncertainty.determination`); ``None`` for a method without rollouts."""
    from ..irl.uncertainty import determination, residuals_and_jacobian

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    est = make_estimator(unit)
    if not isinstance(est, MOIRL):
        return {"determination": None}
    est.set_params(uncertainty=None)
    est.fit(list(split.train))
    free = est._movable(est._w_fit.shape)
    try:
        r, J = residuals_and_jacobian(est, free)
    except ValueError:  # an unconverged or degenerate rollout: no sensitivity
        return {"determination": None}
    return {"determination": determination(r, J, free).to_dict()}


# ---------------------------------------------------------------------- checkpoints
def _label(name: tuple) -> str:
    p, kind, i = name
    return f"{p} {kind}" if kind == "determination" else f"{p} {kind} {i + 1}"


def job_path(checkpoint_dir: str | Path, unit_key: str, name: tuple) -> Path:
    """Where job ``name`` of the run unit ``unit_key`` (method, posture and sections, as ``units/`` names it) is
    kept: analyses of other methods or section counts into the same folder keep their own."""
    _, kind, i = name
    return Path(checkpoint_dir) / f"{unit_key}-{kind}-{i}.json"


#: the modules the jobs use beyond a unit's own (:func:`reachirl.experiments.protocol.code_fingerprint`): this
#: one, the determination (irl/uncertainty.py, doc/sensitivity.py), MO-IRL's option defaults and the DOC's
#: dynamics and solver
_ANALYSIS_CODE = (
    "experiments/sensitivity.py",
    "irl/uncertainty.py",
    "irl/options.py",
    "doc/sensitivity.py",
    "doc/symbolic.py",
    "doc/newton.py",
)


@functools.lru_cache(maxsize=1)
def _analysis_fingerprint() -> str:
    from .protocol import sources_hash

    return sources_hash(_ANALYSIS_CODE)


def _job_fingerprint(name: tuple, chosen: tuple, config: SensitivityConfig) -> str:
    """What a job's result depends on: the run unit's result as written (its checksum covers the weights and the
    fingerprint of the unit's inputs and code), the code of the analysis, and the job's own options."""
    import hashlib

    from .protocol import code_fingerprint

    unit, _, r = chosen
    payload = {
        "job": list(name),
        "unit": r.get("checksum"),
        "code": code_fingerprint(unit.method, unit.backend),
        "analysis": _analysis_fingerprint(),
        "percent": float(config.percent) if name[1] == "sensitivity" else None,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:16]


def save_job(path: Path, name: tuple, fingerprint: str, result: dict) -> dict:
    """Write a finished job's result (atomically) and return it as :func:`load_job` would read it back."""
    from .results import content_checksum

    if path.exists() and not path.is_file():
        raise InputError("is not a regular file, where a job's checkpoint goes; remove it and rerun", path)
    body = to_jsonable({"job": list(name), "fingerprint": fingerprint, "result": result})
    body["checksum"] = content_checksum(body)
    atomic_write_json(path, body, indent=None)
    return body["result"]


def load_job(path: Path, name: tuple, fingerprint: str) -> dict | None:
    """A finished job's result, or ``None`` (run it) if absent, damaged, edited, or made for other inputs."""
    from .results import content_checksum, read_checkpoint

    if path.exists() and not path.is_file():
        raise InputError("is not a regular file, where a job's checkpoint goes; remove it and rerun", path)
    if not path.is_file():
        return None
    body = read_checkpoint(path, "running the job again")
    if not isinstance(body, dict) or body.get("job") != list(name) or body.get("fingerprint") != fingerprint:
        return None
    if body.get("checksum") != content_checksum(body) or not isinstance(body.get("result"), dict):
        log.warning("%s: its content does not match its checksum (edited or damaged); running the job again", path)
        return None
    return body["result"]


# ---------------------------------------------------------------------- statistics
#: paired trials needed for an interval: a bootstrap over fewer only spans the few differences (with two, both of
#: the same sign would read as a 95 % finding, a 1-in-4 chance under no effect)
MIN_PAIRED = 5


def paired_interval(d: Sequence[float], n_boot: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """Mean of the paired differences ``d`` and its 95 % bootstrap interval (seeded); NaNs without data, and a mean
    with a NaN interval from fewer than :data:`MIN_PAIRED` differences."""
    d = np.asarray(d, dtype=float)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return float("nan"), float("nan"), float("nan")
    if d.size < MIN_PAIRED:
        return float(d.mean()), float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    boot = d[rng.integers(0, d.size, size=(int(n_boot), d.size))].mean(axis=1)
    lo, hi = np.quantile(boot, [0.025, 0.975])
    return float(d.mean()), float(lo), float(hi)


def _converged_mask(*results) -> np.ndarray:
    """The trials predicted successfully in every one of ``results``, each ``(per-trial RMSEs, per-trial converged
    flags)``: an RMSE that is missing (NaN) counts as failed; flags ``None`` (a result that does not record them):
    every prediction converged."""
    ok = None
    for values, flags in results:
        m = np.isfinite(np.asarray(values, dtype=float))
        if flags is not None:
            m &= np.asarray(flags, dtype=bool)
        ok = m if ok is None else ok & m
    return ok


def _converged_pairs(new: Sequence, new_ok: Sequence | None, old: Sequence, old_ok: Sequence | None):
    """``(differences, left_out)``: ``new − old`` per trial over the trials whose predictions converged on both
    sides (:func:`_converged_mask`), and how many were left out."""
    ok = _converged_mask((new, new_ok), (old, old_ok))
    return np.asarray(new, dtype=float)[ok] - np.asarray(old, dtype=float)[ok], int(ok.size - ok.sum())


def _interval_cells(d: Sequence[float], n_boot: int, seed: int) -> tuple:
    """:func:`paired_interval` of ``d`` as a row's cells: ``None`` (empty), never NaN, where there is none."""
    return tuple(None if not np.isfinite(v) else v for v in paired_interval(d, n_boot, seed))


def _mean_or_none(d: Sequence[float]) -> float | None:
    d = np.asarray(d, dtype=float)
    return float(d.mean()) if d.size else None


def reading(row: dict, s: str) -> str | None:
    """What set ``s``'s 95 % interval alone says of a refit: ``needed`` (above 0), ``better without`` (below 0) or
    ``not needed``; None without an interval."""
    lo, hi = row.get(f"{s}_ci_lo"), row.get(f"{s}_ci_hi")
    if lo is None or hi is None or not (np.isfinite(lo) and np.isfinite(hi)):
        return None
    return "needed" if lo > 0 else "better without" if hi < 0 else "not needed"


def _verdict(row: dict) -> str:
    for s in ("cv", "iscv", "train"):
        said = reading(row, s)
        if said is not None:
            return f"{said} ({s})"
    if any(row.get(f"{s}_delta_deg") is not None and np.isfinite(row[f"{s}_delta_deg"]) for s in SETS):
        return f"too few trials (fewer than {MIN_PAIRED} in every set)"
    return ""


# ---------------------------------------------------------------------- the analysis
def _executor(workers: int):
    from .runner import unit_executor

    return unit_executor(workers)  # bounded, dies with its parent, ignores Ctrl-C


def run_sensitivity(
    run_dir: str | Path,
    config: SensitivityConfig | None = None,
    *,
    workers: int = 1,
    checkpoint_dir: str | Path | None = None,
    on_start: Callable[[int, int], None] | None = None,
    on_done: Callable[[str, bool], None] | None = None,
) -> dict:
    """Occlusion, sensitivity and identifiability of the chosen units of ``run_dir`` (module docstring). Returns
    ``{"rows": [...], "identifiability": {...}, "units": [...], "config": {...}}``.

    With ``checkpoint_dir``, each job (a refit, a window's weight changes, a posture's determination) is saved
    there as it finishes and reused by a later call on the same run unit, code and options, so an interrupted
    analysis resumes where it stopped. ``on_start(n_jobs, n_reused)`` is called once, ``on_done(label,
    reused)`` per job."""

    config = config or SensitivityConfig()
    dataset, pconfig, units, train_subject = load_run(run_dir)
    results = Path(run_dir) / "results.json"  # what the refusals below name: the run they read
    method = config.method or pconfig.methods[0]
    if method not in pconfig.methods:
        raise InputError(f"--method {method!r} was not run; the run has {', '.join(pconfig.methods)}", results)
    if config.occlusion and method != "moirl":
        chosen = "--method" if config.method else "the run's first method"
        raise InputError(
            f"occlusion refits need MO-IRL; the method analysed ({chosen}) is {method!r} (use --no-occlusion"
            + (", or --method moirl)" if "moirl" in pconfig.methods else ")"),
            results,
        )
    sections = int(config.sections or max(pconfig.sections))
    if sections not in pconfig.sections:
        raise InputError(
            f"--sections {sections} was not run; the run has {', '.join(map(str, pconfig.sections))}", results
        )
    postures = list(config.postures or pconfig.postures)
    unknown = [p for p in postures if p not in pconfig.postures]
    if unknown:
        raise InputError(
            f"posture(s) {', '.join(unknown)} were not run; the run has {', '.join(pconfig.postures)}", results
        )
    trials = list(dataset.trials)
    chosen = {}
    for p in postures:
        key = next(
            (
                k
                for k, e in units.items()
                if e["unit"].get("method") == method
                and e["unit"]["posture"] == p
                and e["unit"].get("sections") == sections
                and not e["unit"].get("train_subject")
                and not e["unit"].get("held_out_posture")  # a posture-transfer unit names its held-out posture
            ),
            None,
        )
        if key is None:
            raise InputError(f"the run has no unit {method}, {p}, {sections} sections", Path(run_dir) / "results.json")
        r = run_unit(run_dir, key)
        split = split_trials(trials, p, pconfig)
        if [t.id for t in split.train] != [e["id"] for e in r["sets"]["train"]["trials"]]:
            raise InputError(f"{r['key']}: the training trials differ from the run's", run_dir)
        u = r["unit"]
        unit = Unit(
            u["method"],
            u["posture"],
            int(u["sections"]),
            u["seed"],
            u["n_nodes"],
            u["max_iter"],
            u["tol"],
            u["backend"],
            tuple(tuple(x) for x in u.get("estimator_options", ())),
        )
        chosen[p] = (unit, split, r)

    jobs = []  # (name, fn, args)
    for p, (unit, split, r) in chosen.items():
        jobs.append(((p, "determination", 0), determination_job, (unit, split)))
        if config.occlusion:
            for j in range(N_FEATURES):
                jobs.append(((p, "occlude_feature", j), occlusion_job, (unit, split, (j,), ())))
            if sections > 1:
                for s in range(sections):
                    jobs.append(((p, "freeze_window", s), occlusion_job, (unit, split, (), (s,))))
        if config.sensitivity:
            for s in range(sections):
                jobs.append(
                    (
                        (p, "sensitivity", s),
                        sensitivity_job,
                        (
                            np.asarray(r["weights"]),
                            list(split.train),
                            unit.n_nodes,
                            unit.backend,
                            s,
                            float(config.percent),
                            unit.observe,
                        ),
                    )
                )
    done: dict = {}
    todo, fingerprints, paths = [], {}, {}
    for name, fn, args in jobs:
        fingerprints[name] = _job_fingerprint(name, chosen[name[0]], config)
        if checkpoint_dir is not None:
            paths[name] = job_path(checkpoint_dir, chosen[name[0]][2]["key"], name)
        res = None if checkpoint_dir is None else load_job(paths[name], name, fingerprints[name])
        if res is None:
            todo.append((name, fn, args))
        else:
            done[name] = res
    if on_start:
        on_start(len(jobs), len(done))
    for name in list(done):
        if on_done:
            on_done(_label(name), True)

    def finish(name, res) -> None:  # every result as a resumed run reads it back
        fp = fingerprints[name]
        done[name] = to_jsonable(res) if checkpoint_dir is None else save_job(paths[name], name, fp, res)
        if on_done:
            on_done(_label(name), False)

    if workers <= 1 or len(todo) <= 1:
        for name, fn, args in todo:
            finish(name, fn(*args))
    else:
        from .processes import stop_workers, worker_died

        ex = _executor(min(workers, len(todo)))
        try:
            futs = {ex.submit(fn, *args): name for name, fn, args in todo}
            for f in cf.as_completed(futs):
                try:
                    res = f.result()
                except cf.process.BrokenProcessPool:  # killed (SIGKILL, the OOM killer): said as a unit's worker
                    kept = "finished jobs are kept (rerun to resume)" if checkpoint_dir else "nothing is kept"
                    job = _label(futs[f])
                    raise worker_died(
                        f"running job {job}", kept, checkpoint_dir if checkpoint_dir is not None else run_dir
                    ) from None
                finish(futs[f], res)
        except BaseException:  # Ctrl-C, SIGTERM or an error: the workers (which ignore Ctrl-C) end now
            stop_workers(ex)
            raise
        ex.shutdown()

    rows, pooled, pooled_failed, ident = [], {}, {}, {}
    for p, (_, _, r) in chosen.items():
        shares = np.asarray(r["cost_shares"])
        unc = r.get("uncertainty")
        determined = None if not unc else np.asarray(unc["share_intervals"]["determined"], dtype=bool)
        base = {
            s: np.array([np.nan if e["rmse_deg"]["q"] is None else e["rmse_deg"]["q"] for e in r["sets"][s]["trials"]])
            for s in SETS
        }
        base_ok = {s: [bool(e.get("converged", True)) for e in r["sets"][s]["trials"]] for s in SETS}
        ident[p] = dict(done[(p, "determination", 0)])
        ident[p]["effect_collinearity"] = _effect_collinearity(done, p, sections)
        ident[p]["key"] = r["key"]
        ident[p]["flag"] = r.get("flag")
        for kind in ("occlude_feature", "freeze_window"):
            n_items = N_FEATURES if kind == "occlude_feature" else (sections if sections > 1 else 0)
            for i in range(n_items):
                res = done.get((p, kind, i))
                if res is None:
                    continue
                row = _row(method, p, sections, kind, i, shares, determined=determined)
                for s in SETS:
                    d, failed = _converged_pairs(
                        res["rmse"][s], (res.get("converged") or {}).get(s), base[s], base_ok[s]
                    )
                    pooled.setdefault((kind, i, s), []).extend(d.tolist())
                    pooled_failed[(kind, i, s)] = pooled_failed.get((kind, i, s), 0) + failed
                    row[f"{s}_delta_deg"], row[f"{s}_ci_lo"], row[f"{s}_ci_hi"] = _interval_cells(
                        d, config.n_boot, config.seed
                    )
                    row[f"{s}_doc_failures"] = failed
                row["verdict"] = _verdict(row)
                rows.append(row)
        for s in range(sections):
            res = done.get((p, "sensitivity", s))
            if res is None:
                continue
            b = np.asarray(res["base"], dtype=float)
            for j, rec in enumerate(res["features"]):
                row = _row(method, p, sections, "sensitivity", j, shares, window=s, determined=determined)
                # the row's figures over the same trials: those predicted at the full fit's weights and both changed
                plus, minus = np.asarray(rec["plus"], dtype=float), np.asarray(rec["minus"], dtype=float)
                ok = _converged_mask(
                    (b, res.get("base_converged")),
                    (plus, rec.get("plus_converged")),
                    (minus, rec.get("minus_converged")),
                )
                row["plus_delta_deg"] = _mean_or_none(plus[ok] - b[ok])
                row["minus_delta_deg"] = _mean_or_none(minus[ok] - b[ok])
                paths = np.asarray(rec["path_plus"], dtype=float)[ok].tolist()
                paths += np.asarray(rec["path_minus"], dtype=float)[ok].tolist()
                row["path_change_deg"] = _mean_or_none(paths)
                row["train_doc_failures"] = int(ok.size - ok.sum())
                pooled.setdefault(("sensitivity", s, j), []).append(row)
                rows.append(row)
    if len(chosen) > 1:  # ALL: every posture's trials pooled
        mean_shares = np.mean([np.asarray(r["cost_shares"]) for _, _, r in chosen.values()], axis=0)
        uncs = [r.get("uncertainty") for _, _, r in chosen.values()]
        all_determined = (  # a mean over postures is determined when every posture's share is
            None
            if not all(uncs)
            else np.all([np.asarray(u["share_intervals"]["determined"], dtype=bool) for u in uncs], axis=0)
        )
        for kind in ("occlude_feature", "freeze_window"):
            for i in range(N_FEATURES if kind == "occlude_feature" else sections):
                if (kind, i, "train") not in pooled:
                    continue
                row = _row(method, ALL, sections, kind, i, mean_shares, determined=all_determined)
                for s in SETS:
                    row[f"{s}_delta_deg"], row[f"{s}_ci_lo"], row[f"{s}_ci_hi"] = _interval_cells(
                        pooled[(kind, i, s)], config.n_boot, config.seed
                    )
                    row[f"{s}_doc_failures"] = pooled_failed[(kind, i, s)]
                row["verdict"] = _verdict(row)
                rows.append(row)
        for s in range(sections):
            for j in range(N_FEATURES):
                per = pooled.get(("sensitivity", s, j))
                if not per:
                    continue
                row = _row(method, ALL, sections, "sensitivity", j, mean_shares, window=s, determined=all_determined)
                for k in ("plus_delta_deg", "minus_delta_deg", "path_change_deg"):  # postures with none: left out
                    row[k] = _mean_or_none([x[k] for x in per if x[k] is not None])
                row["train_doc_failures"] = sum(x["train_doc_failures"] for x in per)
                rows.append(row)
    return {
        "rows": rows,
        "identifiability": ident,
        "units": [r["key"] for _, _, r in chosen.values()],
        "config": {
            "method": method,
            "sections": sections,
            "postures": postures,
            "percent": config.percent,
            "n_boot": config.n_boot,
            "seed": config.seed,
            "train_subject": train_subject,
        },
    }


def _effect_collinearity(done: dict, posture: str, sections: int, threshold: float = 0.9) -> list[dict]:
    """Per window, feature pairs whose +x % weight changes move the predicted paths in nearly the same (or the
    opposite) direction: ``|cos| ≥ threshold`` between the displacements. Such weights trade off in their
    effect on the reach even when their running rates are not correlated."""
    out = []
    for s in range(sections):
        res = done.get((posture, "sensitivity", s))
        if res is None:
            continue
        d = [np.asarray(f["displacement"], dtype=float) for f in res["features"]]
        for i in range(N_FEATURES):
            for j in range(i + 1, N_FEATURES):
                ni, nj = np.linalg.norm(d[i]), np.linalg.norm(d[j])
                if ni > 0 and nj > 0:
                    c = float(d[i] @ d[j] / (ni * nj))
                    if abs(c) >= threshold:
                        out.append({"window": s + 1, "features": [FEATURES[i], FEATURES[j]], "cos": c})
    return out


def _row(method, posture, sections, kind, i, shares, window=None, determined=None) -> dict:
    """A row of sensitivity.csv; ``determined`` ``(S, 7)`` booleans (the fit's narrow share intervals) or
    None without weight samples."""
    row = {c: None for c in COLUMNS}
    row.update(method=method, posture=posture, sections=sections, analysis=kind, verdict="")
    if kind == "occlude_feature":
        row.update(feature=FEATURES[i], window="all", cost_share=float(shares[:, i].mean()))
        if determined is not None:  # a mean over windows is determined when every window's share is
            row["cost_share_determined"] = bool(np.all(determined[:, i]))
    elif kind == "freeze_window":
        row.update(feature="all", window=str(i + 1), cost_share=None)
    else:
        row.update(feature=FEATURES[i], window=str(window + 1), cost_share=float(shares[window, i]))
        if determined is not None:
            row["cost_share_determined"] = bool(determined[window, i])
    return row
