"""``reachirl preprocess``: motion-capture files → a trials file (NPZ), one trial per input.

Per input file, the subject, posture, side and static trial come from (first found): the manifest row, the
command-line option, a UE-ADL file name (``ADL001FR3.csv`` → subject ADL001, right arm, trial FR3, posture
``forward``; its static ``ADL001_static.csv`` beside it), else the file's stem / ``default`` / ``right``. A
folder as INPUT stands for its reach files (``*.trc``, ``*.c3d``, ``*.mot``, ``*.sto`` and UE-ADL reaches).

``--subject-info`` takes reachirl's CSV (``subject,sex,height_m,mass_kg[,upper_arm_m,forearm_m,hand_m]``) or
UE-ADL's ``subjects.csv`` as is. Without it, Berret 2011's mean subject (M, 1.76 m, 69.9 kg) is used, with a
note.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..data.markersets import load_markerset, parse_marker_map
from ..data.pipeline import preprocess_entries
from ..data.preprocess import PreprocessOptions
from ..data.readers import FORMATS, ManifestEntry, read_manifest, read_subject_info
from ..data.trial import Trial, save_trials
from ..data.ue_adl import parse_trial_name
from ..errors import InputError
from ._args import int_in, number_in

_EXTS = (".trc", ".c3d", ".mot", ".sto")


def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "preprocess",
        help="motion-capture files -> trials (q, qd, qdd, tau on the subject's planar arm)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("inputs", nargs="*", metavar="INPUT", help="marker or joint-angle files, or folders")
    p.add_argument(
        "--out", required=True, metavar="TRIALS", help="trials file to write (NPZ), exactly this path"
    )
    p.add_argument(
        "--format", default="auto", choices=("auto", *FORMATS), help="input format (default: auto)"
    )
    p.add_argument(
        "--markers", metavar="MAP", help="shoulder=A,elbow=B,wrist=C,fingertip=D (B1+B2: midpoint)"
    )
    p.add_argument(
        "--static", metavar="FILE", help="static calibration trial (for landmark-based marker sets)"
    )
    p.add_argument("--markerset", metavar="NAME|FILE", help="preset (ue-adl, default) or a JSON marker set")
    p.add_argument("--subject-info", metavar="CSV", help="subject,sex,height_m,mass_kg[,upper_arm_m,...]")
    p.add_argument("--subject", metavar="ID", help="subject id (default: from the file name)")
    p.add_argument("--posture", metavar="NAME", help="posture / condition label")
    p.add_argument("--side", choices=("right", "left"), help="arm that moved (left arms are mirrored)")
    p.add_argument(
        "--manifest", metavar="CSV", help="file,subject,posture[,side,static]; paths relative to it"
    )
    g = p.add_argument_group("processing options (defaults follow Berret et al. 2011)")
    d = PreprocessOptions()
    g.add_argument("--cutoff", type=number_in(0.0, 1000.0), default=d.cutoff_hz, metavar="HZ",
                   help=f"low-pass cutoff, 0 to 1000 Hz and below half the frame rate; 0: none "
                   f"(default {d.cutoff_hz:g})")
    g.add_argument("--filter-order", type=int_in(1, 8), default=d.filter_order, metavar="N",
                   help=f"Butterworth order, 1 to 8 (default {d.filter_order}); --cutoff 0 turns the filter off")
    g.add_argument(
        "--threshold",
        type=number_in(0.001, 0.9),
        default=d.onset_threshold,
        metavar="FRAC",
        help="onset/offset at this fraction of the peak fingertip speed, 0.001 to 0.9 (default 0.05)",
    )
    g.add_argument(
        "--max-gap",
        type=int_in(0, 100000),
        default=d.max_gap_frames,
        metavar="FRAMES",
        help="longest gap filled by a cubic spline, 0 to 100000 (default 10)",
    )
    g.add_argument("--plane", choices=("pca", "vertical", "axes"), default=d.plane)
    g.add_argument("--up-axis", metavar="AXIS", help="lab axis opposite gravity (+z Vicon/C3D, +y TRC)")
    g.add_argument("--forward-axis", metavar="AXIS", help="lab forward axis, with --plane axes")
    g.add_argument("--ik", choices=("segments", "fingertip"), default=d.ik)
    g.add_argument(
        "--distal",
        choices=("fingertip", "wrist"),
        default=d.distal,
        help="q2 from elbow->fingertip (model's segment 2) or elbow->wrist",
    )
    g.add_argument("--n-samples", type=int_in(4, 100000), metavar="N",
                   help="resample each trial to N points, 4 to 100000 (Berret: 200)")
    return p


def _options(args) -> PreprocessOptions:
    try:
        return PreprocessOptions(
            max_gap_frames=args.max_gap,
            cutoff_hz=args.cutoff or None,
            filter_order=args.filter_order,
            onset_threshold=args.threshold,
            plane=args.plane,
            up_axis=args.up_axis,
            forward_axis=args.forward_axis,
            ik=args.ik,
            distal=args.distal,
            n_samples=args.n_samples,
        )
    except ValueError as e:
        raise InputError(str(e)) from None


def _expand(inputs: list[str]) -> list[Path]:
    out: list[Path] = []
    for s in inputs:
        p = Path(s)
        if p.is_dir():
            found = sorted(
                f
                for f in p.rglob("*")
                if f.is_file()
                and (f.suffix.lower() in _EXTS or (f.suffix.lower() == ".csv" and parse_trial_name(f)))
            )
            if not found:
                raise InputError(
                    "folder holds no motion files (*.trc, *.c3d, *.mot, *.sto, UE-ADL reaches)", p
                )
            out += found
        else:
            out.append(p)
    return out


def _summary(tr: Trial) -> str:
    speed = np.linalg.norm(tr.arm.fingertip_velocity(tr.q, tr.qd), axis=1)
    q = np.degrees(tr.q)
    return (
        f"{tr.id}: {tr.duration:.2f} s, peak fingertip speed {speed.max():.2f} m/s, "
        f"q1 {q[:, 0].min():.0f}..{q[:, 0].max():.0f}°, q2 {q[:, 1].min():.0f}..{q[:, 1].max():.0f}°, "
        f"target x {tr.target_x:.3f} m"
    )


def run(args) -> int:
    from ..validation import check_output_file

    options = _options(args)
    out = check_output_file(args.out)
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
    else:
        if not args.inputs:
            raise InputError("no INPUT files (or give --manifest)")
        entries = [ManifestEntry(file=p, subject="", posture="") for p in _expand(args.inputs)]
    infos = read_subject_info(args.subject_info) if args.subject_info else None
    markers = (
        parse_marker_map(args.markers)
        if args.markers
        else (load_markerset(args.markerset) if args.markerset else None)
    )
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
    save_trials(out, trials)
    if infos is None:
        print(
            "note: no --subject-info; masses and inertias use Berret 2011's mean subject "
            "(M, 1.76 m, 69.9 kg)",
            file=sys.stderr,
        )
    for ln in lines:
        print(ln)
    print(f"wrote {len(trials)} trial(s) to {out}")
    return 0
