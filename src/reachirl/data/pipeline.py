"""Files to trials: the whole preprocessing of a list of recordings (what ``reachirl preprocess`` runs).

For each file, the subject, posture, side and static trial come from (first found): its manifest row, the
defaults given here, a UE-ADL file name (``ADL001FR3.csv`` → subject ADL001, right arm, trial FR3, posture
``forward``; its static ``ADL001_static.csv`` beside it), else the file's stem / ``default`` / ``right``.
The marker set is the one given, else ``ue-adl`` when the file has UE-ADL's clusters, else ``default``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from ..errors import InputError
from .checks import check_start_and_target, check_trial_posture
from .markersets import MarkerSet, load_markerset, resolve_name
from .preprocess import DEFAULT_SUBJECT, PreprocessOptions, angles_to_trial, markers_to_trial
from .readers import AngleData, ManifestEntry, MarkerData, SubjectInfo, read_file, read_manifest, read_subject_info
from .trial import Trial
from .ue_adl import find_static, parse_trial_name

__all__ = ["auto_markerset", "preprocess_entries", "preprocess_manifest"]

log = logging.getLogger(__name__)


def auto_markerset(md: MarkerData) -> MarkerSet:
    """``ue-adl`` when the recording has UE-ADL's fingertip and upper-arm cluster (either side), else ``default``."""
    if any(resolve_name(f"{pre}FTP", md.names) and resolve_name(f"{pre}UAR1", md.names) for pre in ("R", "L")):
        return load_markerset("ue-adl")
    return load_markerset("default")


def preprocess_entries(
    entries: Sequence[ManifestEntry],
    *,
    subject_info: Mapping[str, SubjectInfo] | None = None,
    markers: MarkerSet | None = None,
    static: Path | None = None,
    options: PreprocessOptions | None = None,
    fmt: str = "auto",
    subject: str | None = None,
    posture: str | None = None,
    side: str | None = None,
    on_trial: Callable[[Trial], None] | None = None,
) -> list[Trial]:
    """One :class:`Trial` per entry. Without ``subject_info``, Berret 2011's mean subject is used (logged at INFO;
    ``reachirl preprocess`` notes it once it has written the trials). A recording's warnings are logged once its
    trial passes the posture and target checks: a refused recording gets its refusal alone."""
    if subject_info is None:
        log.info("no subject info: masses and inertias use Berret 2011's mean subject (M, 1.76 m, 69.9 kg)")
    statics: dict[Path, MarkerData] = {}
    trials: list[Trial] = []
    for e in entries:
        ue = parse_trial_name(e.file)
        subj = e.subject or subject or (ue[0] if ue else e.file.stem)
        given = e.side or side or (ue[1] if ue else None)
        sd = given or "right"
        post = e.posture or posture or ("forward" if ue else "default")
        trial_id = ue[2] if ue else e.file.stem
        if subject_info is not None and subj not in subject_info:
            raise InputError(f"subject {subj!r} is not in the subject-info file", e.file)
        info = subject_info[subj] if subject_info is not None else DEFAULT_SUBJECT
        data = read_file(e.file, fmt, side=sd)
        if isinstance(data, AngleData) and data.side is not None and data.side != sd:
            if given is not None:  # read as the other arm's, it would be labelled and built as this one
                raise InputError(
                    f"its angle columns are the {data.side} arm's, but the trial is given as the {sd} arm's (give "
                    f"--side {data.side} or the manifest's side column)",
                    e.file,
                )
            sd = data.side  # no side given: the arm the columns name (reachirl's own export of a left trial)
        held: list[tuple] = []
        common = {
            "subject": subj,
            "posture": post,
            "trial_id": trial_id,
            "side": sd,
            "subject_info": info,
            "options": options,
        }
        if isinstance(data, MarkerData):
            mset = markers or auto_markerset(data)
            static_md = None
            if not mset.needs_static and (e.static or static):  # it would be left unread
                raise InputError(
                    f"a static trial is given ({e.static or static}), but marker set {mset.name!r} places every "
                    "joint from this file's markers and reads none: leave it out, or give a marker set with "
                    "landmarks (--markerset)",
                    e.file,
                )
            if mset.needs_static:
                sp = e.static or static or (find_static(e.file, subj, mset.static) if mset.static else None)
                if sp is None:
                    raise InputError(
                        f"marker set {mset.name!r} needs a static trial: give --static, a manifest 'static' "
                        f"column, or put {subj}_static.csv beside the file",
                        e.file,
                    )
                if sp not in statics:
                    md = read_file(sp, "auto")
                    if not isinstance(md, MarkerData):
                        raise InputError("static trial holds joint angles, expected markers", sp)
                    statics[sp] = md
                static_md = statics[sp]
                mine, its = set(data.labelled_subjects), set(static_md.labelled_subjects)
                if mine and its and not mine & its:  # Vicon names the subject before each marker
                    raise InputError(
                        f"the static trial {sp} was recorded on {', '.join(sorted(its))}, this reach on "
                        f"{', '.join(sorted(mine))} (the subject before the marker names): give the subject's own "
                        f"static trial",
                        e.file,
                    )
            tr = markers_to_trial(data, mset, static=static_md, held=held, **common)
        else:
            tr = angles_to_trial(data, held=held, **common)
        check_trial_posture(tr, e.file)  # a mirrored or backwards recording is caught here, where it can be fixed
        check_start_and_target(tr, e.file)  # as load_trials will check it
        for warning in held:  # said of a trial accepted, not before its refusal
            log.warning(*warning)
        trials.append(tr)
        if on_trial is not None:
            on_trial(tr)
    return trials


def preprocess_manifest(
    manifest: str | Path,
    subject_info: str | Path | None = None,
    markers: MarkerSet | None = None,
    options: PreprocessOptions | None = None,
) -> list[Trial]:
    """Every file of a manifest CSV (``file,subject,posture[,side][,static]``) to a :class:`Trial`."""
    infos = read_subject_info(subject_info) if subject_info is not None else None
    return preprocess_entries(read_manifest(manifest), subject_info=infos, markers=markers, options=options)
