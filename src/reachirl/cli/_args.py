"""Argument types shared by the subcommands: bad values become argparse's one-line usage error (exit 2)."""

from __future__ import annotations

import argparse
import os
import re
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError


def _checked(
    convert: Callable[[str], float], ok: Callable[[float], bool], expected: str, trim: int | None = None
) -> Callable[[str], float]:
    """A parser: ``convert(text)``, refused with ``expected {expected}, got …`` when it fails or ``ok`` is
    False. The message echoes the value, or with ``trim`` the text cut to that many characters."""

    def parse(text: str):
        try:
            v = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text[:trim]!r}") from None
        if not ok(v):  # False for NaN in every range below
            raise argparse.ArgumentTypeError(f"expected {expected}, got {v if trim is None else text[:trim]}")
        return v

    return parse


def file_path(text: str) -> Path:
    """An output file's path; one that ends with '/' names a folder (``Path`` would drop the slash, and the command
    write a file by the folder's name)."""
    if text.endswith(("/", os.sep)):
        raise argparse.ArgumentTypeError(f"expected a file path, got a folder ({text[:200]!r} ends with '/')")
    return Path(text)


def int_at_least(lo: int) -> Callable[[str], int]:
    """An integer ``>= lo``."""
    return _checked(int, lambda v: v >= lo, f"an integer >= {lo}")


def float_in(lo: float, hi: float) -> Callable[[str], float]:
    """A number in ``[lo, hi)``."""
    return _checked(float, lambda v: lo <= v < hi, f"a number in [{lo}, {hi})")


positive_int = int_at_least(1)
non_negative_int = int_at_least(0)


def int_in(lo: int, hi: int) -> Callable[[str], int]:
    """An integer in ``[lo, hi]`` (the limits go in the option's help)."""
    return _checked(int, lambda v: lo <= v <= hi, f"an integer in [{lo}, {hi}]", trim=40)


def samples_or_none(lo: int, hi: int) -> Callable[[str], int]:
    """``0`` (none) or an integer in ``[lo, hi]``: a number of weight samples (``reproduce --uncertainty``)."""
    return _checked(int, lambda v: v == 0 or lo <= v <= hi, f"0 (none) or an integer in [{lo}, {hi}]", trim=40)


def number_in(lo: float, hi: float) -> Callable[[str], float]:
    """A finite number in ``[lo, hi]`` (NaN and infinities are refused)."""
    return _checked(float, lambda v: lo <= v <= hi, f"a number in [{lo:g}, {hi:g}]", trim=40)


def lab_axis_arg(text: str) -> str:
    """A lab axis ``±x``, ``±y`` or ``±z`` (``--up-axis``, ``--forward-axis``), checked as the option is read so
    that a wrong one is refused naming the option, before any recording is read."""
    if not re.fullmatch(r"[+-]?[xyz]", text.strip().lower()):
        raise argparse.ArgumentTypeError(f"expected one of ±x, ±y, ±z, got {text[:40]!r}")
    return text


def number_below(lo: float, hi: float) -> Callable[[str], float]:
    """A finite number in ``[lo, hi)`` (NaN and infinities are refused)."""
    return _checked(float, lambda v: lo <= v < hi, f"a number in [{lo:g}, {hi:g})", trim=40)


#: ``--backend`` of the commands that predict with a MODEL.json
PREDICTION_BACKEND_HELP = (
    "DOC backend of the predictions (default: the fit's, MODEL.json's info.backend; casadi when it records none)"
)


def add_selection(p: argparse.ArgumentParser, what: str) -> None:
    """``--subject``, ``--posture`` and ``--side``: which trials of the trials file ``what`` (e.g. "fit")."""
    p.add_argument(
        "--subject",
        nargs="+",
        action="extend",
        metavar="ID",
        default=None,
        help=f"{what} only these subjects' trials (default: every subject)",
    )
    p.add_argument(
        "--posture",
        nargs="+",
        action="extend",
        metavar="NAME",
        default=None,
        help=f"{what} only the trials of these postures (default: every posture)",
    )
    p.add_argument(
        "--side", choices=("right", "left"), default=None, help=f"{what} only the trials of this arm (default: both)"
    )


def chosen_trials(args: argparse.Namespace, trials: list) -> tuple[list, dict | None]:
    """Those of ``trials`` (read from the file ``args.trials``, which an error names) that ``--subject/--posture
    /--side`` choose (:func:`reachirl.data.trial.select_trials`), and those choices as its keywords (``None``
    when none was given: every trial)."""
    from ..data.trial import select_trials

    def once(values):  # `--subject S01 S01` chooses S01, and is recorded so
        return None if values is None else list(dict.fromkeys(values))

    chosen = {"subjects": once(args.subject), "postures": once(args.posture), "sides": once(args.side and [args.side])}
    if all(v is None for v in chosen.values()):
        return trials, None
    return select_trials(trials, **chosen, path=args.trials), chosen


def _held(args: argparse.Namespace, selected: list, trials: list) -> str:
    """How many trials the selection holds, in words: of the whole file, or of what --subject/--posture/--side
    choose."""
    given = [
        f"--{name} {' '.join(v) if isinstance(v, list) else v}"
        for name in ("subject", "posture", "side")
        if (v := getattr(args, name, None)) is not None
    ]
    n = len(trials)
    if not given:
        return f"the file holds {n} trial{'s' if n != 1 else ''}"
    return f"the selection {' '.join(given)} holds {len(selected)} of the file's {n} trial{'s' if n != 1 else ''}"


def picked_trials(args: argparse.Namespace, trials: list, path) -> list:
    """Those of ``trials`` (read from the file ``path``, which an error names) that ``--subject/--posture/--side``
    select (:func:`chosen_trials`), then of these the ones ``--trial`` names, in the order
    given, each once (all of them without ``--trial``).

    A key is a selected trial's id or trial_id, else an integer: the index of a trial among the selected ones (the
    N-th selected, 0-based). An index out of range, a key naming only trials the selection leaves out, or one naming
    none raises :class:`InputError` saying how many trials the selection holds."""
    selected, _ = chosen_trials(argparse.Namespace(**{**vars(args), "trials": path}), trials)
    if not args.trial:
        return selected
    chosen = []
    for key in args.trial:
        hits = [t for t in selected if key in (t.id, t.trial_id)]
        if not hits and key.removeprefix("-").isdecimal():
            i = int(key)
            if not 0 <= i < len(selected):
                raise InputError(
                    f"--trial {key}: index out of range, expected 0 to {len(selected) - 1} "
                    f"({_held(args, selected, trials)})",
                    path,
                )
            hits = [selected[i]]
        if not hits:
            left_out = [t.id for t in trials if key in (t.id, t.trial_id)]
            what = (
                f"{left_out[0]} is not among the selected trials"
                if left_out
                else "no trial with that id, trial_id or index"
            )
            raise InputError(f"--trial {key}: {what} ({_held(args, selected, trials)})", path)
        chosen.extend(hits)
    # a trial named twice (by id and by index) is one trial: not played, drawn or counted in a summary twice
    return list({id(t): t for t in chosen}.values())


def same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` are one file: the same path (existing or not, through symlinked folders and ``..``
    as the file system resolves them), a symlink or a hard link."""

    def real(p) -> str:  # the folder resolved by the file system (symlinks, then ".."), the name kept
        p = Path(p)
        if p.name in ("", ".", ".."):
            return os.path.realpath(p)
        return os.path.join(os.path.realpath(p.parent), p.name)

    if real(a) == real(b):
        return True
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # either does not exist (yet), or cannot be examined
        return False


def refuse_overwrite(outputs: dict[str, object], inputs) -> None:
    """Before any work: no output path (``{option: path}``; ``None`` values skipped) resolves to one of
    ``inputs`` (paths; ``None`` skipped) — the same path, a symlink to it or a hard link (the same inode) — so
    that a command never replaces a file it reads. Raises :class:`~reachirl.errors.InputError` naming the file."""
    ins = [Path(p) for p in inputs if p is not None and str(p) != ""]
    for option, out in outputs.items():
        if out is None or str(out) == "":
            continue
        out = Path(out)
        for inp in ins:
            if same_file(out, inp):
                what = "folder" if inp.is_dir() else "file"
                raise InputError(
                    f"{option} is the input {what} {inp}; it would be overwritten (choose another output path)", out
                )


def output_folder_files(folder: object, names, inputs, option: str, outputs: dict[str, object] | None = None) -> None:
    """Before any work: none of the files ``names`` that a command will write into ``folder`` is one of
    ``inputs`` (as :func:`refuse_overwrite`) or one of the command's other ``outputs`` (``{option: path}``)."""
    if folder is None:
        return
    refuse_overwrite({f"{option} ({Path(folder) / n})": Path(folder) / n for n in names}, inputs)
    for other, path in (outputs or {}).items():
        hit = next((n for n in names if path is not None and same_file(Path(folder) / n, Path(path))), None)
        if hit is not None:
            raise InputError(
                f"{other} is {hit}, a file that {option} writes into {folder}; give each output its own path", path
            )


def refuse_foreign_figures(folder: object, names, option: str) -> None:
    """Before any figure is written: each of ``names`` that a command would replace or remove in ``folder`` is a
    figure reachirl wrote (its metadata carries reachirl's mark: :func:`reachirl.experiments.figures
    .is_marked_figure`), never a file of the user's own, which is refused (:class:`InputError` naming it). A figure
    of a reachirl from before the mark is refused as well: nothing tells it from the user's."""
    from ..experiments.figures import is_marked_figure

    if folder is None or not Path(folder).is_dir():
        return
    for n in names:
        p = Path(folder) / n
        if (p.exists() or p.is_symlink()) and not (p.is_file() and is_marked_figure(p)):
            raise InputError(
                f"{option}: exists and is not a figure written by reachirl (no reachirl mark in its metadata); it "
                "would be replaced (choose another folder, or remove it first)",
                p,
            )


def refuse_foreign_export_files(folder: object, names, option: str, inputs=()) -> None:
    """Before any work: an export into ``folder`` (writing ``names``, :func:`export_names`) replaces only an earlier
    export's files. An ``index.csv`` that is not an export's, or a file of ``names`` that the earlier export's index
    does not list, is the user's own: refused (:class:`InputError` naming it); so is one of ``inputs`` among the
    earlier export's files that this one does not write, which it would remove. Without an index (none yet, or an
    export interrupted after removing it) the files cannot be told apart and are replaced as before."""
    from ..data.exports import EARLIER_INDEX_COLUMNS, INDEX_COLUMNS, earlier_names, is_export, listed_names

    if folder is None or not Path(folder).is_dir():
        return
    folder = Path(folder)
    ins = [Path(p) for p in inputs if p is not None and str(p) != ""]
    for stem in sorted(earlier_names(folder) - {Path(n).stem for n in names}):  # what the export removes
        for gone in (folder / f"{stem}.csv", folder / f"{stem}.mot"):
            if any(same_file(gone, inp) for inp in ins):
                raise InputError(
                    f"{option}: is an input file, which an earlier export in {folder} listed and this one would "
                    "remove (choose another folder for the export)",
                    gone,
                )
    index = folder / "index.csv"
    if not index.exists():
        return
    if not is_export(folder):
        raise InputError(
            f"{option}: exists and is not the index of an earlier export (its header is neither "
            f"{','.join(INDEX_COLUMNS)} nor an earlier export's {','.join(EARLIER_INDEX_COLUMNS)}); it would be "
            "replaced (choose another folder, or remove it first)",
            index,
        )
    earlier = listed_names(folder)
    for n in names:
        if n != "index.csv" and (folder / n).exists() and Path(n).stem not in earlier:
            raise InputError(
                f"{option}: exists and is not a file of the earlier export in {folder} (its index.csv does not "
                "list it); it would be replaced (choose another folder, or remove it first)",
                folder / n,
            )


def export_names(ids) -> list[str]:
    """The files that :func:`reachirl.data.exports.export_trajectories` writes for trials ``ids``: ``<name>.csv``,
    ``<name>.mot`` per id (a repeated name gets ``-2``, ``-3`` …) and ``index.csv``."""
    from ..data.exports import safe_name

    used: set[str] = set()
    names = ["index.csv"]
    for i in ids:
        base = safe_name(i)
        name, k = base, 1
        while name in used:
            k += 1
            name = f"{base}-{k}"
        used.add(name)
        names += [f"{name}.csv", f"{name}.mot"]
    return names


def regular_input(path: object, option: str | None = None) -> Path:
    """Before reading: ``path`` is an existing regular file (a FIFO, a device or a socket would block or never
    end; a folder is not a file). Raises :class:`~reachirl.errors.InputError` naming it (and ``option``)."""
    from ..io import check_regular_file

    return check_regular_file(path, option)


def _keys(*names: str) -> Callable[[object], bool]:
    return lambda d: isinstance(d, dict) and set(names) <= d.keys()


def _model_json(d: object) -> bool:
    from ..irl.model import MODEL_FORMAT

    return isinstance(d, dict) and d.get("format") == MODEL_FORMAT


#: the JSON outputs a command may replace (its own earlier output): a name and how its content is recognised
#: (``bench`` recognises its own from its suites)
JSON_KINDS: dict[str, tuple[str, Callable[[object], bool]]] = {
    "fit": ("MODEL.json", _model_json),
    "evaluate": ("METRICS.json", _keys("model", "trials_file", "summary", "trials")),
    "simulate": ("SIM.json", _keys("backend", "mode", "substeps", "trials")),
}


def _gif(head: bytes) -> bool:
    return head[:6] in (b"GIF87a", b"GIF89a")


def _mp4(head: bytes) -> bool:
    return head[4:8] == b"ftyp"  # an ISO media file opens with its ftyp box


#: the animations ``simulate --render`` may replace, by suffix: a file that is what its name says (its magic bytes),
#: as simulate writes it; a file of another kind named .gif or .mp4 by mistake is refused
ANIMATION_KINDS: dict[str, tuple[str, Callable[[object], bool]]] = {
    ".gif": ("GIF animation", _gif),
    ".mp4": ("MP4 video", _mp4),
}


def _trials_header(d: object) -> bool:
    from ..data.trial import is_trials_header

    return is_trials_header(d)


#: the trials file ``preprocess`` may replace (its own earlier output, of this reachirl or an older one),
#: recognised by its ``meta.json`` header
TRIALS_KIND: tuple[str, Callable[[object], bool]] = ("reachirl trials file", _trials_header)


def refuse_out_in_run_folders(out: Path, run_dir: Path, folders: tuple[str, ...], what: str, example: str) -> None:
    """Before any work: ``out`` is none of the ``reproduce`` run ``run_dir``'s ``folders`` nor inside one (``what``,
    the command's outputs, would mix with the files a rerun of the run reads back, replaces or removes); an
    :class:`InputError` naming ``out`` and suggesting ``run_dir / example``."""
    o, run = out.resolve(), run_dir.resolve()
    for name in folders:
        own = run / name
        if o == own or own in o.parents:
            raise InputError(
                f"--out is inside the run's own {name}/ folder, which `reachirl reproduce` writes and reads back; "
                f"choose another --out for {what} (e.g. {run / example})",
                out,
            )
