"""Where ``reproduce`` gets its trials: the built-in virtual subjects, a trials file, or a folder
with a manifest.

:func:`load` is the one entry point. It returns a :class:`Dataset`: the trials, where they came from, and the
true weights when the data are virtual subjects (``truth.json`` beside the manifest).

* ``None``: the built-in data set (:func:`reachirl.virtual.builtin_dataset_dir`, generated on first use and
  cached), preprocessed from its TRC markers exactly as ``reachirl preprocess`` would; the preprocessed trials are
  cached too (:mod:`reachirl.data.cache`), keyed by the folder's content and the preprocessing code.
* a ``.npz`` trials file written by ``reachirl preprocess`` (:func:`reachirl.data.trial.load_trials`); a
  ``truth.json`` beside it (virtual subjects) is read as the ground truth;
* a folder holding ``manifest.csv`` (``file,subject,posture[,side,static]``) and optionally ``subjects.csv``
  (``subject,sex,height_m,mass_kg[,...]``) and ``truth.json``;
* a UE-ADL folder (``ADLxxx/ADLxxxFR1.csv`` ..., static trials beside them, its ``subjects.csv``), with no
  manifest: every reach, posture ``forward``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..data.trial import Trial, load_trials
from ..errors import InputError
from ..irl.provenance import fingerprint

__all__ = ["Dataset", "fingerprint", "load", "preprocess_folder", "toy"]

log = logging.getLogger(__name__)

_MANIFEST_NAMES = ("manifest.csv",)
_SUBJECT_NAMES = ("subjects.csv", "subject_info.csv", "subject-info.csv")


@dataclass(frozen=True)
class Dataset:
    """Trials plus provenance. ``truth`` is ``truth.json`` of virtual subjects (``None`` for real data)."""

    trials: tuple[Trial, ...]
    source: str
    kind: str  # "builtin" | "trials-file" | "folder" | "memory"
    truth: dict | None = field(default=None, repr=False)

    @property
    def subjects(self) -> list[str]:
        return sorted({t.subject for t in self.trials})

    @property
    def postures(self) -> list[str]:
        return sorted({t.posture for t in self.trials})

    def describe(self) -> dict:
        counts: dict[str, dict[str, int]] = {}
        for t in self.trials:
            counts.setdefault(t.subject, {}).setdefault(t.posture, 0)
            counts[t.subject][t.posture] += 1
        return {
            "source": self.source,
            "kind": self.kind,
            "n_trials": len(self.trials),
            "subjects": self.subjects,
            "postures": self.postures,
            "trials_per_subject_posture": counts,
            "has_truth": self.truth is not None,
            "fingerprint": fingerprint(self.trials),
        }


def _find(folder: Path, names: Sequence[str]) -> Path | None:
    for n in names:
        if (folder / n).is_file():
            return folder / n
    return None


def preprocess_folder(folder: str | Path, marker_map: str | None = None) -> list[Trial]:
    """Every file of ``folder/manifest.csv`` to a :class:`Trial`, as ``reachirl preprocess --manifest`` does.

    ``marker_map`` is ``shoulder=A,elbow=B,wrist=C,fingertip=D``; without it the marker names come from
    ``truth.json`` (virtual subjects) or the built-in marker sets are tried (``ue-adl``, then ``default``).
    """
    from ..data.markersets import parse_marker_map
    from ..data.pipeline import preprocess_entries, preprocess_manifest
    from ..data.readers import ManifestEntry, read_subject_info
    from ..data.ue_adl import reach_files
    from ..virtual.files import refuse_unfinished

    folder = Path(folder)
    refuse_unfinished(folder)
    manifest = _find(folder, _MANIFEST_NAMES)
    info_path = _find(folder, _SUBJECT_NAMES)
    if manifest is None:  # a UE-ADL folder: its reach files, each with its static trial beside it
        files = reach_files(folder)
        if not files:
            raise InputError(
                "folder has no manifest.csv (columns file,subject,posture[,side]) and no UE-ADL "
                "reach files (ADLxxxFR1.csv ...)",
                folder,
            )
        infos = read_subject_info(info_path) if info_path else None
        markers = parse_marker_map(marker_map) if marker_map else None
        entries = [ManifestEntry(file=f, subject="", posture="") for f in files]
        return preprocess_entries(entries, subject_info=infos, markers=markers)
    if marker_map is not None:
        _refuse_markers_for_angles(manifest)
    if marker_map is None and (folder / "truth.json").is_file():
        m = (_read_truth(folder) or {}).get("markers")
        if isinstance(m, dict):
            marker_map = ",".join(f"{k}={v}" for k, v in m.items())
    return preprocess_manifest(manifest, info_path, parse_marker_map(marker_map) if marker_map else None)


def _refuse_markers_for_angles(manifest: Path) -> None:
    """``--markers`` names marker recordings' columns: given for a folder whose every recording is a joint-angle
    file (MOT, CSV), it would be left unused; refused, naming the manifest (as ``preprocess`` refuses it)."""
    from ..data.readers import ANGLE_FORMATS, detect_format, read_manifest

    entries = read_manifest(manifest)
    if entries and all(detect_format(e.file) in ANGLE_FORMATS for e in entries):
        raise InputError(
            "--markers applies to marker recordings (TRC, C3D, Vicon CSV), and every recording it lists is a "
            "joint-angle file (MOT, CSV): it would be left unused",
            manifest,
        )


def _read_truth(folder: Path) -> dict | None:
    p = folder / "truth.json"
    if not p.is_file():
        return None
    from ..io import read_json

    truth = read_json(p)  # InputError naming the file when it is not JSON
    if not isinstance(truth, dict):
        raise InputError(
            f"expected a JSON object (the ground truth of `reachirl synth`), found a {type(truth).__name__}", p
        )
    m = truth.get("markers")
    if m is not None and not (isinstance(m, dict) and all(isinstance(v, str) for v in m.values())):
        raise InputError("field 'markers': expected an object of marker names", p)
    _check_truth_weights(truth, p)
    return truth


def _check_truth_weights(truth: dict, p: Path) -> None:
    """The parts of truth.json the report reads: n_windows, nominal weights, per-trial weights (n_windows, 7)."""

    def weights(w, where):
        a = np.asarray(w, dtype=object)
        ok = (
            a.ndim == 2
            and a.shape[1] == 7
            and all(
                isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) and v >= 0 for v in a.flat
            )
        )
        if not ok:
            raise InputError(f"{where}: expected rows of 7 finite weights >= 0", p)

    n = truth.get("n_windows", 1)
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 1000:
        raise InputError(f"field 'n_windows': expected an integer in [1, 1000], found {str(n)[:40]}", p)
    inner = truth.get("truth") or {}
    if not isinstance(inner, dict):
        raise InputError("field 'truth': expected an object", p)
    if inner.get("nominal_weights") is not None:
        weights(inner["nominal_weights"], "field 'truth.nominal_weights'")
    subjects = truth.get("subjects") or {}
    if not isinstance(subjects, dict):
        raise InputError("field 'subjects': expected an object", p)
    for sid, subj in subjects.items():
        trials = subj.get("trials") if isinstance(subj, dict) else None
        if not isinstance(trials or {}, dict) or not all(isinstance(r, list) for r in (trials or {}).values()):
            raise InputError(f"field 'subjects.{sid}.trials': expected an object of lists", p)
        for recs in (trials or {}).values():
            for r in recs:
                if not isinstance(r, dict):
                    raise InputError(f"field 'subjects.{sid}.trials': expected objects, found {str(r)[:40]}", p)
                if r.get("weights") is not None:
                    weights(r["weights"], f"field 'subjects.{sid}.trials', file {str(r.get('file'))[:40]}")


def _builtin_trials(folder: Path, marker_map: str | None) -> list[Trial]:
    """:func:`preprocess_folder` of a built-in data set's folder, kept in the trials cache
    (:mod:`reachirl.data.cache`): preprocessed again only when a file of the folder (or one its manifest names),
    ``marker_map`` or the preprocessing code changes."""
    from ..data.cache import cached_trials

    files = [p for p in folder.iterdir() if p.is_file()]
    manifest = _find(folder, _MANIFEST_NAMES)
    if manifest is not None:
        from ..data.readers import read_manifest

        try:
            entries = read_manifest(manifest)
        except InputError:  # preprocess_folder says what is wrong with it
            return preprocess_folder(folder, marker_map)
        files += [p for e in entries for p in (e.file, e.static) if p is not None]
    return cached_trials(
        folder.name,
        files,
        {"marker_map": marker_map},
        lambda: preprocess_folder(folder, marker_map),
        sources=(__file__,),
    )


#: built-in virtual subjects at most (generating one takes seconds to minutes: 100 is hours of solves)
MAX_SUBJECTS = 100


def load(
    path: str | Path | None = None, seed: int = 0, marker_map: str | None = None, n_subjects: int | None = None
) -> Dataset:
    """The trials ``reproduce`` runs on; see the module docstring. Problems raise :class:`InputError`.
    ``n_subjects`` (built-in data only) makes that many virtual subjects (default 2)."""
    for name, v, lo in (("seed", seed, 0), ("n_subjects", n_subjects, None)):
        if name == "n_subjects" and v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or (lo is not None and not lo <= v < 2**32):
            raise InputError(f"{name} must be an integer{' in [0, 2**32 - 1]' if lo is not None else ''}, got {v!r}")
    if n_subjects is not None and path is not None:
        raise InputError("--subjects makes built-in virtual subjects; it cannot be combined with --data")
    if seed != 0 and path is not None:  # it would be left unused: the data are the user's
        raise InputError(f"--data-seed {seed} seeds the built-in virtual subjects; it cannot be combined with --data")
    if marker_map is not None and path is not None and not Path(path).is_dir():
        raise InputError(
            "--markers names the markers of a folder of recordings; a trials file holds joint angles, no markers",
            path,
        )
    if n_subjects is not None and int(n_subjects) < 2:
        raise InputError(f"--subjects needs at least 2 subjects (one to learn from, one to predict), got {n_subjects}")
    if n_subjects is not None and int(n_subjects) > MAX_SUBJECTS:
        raise InputError(
            f"--subjects {n_subjects}: at most {MAX_SUBJECTS} built-in virtual subjects (as `reachirl "
            "synth --subjects`)"
        )
    if path is None:
        from ..virtual import builtin_dataset_dir

        n = 2 if n_subjects is None else int(n_subjects)
        folder = builtin_dataset_dir(seed, n)
        try:
            trials, truth = _builtin_trials(folder, marker_map), _read_truth(folder)
        except InputError as e:  # a cache file damaged since it was made (cut short, edited): made again, once
            if e.path is None or Path(folder).resolve() not in Path(str(e.path)).resolve().parents:
                raise  # not the cache's (a --markers map, say)
            import shutil

            log.warning("the cached built-in data set %s is damaged (%s); it is made again", folder, e)
            shutil.rmtree(folder, ignore_errors=True)
            folder = builtin_dataset_dir(seed, n)
            trials, truth = _builtin_trials(folder, marker_map), _read_truth(folder)
        return Dataset(
            tuple(trials),
            f"built-in virtual subjects ({n} subjects, seed {seed}): {folder}"
            if n != 2
            else f"built-in virtual subjects (seed {seed}): {folder}",
            "builtin",
            truth,
        )
    p = Path(path)
    if not p.exists():
        raise InputError("no such file or folder (expected a trials .npz or a folder with manifest.csv)", p)
    if p.is_dir():
        trials = preprocess_folder(p, marker_map)
        kind, truth = "folder", _read_truth(p)
    elif p.name.lower() == "manifest.csv":  # the folder's manifest given for the folder
        raise InputError(
            f"a manifest, not a trials file: give the folder that holds it (--data {p.parent}), or a trials .npz", p
        )
    else:
        trials = load_trials(p)
        kind, truth = "trials-file", _read_truth(p.parent)
    if not trials:
        raise InputError("holds no trials", p)
    return Dataset(tuple(trials), str(p.resolve()), kind, truth)  # absolute: `sensitivity` reloads it from anywhere


def toy(
    n_subjects: int = 2,
    postures: Sequence[str] = ("P2", "P4"),
    n_trials: int = 4,
    n_nodes: int = 40,
    seed: int = 0,
) -> Dataset:
    """A small in-memory virtual data set for tests and examples: DOC reaches (no markers, no preprocessing)
    from Berret's postures under the synth module's nominal weights, jittered per trial, with their truth.

    Subjects differ in anthropometrics; each trial jitters the start (2° SD), the duration (0.7 ± 0.04 s) and
    every weight (× exp(N(0, 0.2))). The bar is at 95 % of arm length.
    """
    from ..arm import ArmModel
    from ..data.trial import trial_from_solution
    from ..doc import ReachingTask, solve_doc
    from ..virtual import nominal_weights, posture_q

    rng = np.random.default_rng(seed)
    w_nom = nominal_weights()
    bodies = [(1.76, 70.0, "M"), (1.70, 63.0, "F"), (1.82, 80.0, "M"), (1.65, 58.0, "F")]
    trials, truth_subjects = [], {}
    for k in range(n_subjects):
        h, m, sex = bodies[k % len(bodies)]
        arm = ArmModel.from_anthropometrics(h + 0.01 * (k // len(bodies)), m, sex)
        sid = f"S{k + 1:02d}"
        truth_subjects[sid] = {"trials": {}}
        for p in postures:
            for i in range(n_trials):
                for _attempt in range(10):
                    q0 = posture_q(p) + np.deg2rad(rng.normal(0.0, 2.0, 2))
                    w = w_nom * np.exp(rng.normal(0.0, 0.2, w_nom.shape))
                    task = ReachingTask(arm, q0, 0.95 * arm.length, 0.7 + rng.normal(0.0, 0.04), n_nodes=n_nodes)
                    sol = solve_doc(task, w)
                    if sol.converged:
                        break
                else:  # pragma: no cover
                    raise RuntimeError(f"toy data: the DOC failed 10 times for {sid} {p}")
                tid = f"{sid}_{p}_T{i + 1:02d}"
                trials.append(trial_from_solution(sol, arm, task.target_x, sid, p, tid))
                truth_subjects[sid]["trials"].setdefault(p, []).append(
                    {"trial_id": f"T{i + 1:02d}", "file": f"{tid}.trc", "weights": w.tolist()}
                )
    truth = {
        "generator": "reachirl.experiments.datasets.toy",
        "n_windows": int(w_nom.shape[0]),
        "truth": {"nominal_weights": w_nom.tolist()},
        "subjects": truth_subjects,
    }
    return Dataset(tuple(trials), f"toy virtual subjects (seed {seed}, in memory)", "memory", truth)
