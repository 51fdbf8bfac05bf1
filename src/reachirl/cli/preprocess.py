"""``reachirl preprocess``: motion-capture files → a trials file (NPZ), one trial per input.

Per input file, the subject, posture, side and static trial come from (first found): the manifest row, the
command-line option, a UE-ADL file name (``ADL001FR3.csv`` → subject ADL001, right arm, trial FR3, posture
``forward``; its static ``ADL001_static.csv`` beside it), else the file's stem / ``default`` / ``right``. A
folder as INPUT stands for its reach files (``*.trc``, ``*.c3d``, ``*.mot``, ``*.sto`` and UE-ADL reaches);
a single folder that holds a ``manifest.csv`` stands for that manifest (and its ``subjects.csv`` for
``--subject-info``, its ``truth.json`` marker names for ``--markers``), as ``reproduce --data FOLDER`` reads it.

``--subject-info`` takes reachirl's CSV (``subject,sex,height_m,mass_kg[,upper_arm_m,forearm_m,hand_m]``) or
UE-ADL's ``subjects.csv`` as is. Without it, Berret 2011's mean subject (M, 1.76 m, 69.9 kg) is used, with a
note.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..data.exports import is_export
from ..data.markersets import load_markerset, parse_marker_map
from ..data.pipeline import preprocess_entries
from ..data.preprocess import PreprocessOptions
from ..data.readers import ANGLE_FORMATS, FORMATS, ManifestEntry, detect_format, read_manifest, read_subject_info
from ..data.trial import Trial, save_trials
from ..data.ue_adl import parse_trial_name
from ..errors import InputError
from ..io import holding_folder
from . import SUMMARIES
from ._args import (
    TRIALS_KIND,
    export_names,
    int_in,
    lab_axis_arg,
    number_in,
    output_folder_files,
    refuse_foreign_export_files,
    refuse_overwrite,
    regular_input,
)

_EXTS = (".trc", ".c3d", ".mot", ".sto")


def _segment_cutoff(text: str) -> float | str | None:
    """``auto``, or Hz in [0, 1000] (0: the --cutoff speed)."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return number_in(0.0, 1000.0)(text) or None
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected auto or a number of Hz in [0, 1000], got {text[:40]!r}") from None


def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "preprocess",
        help=SUMMARIES["preprocess"],
        description=__doc__.replace("``", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("inputs", nargs="*", metavar="INPUT", help="marker or joint-angle files, or folders")
    p.add_argument(
        "--out", required=True, metavar="TRIALS", help="trials file to write (NPZ, ending in .npz), exactly this path"
    )
    p.add_argument("--format", default="auto", choices=("auto", *FORMATS), help="input format (default: auto)")
    p.add_argument(
        "--markers",
        metavar="MAP",
        help="shoulder=A,elbow=B,wrist=C,fingertip=D (B1+B2: midpoint) (default: --markerset, else detected)",
    )
    p.add_argument(
        "--static",
        metavar="FILE",
        help="static calibration trial, for landmark-based marker sets (default: <subject>_static.csv beside "
        "each file, when the marker set needs one)",
    )
    p.add_argument(
        "--markerset",
        metavar="NAME|FILE",
        help="preset (ue-adl, default) or a JSON marker set (default: ue-adl when the file has its "
        "clusters, else default)",
    )
    p.add_argument(
        "--subject-info",
        metavar="CSV",
        help="CSV with subject,sex,height_m (m),mass_kg (kg)[,upper_arm_m,forearm_m,hand_m] (default: "
        "subjects.csv inside a single INPUT folder, else Berret 2011's mean subject)",
    )
    p.add_argument("--subject", metavar="ID", help="subject id (default: from the manifest or the file name)")
    p.add_argument(
        "--posture", metavar="NAME", help="posture / condition label (default: from the manifest, else 'default')"
    )
    p.add_argument(
        "--side",
        choices=("right", "left"),
        help="arm that moved; left arms are mirrored (default: from the manifest, else right)",
    )
    p.add_argument(
        "--manifest",
        metavar="CSV",
        help="CSV with the columns file,subject,posture[,side,static]; paths relative to it (default: "
        "manifest.csv inside a single INPUT folder, when there is one)",
    )
    p.add_argument(
        "--export",
        metavar="DIR",
        default=None,
        help="also write each processed trial (t, q, q̇, τ in SI and degrees) as DIR/<trial id>.csv and its "
        "angles as the OpenSim motion file DIR/<trial id>.mot (slashes in ids become _; DIR/index.csv maps them) "
        "(default: none)",
    )
    g = p.add_argument_group("processing options (defaults follow Berret et al. 2011)")
    d = PreprocessOptions()
    g.add_argument(
        "--cutoff",
        type=number_in(0.0, 1000.0),
        default=d.cutoff_hz,
        metavar="HZ",
        help=f"zero-lag Butterworth low-pass cutoff, 0 to 1000 Hz and below half the frame rate; "
        f"0: no filter (default {d.cutoff_hz:g})",
    )
    g.add_argument(
        "--filter-order",
        type=int_in(1, 8),
        default=d.filter_order,
        metavar="N",
        help=f"order of the Butterworth low-pass, 1 to 8, applied forward and backward (default {d.filter_order})",
    )
    g.add_argument(
        "--threshold",
        type=number_in(0.001, 0.9),
        default=d.onset_threshold,
        metavar="FRAC",
        help="onset/offset at this fraction of the peak fingertip speed, 0.001 to 0.9 (default 0.05)",
    )
    g.add_argument(
        "--segment-cutoff",
        type=_segment_cutoff,
        default=d.segment_cutoff_hz,
        metavar="HZ|auto",
        help="low-pass of the fingertip speed on which onset and offset are found: auto = only as low as the "
        "markers' noise needs (clean data keep the --cutoff speed), a number of Hz (0 to 1000), or 0 for the "
        f"--cutoff speed, as Berret (default {d.segment_cutoff_hz})",
    )
    g.add_argument(
        "--max-gap",
        type=int_in(0, 100000),
        default=d.max_gap_frames,
        metavar="FRAMES",
        help="longest gap filled by a cubic spline, 0 to 100000 (default 10); a longer one in the rest before or "
        "after the reach is cut off, with a warning",
    )
    g.add_argument(
        "--plane",
        choices=("pca", "vertical", "axes"),
        default=d.plane,
        help="sagittal plane: pca = principal plane of the joint centres (Berret), vertical = the "
        "vertical plane of the fingertip's travel, axes = --up-axis/--forward-axis (default pca)",
    )
    g.add_argument(
        "--up-axis",
        type=lab_axis_arg,
        metavar="AXIS",
        help="lab axis opposite gravity, e.g. +z (default: a C3D file's POINT:Y_SCREEN, else the marker set's, "
        "else the format's: +z Vicon/C3D, +y TRC)",
    )
    g.add_argument(
        "--forward-axis",
        type=lab_axis_arg,
        metavar="AXIS",
        help="lab forward axis, with --plane axes: the axis (x, y or z; its sign follows the reach's own "
        "direction, so +x and -x are one axis; default: the horizontal axis the fingertip moves along)",
    )
    g.add_argument(
        "--ik",
        choices=("segments", "fingertip"),
        default=d.ik,
        help="planar IK: segments = angles of the shoulder->elbow and elbow->distal directions, "
        "fingertip = 2-link IK of the fingertip alone (Berret) (default segments)",
    )
    g.add_argument(
        "--distal",
        choices=("fingertip", "wrist"),
        default=d.distal,
        help="with --ik segments: q2 from elbow->fingertip (the model's segment 2) or elbow->wrist (default fingertip)",
    )
    g.add_argument(
        "--n-samples",
        type=int_in(4, 100000),
        metavar="N",
        help="resample each trial to N points, 4 to 100000 (Berret: 200) (default: keep the recording's samples)",
    )
    return p


def _options(args) -> PreprocessOptions:
    if args.forward_axis and args.plane != "axes":  # it would be left unused: the plane comes from the markers
        raise InputError(f"--forward-axis is used with --plane axes only, not --plane {args.plane}")
    if args.distal != PreprocessOptions.distal and args.ik != "segments":  # unused: the IK reads the fingertip alone
        raise InputError(f"--distal {args.distal} is used with --ik segments only, not --ik {args.ik}")
    up, fwd = (a.strip().lower().lstrip("+-") if a else None for a in (args.up_axis, args.forward_axis))
    if up is not None and up == fwd:
        raise InputError(
            f"--up-axis {args.up_axis} and --forward-axis {args.forward_axis} are the same lab axis; the "
            "forward axis must be horizontal, e.g. --up-axis +y --forward-axis +x"
        )
    try:
        return PreprocessOptions(
            max_gap_frames=args.max_gap,
            cutoff_hz=args.cutoff or None,
            filter_order=args.filter_order,
            onset_threshold=args.threshold,
            segment_cutoff_hz=args.segment_cutoff,
            plane=args.plane,
            up_axis=args.up_axis,
            forward_axis=args.forward_axis,
            ik=args.ik,
            distal=args.distal,
            n_samples=args.n_samples,
        )
    except ValueError as e:
        raise InputError(str(e)) from None


def _motion_files(folder: Path) -> list[Path]:
    """The motion files under ``folder``, leaving out static trials and reachirl's own exports below it (an export
    into the data folder would otherwise be read back as new reaches; an export folder given itself is read)."""
    exports: dict[Path, bool] = {folder: False}

    def exported(d: Path) -> bool:
        if d not in exports:
            exports[d] = is_export(d)
        return exports[d]

    return sorted(
        f
        for f in folder.rglob("*")
        if f.is_file()
        and (f.suffix.lower() in _EXTS or (f.suffix.lower() == ".csv" and parse_trial_name(f)))
        and not f.stem.lower().endswith("_static")  # a static trial calibrates the reaches beside it
        and not exported(f.parent)
    )


def _expand(inputs: list[str]) -> list[Path]:
    """The motion files the INPUTs name: files as given, folders searched recursively (:func:`_motion_files`)."""
    out: list[Path] = []
    for s in inputs:
        p = Path(s)
        if not p.exists():
            raise InputError("file or folder not found", p)
        if p.is_dir():
            found = _motion_files(p)
            if not found:
                raise InputError("folder holds no motion files (*.trc, *.c3d, *.mot, *.sto, UE-ADL reaches)", p)
            out += found
        else:
            _refuse_non_reach(p)
            out.append(p)
    return out


def _refuse_non_reach(p: Path) -> None:
    """A file given by name that is not a reach, as a shell glob (``ADL001/*.csv``) names them beside the reaches:
    a static trial, or UE-ADL's joint angles of the data's authors (a folder scan leaves both out)."""
    if p.stem.lower().endswith("_static"):
        raise InputError(
            "a static calibration trial, not a reach: leave it out of the INPUTs (it is found beside each reach, "
            "or give it with --static)",
            p,
        )
    if p.suffix.lower() == ".csv" and p.stem.lower().endswith("angles") and parse_trial_name(p.with_name(p.stem[:-6])):
        raise InputError(
            f"the data authors' joint angles of {p.stem[:-6]}{p.suffix}, not a recording: give the reach files "
            "(ADLxxxF[RL]n.csv) or their folder",
            p,
        )


def _summary(tr: Trial) -> str:
    speed = tr.arm.fingertip_speed(tr.q, tr.qd)
    q = np.degrees(tr.q)
    return (
        f"{tr.id}: {tr.duration:.2f} s, peak fingertip speed {speed.max():.2f} m/s, "
        f"q1 {q[:, 0].min():.0f}..{q[:, 0].max():.0f}°, q2 {q[:, 1].min():.0f}..{q[:, 1].max():.0f}°, "
        f"target x {tr.target_x:.3f} m"
    )


def _folder_defaults(args) -> None:
    """A single INPUT folder with a manifest.csv stands for its manifest (as ``reproduce --data FOLDER``), and
    its subjects.csv for --subject-info, unless they are given; ``args.notes`` says so, once the inputs pass."""
    args.notes = []
    if args.manifest or len(args.inputs) != 1 or not Path(args.inputs[0]).is_dir():
        return
    folder = Path(args.inputs[0])
    from ..virtual.files import refuse_unfinished

    refuse_unfinished(folder)
    if (folder / "manifest.csv").is_file():
        args.manifest = str(folder / "manifest.csv")
        args.inputs = []
        args.notes.append(f"note: using the folder's manifest {args.manifest}")
    if not args.subject_info and (folder / "subjects.csv").is_file():
        args.subject_info = str(folder / "subjects.csv")
        args.notes.append(f"note: using the folder's subject info {args.subject_info}")
    if not (args.markers or args.markerset) and (folder / "truth.json").is_file():  # virtual subjects
        from ..io import read_json

        m = read_json(folder / "truth.json").get("markers")
        if isinstance(m, dict):
            args.markers = ",".join(f"{k}={v}" for k, v in m.items())


def _refuse_overwrite(args, out: Path, entries: list[ManifestEntry]) -> list:
    """No output (the trials file, the --export files) is one of the files read: the recordings and their static
    trials, the manifest, the subject info, the marker set, the static trial. Returns those inputs."""
    inputs = [e.file for e in entries] + [e.static for e in entries if e.static is not None]
    inputs += [args.manifest, args.subject_info, args.static]
    if args.markerset and Path(args.markerset).is_file():
        inputs.append(args.markerset)
    refuse_overwrite({"--out": out}, inputs)
    if args.export is not None:
        refuse_overwrite({"--export": args.export}, inputs)
    return inputs


def _check_npz_name(out: Path) -> None:
    """A trials file is NPZ, named so (as simulate --render by its suffix): a trials.csv would hold an NPZ. Checked
    after the inputs are known, so that an --out naming an input is refused as that, before any preprocessing."""
    if out.suffix.lower() != ".npz":
        csv = "; CSV or MOT files of each trial: --export FOLDER" if out.suffix.lower() in (".csv", ".mot") else ""
        raise InputError(f"--out: a trials file is NPZ, its name must end in .npz{csv}", out)


def _marker_options(args) -> list[str]:
    """The options given that only a marker recording reads (the joint centres, the plane, the IK)."""
    d = PreprocessOptions()
    given = [
        f"--{n.replace('_', '-')}"
        for n in ("markers", "markerset", "static", "up_axis", "forward_axis")
        if getattr(args, n)
    ]
    return given + [f"--{n} {getattr(args, n)}" for n in ("plane", "ik", "distal") if getattr(args, n) != getattr(d, n)]


def _refuse_marker_options_for_angles(args, entries: list[ManifestEntry], given: list[str]) -> None:
    """Before any work: options that only a marker recording reads, given when every input is a joint-angle file
    (MOT, CSV), would be left unused; refused, naming the first."""
    if not given or not entries:
        return
    formats = {args.format if args.format != "auto" else detect_format(e.file) for e in entries}
    if formats <= set(ANGLE_FORMATS):
        raise InputError(
            f"{given[0]} applies to marker recordings (TRC, C3D, Vicon CSV), and every input is a joint-angle file "
            "(MOT, CSV): it would be left unused",
            entries[0].file,
        )


def _refuse_duplicate_ids(trials: list[Trial]) -> None:
    """Two recordings that make the same trial id (the same file name in two folders, or a file given twice)
    would make a trials file that every other command refuses: refused here, naming both."""
    seen: dict[str, Trial] = {}
    for tr in trials:
        if tr.id in seen:
            raise InputError(
                f"gives the trial id {tr.id!r} of {seen[tr.id].source}; ids must be unique (give each file once, "
                "or a manifest with distinct subjects, postures or trial names)",
                tr.source,
            )
        seen[tr.id] = tr


def run(args) -> int:
    from ..validation import check_output_dir, check_output_file

    options = _options(args)
    if args.markers and args.markerset:
        raise InputError("give --markers or --markerset, not both (--markers would win and --markerset be ignored)")
    out = check_output_file(args.out)
    if args.export is None:
        return _preprocess(args, options, out, None)
    # before any work: a folder in which files can be written, and not the trials file's
    check_output_dir(args.export, "--export")
    output_folder_files(args.export, ["index.csv"], [], "--export", {"--out": out})
    # one command at a time in the folder: a second export would remove the first one's index and files
    with holding_folder(args.export, "--export") as make:
        refuse_foreign_export_files(args.export, ["index.csv"], "--export")
        return _preprocess(args, options, out, make)


def _preprocess(args, options, out: Path, make_export) -> int:
    """The preprocessing, once the --export folder (if any) is held; ``make_export()`` makes it and holds it,
    before the first change."""
    from ..validation import check_output_kind

    marker_options = _marker_options(args)  # the user's own: a folder's truth.json may name markers below
    _folder_defaults(args)
    if args.manifest:
        entries = read_manifest(args.manifest)
        if args.inputs:  # the manifest describes the files given; each must be in it
            by_path = {e.file.resolve(): e for e in entries}
            picked = []
            for p in _expand(args.inputs):
                if p.resolve() not in by_path:
                    raise InputError(f"not listed in the manifest {args.manifest}", p)
                picked.append(by_path[p.resolve()])
            entries = picked
        for e in entries:  # before any work: not once the files listed before it are preprocessed
            regular_input(e.file, f"listed in the manifest {args.manifest}")
    else:
        if not args.inputs:
            raise InputError("no INPUT files (or give --manifest)")
        entries = [ManifestEntry(file=p, subject="", posture="") for p in _expand(args.inputs)]
    if args.static:
        regular_input(args.static, "--static")  # given, so it must exist, whether or not the marker set needs it
    for e in entries:  # so must a manifest row's static trial (it was ignored when the marker set needed none)
        if e.static is not None:
            regular_input(e.static, f"the manifest's 'static' of {e.file.name}")
    _refuse_marker_options_for_angles(args, entries, marker_options)
    from ..virtual.files import refuse_unfinished

    for folder in dict.fromkeys(Path(e.file).parent for e in entries):  # its recordings given one by one too
        refuse_unfinished(folder)
    inputs = _refuse_overwrite(args, out, entries)
    _check_npz_name(out)
    check_output_kind(out, ".npz", kind=TRIALS_KIND)
    infos = read_subject_info(args.subject_info) if args.subject_info else None
    markers = (
        parse_marker_map(args.markers) if args.markers else (load_markerset(args.markerset) if args.markerset else None)
    )
    for note in getattr(args, "notes", ()):  # after the inputs' checks: a refusal is one line
        print(note, file=sys.stderr)
    lines: list[str] = []
    trials = preprocess_entries(
        entries,
        subject_info=infos,
        markers=markers,
        static=Path(args.static) if args.static else None,
        options=options,
        fmt=args.format,
        subject=args.subject,
        posture=args.posture,
        side=args.side,
        on_trial=lambda tr: lines.append(_summary(tr)),
    )
    _refuse_duplicate_ids(trials)
    if args.export is not None:  # the export's file names follow the trial ids: checked before anything is written
        names = export_names(tr.id for tr in trials)
        output_folder_files(args.export, names, inputs, "--export", {"--out": out})
        refuse_foreign_export_files(args.export, names, "--export", inputs)
    if args.export is not None:
        make_export()  # held before the first change (a folder made meanwhile by another command: refused)
    # the trials file last, an earlier one removed first: an interrupt never leaves it beside another export
    out.unlink(missing_ok=True)
    if args.export is not None:
        from ..data.exports import TrajectoryExport, export_trajectories

        export_trajectories(
            args.export,
            [
                TrajectoryExport(id=tr.id, t=tr.t, side=tr.side, demo={"q": tr.q, "qd": tr.qd, "tau": tr.tau})
                for tr in trials
            ],
        )
    save_trials(out, trials)
    if infos is None:
        print(
            "note: no --subject-info; masses and inertias use Berret 2011's mean subject (M, 1.76 m, 69.9 kg)",
            file=sys.stderr,
        )
    for ln in lines:
        print(ln)
    print(f"wrote {len(trials)} trial(s) to {out}")
    if args.export is not None:
        print(f"wrote {len(trials)} trajectories (.csv, .mot) and index.csv to {args.export}")
    return 0
