"""The virtual data set as files (marker files, manifest, subject info, truth), and the cached built-in data set."""

from __future__ import annotations

import concurrent.futures as cf
import csv
import hashlib
import io
import json
import logging
import multiprocessing
import os
import re
import shutil
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from ..data.writers import write_c3d, write_mot, write_trc
from ..errors import InputError
from ..features import FEATURES
from ..io import atomic_write_json, atomic_write_text, cache_root, csv_column, sync_folder, to_jsonable
from ..workers import die_with_parent
from .likeness import human_likeness
from .population import (
    _LOG_WEIGHT_SD,
    _POSTURE_SD_DEG,
    BERRET_DURATIONS_S,
    BERRET_POSTURES_DEG,
    FEATURE_SCALE,
    MOVEMENT_FRACTION,
    RELATIVE_IMPORTANCE,
    SynthSubject,
    draw_subject,
    nominal_weights,
    posture_q,
)
from .recording import SynthConfig, SynthTrial, _simulate_group, check_relative_importance, to_opensim_axes

log = logging.getLogger(__name__)

GENERATOR_VERSION = 5  # bump whenever the generated files change for the same seed


@dataclass(frozen=True)
class SynthResult:
    out_dir: Path
    config: SynthConfig
    subjects: tuple[SynthSubject, ...]
    trials: tuple[SynthTrial, ...]
    doc_failures: int
    elapsed_s: float
    human_likeness: tuple[dict, ...] = ()


def _csv_text(header: Sequence[str], rows: Sequence[Sequence]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


#: a recording's name as :func:`_file_name` makes it (an earlier data set's, in its manifest)
_RECORDING = re.compile(r"S\d+_P\d+_T\d+\.(trc|c3d|mot)")


def _file_name(tr: SynthTrial, fmt: str) -> str:
    return f"{tr.subject}_{tr.posture}_{tr.trial_id}.{fmt}"


def _run_groups(subjects, config: SynthConfig) -> list[SynthTrial]:
    groups = [(s, p) for s in subjects for p in config.postures]
    workers = max(1, int(config.workers))
    if multiprocessing.current_process().daemon:
        workers = 1  # a daemonic process (e.g. a pool worker) may not have children
    if workers == 1 or len(groups) == 1:
        return [tr for s, p in groups for tr in _simulate_group(s, p, config)]
    # fork is cheap and works from unguarded scripts; never fork a process that runs other threads
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("fork" if "fork" in methods and threading.active_count() == 1 else "spawn")
    ex = cf.ProcessPoolExecutor(
        max_workers=min(workers, len(groups)), mp_context=ctx, initializer=_worker_signals, initargs=(os.getpid(),)
    )
    try:
        futures = [ex.submit(_simulate_group, s, p, config) for s, p in groups]
        trials = [tr for f in futures for tr in f.result()]
    except BaseException:  # Ctrl-C, SIGTERM or an error: end the workers now, not after their groups
        procs = list(getattr(ex, "_processes", {}).values())  # no public API for the worker processes
        ex.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        for proc in procs:
            proc.join(timeout=2.0)
            if proc.is_alive():
                proc.kill()
        raise
    ex.shutdown(wait=True)
    return trials


SYNTH_FILES = ("manifest.csv", "subjects.csv", "truth.json", "human_likeness.csv")
"""The files ``generate`` writes beside the recordings."""

INCOMPLETE = "synth-incomplete.json"
"""Present while ``generate`` writes a data set (removed once ``truth.json`` is written): a folder holding it is a
set that was interrupted, which a rerun finishes; it lists the recordings that set was writing."""


def refuse_unfinished(folder: str | Path) -> None:
    """An :class:`InputError` when ``folder`` is a synth data set interrupted while its files were written
    (:data:`INCOMPLETE`): its recordings are a part of a set, described by nothing."""
    if (Path(folder) / INCOMPLETE).is_file():
        raise InputError(
            f"an unfinished synth data set ({INCOMPLETE}: interrupted while its files were written); rerun "
            "`reachirl synth --out` into it to finish it",
            folder,
        )


def _ours(path: Path, max_bytes: int = 256 * 1024**2) -> dict | None:
    """``path`` read as JSON when ``reachirl synth`` wrote it (its ``generator``), else None."""
    try:
        if path.stat().st_size < max_bytes:  # a synth truth.json of 100 subjects is a few MB
            data = json.loads(path.read_text())
            if isinstance(data, dict) and data.get("generator") == "reachirl.synth":
                return data
    except (OSError, ValueError):
        pass
    return None


def synth_folder_clash(out_dir: str | Path) -> str | None:
    """The first file in ``out_dir`` that ``generate`` could replace (:data:`SYNTH_FILES`, or a recording named as
    synth names them) when ``out_dir`` is not an earlier synth data set (one whose ``truth.json``, written last,
    says ``reachirl synth`` made it, or one interrupted while it was written: :data:`INCOMPLETE`); else None."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return None
    if _ours(out_dir / "truth.json") is not None or _ours(out_dir / INCOMPLETE) is not None:
        return None
    names = sorted(f.name for f in out_dir.iterdir())
    return next((n for n in names if n in SYNTH_FILES or _RECORDING.fullmatch(n)), None)


def _worker_signals(parent_pid: int | None = None) -> None:
    """A generation worker: Ctrl-C is the parent's business (it ends the workers), SIGTERM ends it at once, and it
    dies with its parent ``parent_pid``, even a SIGKILLed one (a forked worker otherwise waited for its next group
    forever, holding the parent's standard output and error open)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if parent_pid is not None:
        die_with_parent(parent_pid)


def generate(out_dir: str | Path, config: SynthConfig | None = None) -> SynthResult:
    """Generate the virtual data set of ``config`` into ``out_dir`` (created if needed).

        Writes one file per trial (``S01_P1_T01.trc`` …), ``manifest.csv`` (``file,subject,posture,side``),
        ``subjects.csv`` (``subject,sex,height_m,mass_kg,upper_arm_m,forearm_m,hand_m``), ``truth.json`` and
        ``human_likeness.csv``. The same config gives byte-identical files. Into the folder of an earlier data set,
        the recordings its ``manifest.csv`` listed and this one does not write are removed (the folder holds what its
        manifest and ``truth.json`` describe; other files stay). Its ``truth.json``, manifest and the other files
        above are removed before the first recording is written and written again last (``truth.json`` the very
        last), so an interrupted run never leaves new recordings described by the earlier set; while the recordings are
    written, :data:`INCOMPLETE` says so (a rerun into the folder finishes it). A folder that holds
        one of these files and is not an earlier data set (:func:`synth_folder_clash`) is refused by ``reachirl
        synth`` before any work.
    """
    config = config or SynthConfig()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    subjects = tuple(draw_subject(config.seed, i) for i in range(config.n_subjects))
    trials = _run_groups(subjects, config)
    failures = sum(tr.doc_retries for tr in trials)
    earlier = set(csv_column(out_dir / "manifest.csv", "file"))
    earlier |= set((_ours(out_dir / INCOMPLETE) or {}).get("recordings") or ())  # an interrupted set's
    earlier = {n for n in earlier if isinstance(n, str) and _RECORDING.fullmatch(n)}
    for name in SYNTH_FILES:  # the earlier set's description goes before its recordings change
        (out_dir / name).unlink(missing_ok=True)
    names = [_file_name(tr, config.fmt) for tr in trials]
    atomic_write_json(out_dir / INCOMPLETE, {"generator": "reachirl.synth", "recordings": sorted(earlier | set(names))})
    manifest = []
    for tr in trials:
        name = _file_name(tr, config.fmt)
        if config.fmt == "trc":
            write_trc(out_dir / name, tr.time, to_opensim_axes(tr.markers), units="mm", rate=config.rate_hz)
        elif config.fmt == "c3d":
            write_c3d(out_dir / name, tr.time, tr.markers, units="mm", rate=config.rate_hz)
        else:
            write_mot(out_dir / name, tr.time, tr.angles_deg, columns=("q1", "q2"))
        manifest.append([name, tr.subject, tr.posture, "right"])
    for name in earlier - {row[0] for row in manifest}:
        (out_dir / name).unlink(missing_ok=True)
    atomic_write_text(
        out_dir / "subjects.csv",
        _csv_text(
            ("subject", "sex", "height_m", "mass_kg", "upper_arm_m", "forearm_m", "hand_m"),
            [[s.subject, s.sex, s.height_m, s.mass_kg, s.upper_arm_m, s.forearm_m, s.hand_m] for s in subjects],
        ),
    )
    hl = human_likeness(trials, subjects)
    keys = list(hl[0])
    atomic_write_text(
        out_dir / "human_likeness.csv",
        _csv_text(keys, [[f"{r[k]:.6g}" if isinstance(r[k], float) else r[k] for k in keys] for r in hl]),
    )
    atomic_write_text(out_dir / "manifest.csv", _csv_text(("file", "subject", "posture", "side"), manifest))
    atomic_write_json(out_dir / "truth.json", _truth(config, subjects, trials, failures, hl))
    (out_dir / INCOMPLETE).unlink(missing_ok=True)
    elapsed = time.perf_counter() - t0
    log.info(
        "generated %d trials of %d subjects in %.1f s (%d DOC failures redrawn)",
        len(trials),
        len(subjects),
        elapsed,
        failures,
    )
    return SynthResult(out_dir, config, subjects, tuple(trials), failures, elapsed, tuple(hl))


def _truth(config, subjects, trials, failures, hl) -> dict:
    subj = {}
    for s in subjects:
        d = asdict(s)
        d["arm"] = s.arm.to_dict()
        d["target_x_m"] = config.target_fraction * s.arm.length
        d["trials"] = {}
        subj[s.subject] = d
    for tr in trials:
        subj[tr.subject]["trials"].setdefault(tr.posture, []).append(
            {
                "trial_id": tr.trial_id,
                "file": _file_name(tr, config.fmt),
                "weights": tr.weights,
                "q0_deg": np.rad2deg(tr.q0),
                "horizon_s": tr.horizon_s,
                "onset_s": tr.onset_s,
                "offset_s": tr.onset_s + tr.horizon_s,
                "doc_retries": tr.doc_retries,
                "doc_iterations": tr.doc_iterations,
            }
        )
    return {
        "generator": "reachirl.synth",
        "version": GENERATOR_VERSION,
        "config": _config_fields(config),
        "features": list(FEATURES),
        "n_windows": len(_relative_importance(config)),
        "markers": {"shoulder": "SHO", "elbow": "ELB", "wrist": "WRI", "fingertip": "FTP"},
        "units": {
            "markers": "mm",
            "axes": "C3D: lab, Z up; TRC: OpenSim, Y up ((X, Z, -Y) of the lab); movement plane rotated "
            "about the vertical",
            "mot": "degrees, q1 q2 in reachirl's convention",
            "weights": "SI (features are raw SI quantities)",
        },
        "postures": {
            p: {
                "berret_elbow_deg": e,
                "berret_shoulder_deg": sh,
                "q_deg": np.rad2deg(posture_q(p)),
                "berret_duration_s": BERRET_DURATIONS_S[p],
            }
            for p, (e, sh) in BERRET_POSTURES_DEG.items()
        },
        "posture_convention": "q1 = -shoulder, q2 = -elbow (Berret's angles from the forward horizontal, "
        "clockwise in reachirl's x-forward/y-up frame)",
        "truth": {
            "definition": "weights = relative_importance / feature_scale, per window (rows) and feature (columns)",
            "relative_importance": _relative_importance(config),
            "feature_scale": FEATURE_SCALE,
            "nominal_weights": nominal_weights(_relative_importance(config)),
            "jitter": {
                "log_weight_sd": _LOG_WEIGHT_SD,
                "posture_sd_deg": _POSTURE_SD_DEG,
                "duration": "Berret's SD per posture",
                "movement_fraction": MOVEMENT_FRACTION,
            },
        },
        "subjects": subj,
        "doc_failures": failures,
        "human_likeness": hl,
    }


def _number(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None


def read_relative_importance(path: str | Path) -> tuple[tuple[float, ...], ...]:
    """A true cost for :class:`SynthConfig` from a CSV: a header naming the 7 features (any order, each once;
    an optional first column ``window``), then one row per time window, each feature's relative importance in
    that window (≥ 0, each row with a positive sum). Problems raise :class:`InputError` naming the file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError("no such file (expected a CSV of relative importance per window and feature)", p) from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read ({getattr(e, 'strerror', None) or e})", p) from None
    rows = [r for r in csv.reader(io.StringIO(text)) if any(c.strip() for c in r)]
    if not rows:
        raise InputError("is empty: expected a header naming the 7 features, then one row per window", p)
    header = [c.strip() for c in rows[0]]
    cols = header[1:] if header and header[0] == "window" else header
    unknown = [c for c in cols if c not in FEATURES]
    missing = [f for f in FEATURES if f not in cols]
    if unknown or missing or len(cols) != len(FEATURES):
        what = (
            f"unknown column {unknown[0]!r}"
            if unknown
            else f"no column {missing[0]!r}"
            if missing
            else "a repeated column"
        )
        raise InputError(f"header: {what}; expected the features {', '.join(FEATURES)}", p)
    skip = len(header) - len(cols)
    values = []
    for line, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise InputError(f"row {line}: {len(r)} cells where the header has {len(header)}", p)
        try:
            by_name = dict(zip(cols, (float(c) for c in r[skip:]), strict=True))
        except ValueError:
            raise InputError(f"row {line}: expected numbers, found {','.join(r)[:60]!r}", p) from None
        if skip and _number(r[0]) != len(values) + 1:  # the rows are taken in order: a window out of it
            raise InputError(  # would land in another window's place, silently
                f"row {line}: window {r[0].strip()!r} where {len(values) + 1} was expected (the windows numbered "
                "1, 2, ... in order, one row each)",
                p,
            )
        values.append([by_name[f] for f in FEATURES])
    try:
        return check_relative_importance(values if values else np.zeros((0, len(FEATURES))))
    except ValueError as e:
        raise InputError(str(e), p) from None


# ---------------------------------------------------------------------- the built-in data set (cached)
def _builtin_config(seed: int) -> SynthConfig:
    return SynthConfig(n_subjects=2, n_trials=20, seed=seed, fmt="trc", workers=2)


def _relative_importance(config: SynthConfig) -> np.ndarray:
    return RELATIVE_IMPORTANCE if config.relative_importance is None else np.array(config.relative_importance)


def _config_fields(config: SynthConfig) -> dict:
    """The config as ``truth.json`` and the cache key hold it: the true cost is written (and keyed) once, as
    ``truth.relative_importance``."""
    return {k: v for k, v in asdict(config).items() if k not in ("workers", "relative_importance")}


def _cache_key(config: SynthConfig) -> str:
    payload = json.dumps(
        to_jsonable(
            {
                "v": GENERATOR_VERSION,
                "config": _config_fields(config) | {"workers": 0},
                "ri": _relative_importance(config),
                "fs": FEATURE_SCALE,
            }
        ),
        sort_keys=True,
    )
    return f"synth-v{GENERATOR_VERSION}-seed{config.seed}-{hashlib.sha256(payload.encode()).hexdigest()[:10]}"


def builtin_dataset_dir(seed: int = 0, n_subjects: int = 2) -> Path:
    """The built-in data set (2 subjects × 5 postures × 20 trials, TRC), generated on first use and cached.

    ``n_subjects`` draws that many subjects from the same population (``reachirl reproduce --subjects N``;
    20 is Berret 2011's full design). Subjects and trials are drawn per index, so subject ``S01`` and its trials
    are the same for every ``n_subjects``.

    Returns the folder with the TRC files, ``manifest.csv``, ``subjects.csv`` and ``truth.json``. It is built
    in a temporary folder (each file synced to the disk) and renamed into place, the rename synced too, so a
    half-written cache is never used, even after a crash of the system.
    """
    config = _builtin_config(int(seed))
    if int(n_subjects) != config.n_subjects:
        config = replace(config, n_subjects=int(n_subjects))
    root = cache_root()
    final = root / _cache_key(config)
    if final.is_dir() and (final / "truth.json").is_file():
        return final
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".tmp-synth-", dir=root))
    try:
        log.info("generating the built-in data set (seed %d) into %s", seed, final)
        generate(tmp, config)
        try:
            os.rename(tmp, final)
            sync_folder(root)  # the rename on the disk: a crash leaves no cache or the whole one
        except OSError:
            if not (final / "truth.json").is_file():  # not a concurrent winner: a real error
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final
