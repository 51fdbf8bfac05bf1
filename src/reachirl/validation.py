"""Validation at the doors: the physical ranges of a reach, the limits of every number a user can type, output
paths, and the checks of a trials file before anything uses it. (A model file is checked by its loader,
:func:`reachirl.irl.model.load_model`; the limits of every file read, by :mod:`reachirl.io`.)

Every check raises :class:`~reachirl.errors.InputError` with one line that names the file (and field) and says
what was expected and what was found, which the command line turns into exit code 2.

The ranges are wide enough for any human reach and any sensible run, and narrow enough that no value inside them
can make a solver hang, a buffer exhaust the memory or an arithmetic overflow produce NaN.
"""

from __future__ import annotations

import errno
import json
import math
import os
import tempfile
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .errors import InputError
from .io import MAX_FILE_BYTES

__all__ = [
    "ARM_RANGES",
    "DURATION_RANGE",
    "MAX_FILE_BYTES",
    "MAX_NPZ_ENTRY_BYTES",
    "NODES_RANGE",
    "brief",
    "check_arm",
    "check_duration",
    "check_file_size",
    "check_n_nodes",
    "check_npz_file",
    "check_output_dir",
    "check_output_file",
    "not_real",
    "number",
    "require",
]

# ---------------------------------------------------------------------- physical and numerical ranges
#: DOC intervals N: 4 (the least the problem needs) to 1000 (10x the paper's 100; building and solving a DOC
#: of N = 1000 takes seconds, N = 10⁶ would take hours and gigabytes).
NODES_RANGE = (4, 1000)
#: reach duration, s: a human reach lasts 0.2-3 s; below 10 ms or above 60 s it is not a reach (and a duration
#: of 1 µs made the solver spin for minutes).
DURATION_RANGE = (0.01, 60.0)
#: ArmModel fields: lengths and CoM distances (m), masses (kg), inertias (kg·m²), gravity (m/s²).
ARM_RANGES = {
    "l1": (0.02, 2.0),
    "l2": (0.02, 2.0),
    "m1": (0.01, 100.0),
    "m2": (0.01, 100.0),
    "i1": (1e-8, 10.0),
    "i2": (1e-8, 10.0),
    "gravity": (0.0, 100.0),
}
#: one array of a trials or unit NPZ (a trial of 10⁶ samples is 16 MB per array)
MAX_NPZ_ENTRY_BYTES = 256 * 1024**2
#: iterations of an iterative learner (MO-IRL, MaxEnt)
MAX_ITER = 10000


def brief(v) -> str:
    """A number for a message: short, never 80 digits."""
    if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
        s = repr(v)
        return s if len(s) <= 40 else s[:37] + "..."
    if isinstance(v, int | np.integer) and abs(int(v)) < 10**12:
        return str(int(v))
    return f"{float(v):.6g}"


def number(v) -> float:
    """``float(v)``, but a boolean (``true`` of a JSON or TOML file) is a ``TypeError``, not 1.0."""
    if isinstance(v, bool | np.bool_):
        raise TypeError(f"expected a number, got a boolean ({v!r})")
    return float(v)


def not_real(v) -> str | None:
    """What makes ``v`` no array of real numbers although a cast to float would take it: complex numbers (the cast
    drops their imaginary part, numpy only warns) or booleans (read as 0 and 1), an array of them or one among
    the numbers of a list (``[[true, 0.1]]`` of a JSON or TOML file casts to ``[[1.0, 0.1]]``); ``None`` otherwise
    (text and ragged rows are the cast's own to refuse). The check of every numeric list read from a file or
    given to an API."""
    try:
        kind = np.asarray(v).dtype
    except (TypeError, ValueError):
        return None
    if kind.kind == "c":
        return f"complex numbers (dtype {kind})"
    if kind.kind == "b":
        return f"booleans (dtype {kind})"
    hit = _boolean_item(v)
    if hit is not None:
        value, index = hit
        return f"a boolean ({str(value).lower()}) among the numbers, at {''.join(f'[{i}]' for i in index)}"
    return None


def _boolean_item(v) -> tuple[bool, tuple[int, ...]] | None:
    """The first boolean among the items of ``v``, nested lists and tuples (or an object array) that cast to an
    array, with its index; ``None`` when there is none. An array of numbers holds none (its dtype says so)."""
    if not (isinstance(v, list | tuple) or (isinstance(v, np.ndarray) and v.dtype == object)):
        return None
    items = np.asarray(v, dtype=object)
    if not {bool, np.bool_} & set(map(type, items.flat)):  # a million numbers in 50 ms
        return None
    k = next(k for k, x in enumerate(items.flat) if isinstance(x, bool | np.bool_))
    return bool(items.flat[k]), tuple(int(i) for i in np.unravel_index(k, items.shape))


def check_n_nodes(n, where: object | None = None, name: str = "n_nodes") -> int:
    """``n`` as an int in :data:`NODES_RANGE`."""
    lo, hi = NODES_RANGE
    if isinstance(n, bool) or not isinstance(n, int | float | np.integer | np.floating):
        raise InputError(f"{name} must be an integer in [{lo}, {hi}], got {brief(n)}", where)
    if not math.isfinite(float(n)) or float(n) != int(n) or not lo <= int(n) <= hi:
        raise InputError(f"{name} must be an integer in [{lo}, {hi}], got {brief(n)}", where)
    return int(n)


def check_duration(duration, where: object | None = None) -> float:
    lo, hi = DURATION_RANGE
    try:
        d = number(duration)
    except (TypeError, ValueError):
        raise InputError(
            f"duration must be a number of seconds in [{lo}, {hi}], got {brief(duration)}", where
        ) from None
    if not (math.isfinite(d) and lo <= d <= hi):
        raise InputError(f"duration {brief(d)} s is outside the range of a reach, [{lo}, {hi}] s", where)
    return d


def check_arm(arm, where: object | None = None) -> None:
    """The arm's segments, masses, inertias and gravity are in :data:`ARM_RANGES` (a human arm, loosely)."""
    for name, (lo, hi) in ARM_RANGES.items():
        v = getattr(arm, name)
        if not lo <= v <= hi:
            raise InputError(f"arm {name} = {brief(v)} is outside the physical range [{lo:g}, {hi:g}]", where)


# ---------------------------------------------------------------------- output paths
def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


def _exists(p: Path) -> bool:
    try:
        return p.exists()
    except OSError:  # e.g. a name too long to stat
        return False


def _existing_ancestor(path: Path) -> Path:
    p = path
    while not _exists(p) and p != p.parent:
        p = p.parent
    return p


def _check_writable_folder(path: Path, option: str) -> None:
    """``path``'s nearest existing ancestor is a folder in which a file can be created; every missing
    component has a legal name length (with room for the atomic writes' temporary names)."""
    anc = _existing_ancestor(path)
    if not anc.is_dir():
        raise InputError(f"{option}: {anc} is a file, not a folder", path)
    limit = _name_max(anc)
    for part in path.relative_to(anc).parts if path != anc else ():
        if len(os.fsencode(part)) + 16 > limit:
            raise InputError(
                f"{option}: the name {part[:20]}... is {len(os.fsencode(part))} bytes long; the limit here is "
                f"{limit - 16} bytes",
                path,
            )
    try:
        with tempfile.TemporaryFile(dir=anc, prefix=".reachirl-write-test-"):
            pass
    except OSError as e:
        raise InputError(f"{option}: cannot write in {anc} ({e.strerror or e})", path) from None


def check_output_file(path: str | os.PathLike, option: str = "--out") -> Path:
    """Before any work: ``path`` can be written atomically (it is not a folder, its folder exists or can be
    made, is writable, and its name is not too long). Returns it as a :class:`Path`."""
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise InputError(f"{option}: expected a file path, got {str(path)!r}")
    if os.fspath(path).endswith(("/", os.sep)):  # Path drops the slash: `--out newm/` wrote a file named newm
        raise InputError(f"{option}: ends with '/', a folder; expected a file path (e.g. {p / 'out.json'})", path)
    parent = p.absolute().parent
    _check_writable_folder(parent, option)
    if len(os.fsencode(p.name)) + 16 > _name_max(_existing_ancestor(parent)):
        raise InputError(f"{option}: the file name is {len(os.fsencode(p.name))} bytes long, too long here", p)
    if p.is_dir():
        raise InputError(f"{option}: is a folder, expected a file path", p)
    if p.exists() and not p.is_file():
        raise InputError(f"{option}: is not a regular file", p)
    return p


def check_output_kind(
    path: str | os.PathLike | None,
    suffix: str,
    option: str = "--out",
    kind: tuple[str, Callable[[object], bool]] | None = None,
) -> None:
    """Before any work (once the inputs are known not to be ``path``): a file already at ``path`` is of the kind
    the command writes (``suffix``, e.g. ``".json"``; with ``kind = (name, recognises)``, a JSON file whose content
    ``recognises`` accepts, for ``".npz"`` an NPZ whose ``meta.json`` entry it accepts, for any other suffix a
    file whose first :data:`HEAD_BYTES` bytes it accepts, e.g. a GIF's magic): a command replaces its own earlier
    output, never a file of another kind given by mistake (a trials file, a model, another command's JSON, another
    program's NPZ, a file of the user's own)."""
    if path is None:
        return
    p = Path(path)
    if not p.is_file():
        return
    if p.suffix.lower() != suffix:
        raise InputError(f"{option}: exists and is not a {suffix} file; it would be replaced (choose another path)", p)
    if kind is not None:
        name, recognises = kind
        try:
            if suffix not in (".npz", ".json"):
                with open(p, "rb") as fh:
                    content = fh.read(HEAD_BYTES)
            elif p.stat().st_size > MAX_FILE_BYTES:
                raise ValueError
            else:
                content = _npz_meta(p) if suffix == ".npz" else json.loads(p.read_text(encoding="utf-8"))
            ok = recognises(content)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error):
            ok = False
        if not ok:
            raise InputError(
                f"{option}: exists and is not a {name} (an earlier output of this command); it would be replaced "
                "(choose another path, or remove it first)",
                p,
            )


#: how much of an existing output :func:`check_output_kind` reads to recognise a binary file by its magic bytes
HEAD_BYTES = 64


def _npz_meta(path: Path):
    """The parsed ``meta.json`` entry of the NPZ at ``path`` (a reachirl trials file's header); raises
    ``KeyError`` without one, and ``ValueError`` or a zip error when it cannot be read (no pickle)."""
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("meta.json.npy")
        if info.file_size > MAX_FILE_BYTES:
            raise ValueError("meta.json too large")
        with zf.open(info) as fh:
            arr = np.lib.format.read_array(fh, allow_pickle=False)
    return json.loads(bytes(arr).decode("utf-8"))


def check_output_dir(path: str | os.PathLike, option: str = "--out") -> Path:
    """Before any work: ``path`` is a folder (existing or to be made) in which files can be written."""
    p = Path(path)
    if str(path) == "":
        raise InputError(f"{option}: expected a folder path, got ''")
    if _exists(p) and not p.is_dir():
        raise InputError(f"{option}: exists and is not a folder", p)
    _check_writable_folder(p.absolute(), option)
    return p


def check_figure_file(path: str | os.PathLike, option: str = "--out") -> Path:
    """Before any work: ``path`` can be written atomically (:func:`check_output_file`) and names a format that
    matplotlib writes by its suffix (``.png``, ``.pdf``, ...). Returns it as a :class:`Path`."""
    from matplotlib.backend_bases import FigureCanvasBase

    p = check_output_file(path, option)
    kinds = FigureCanvasBase.get_supported_filetypes()
    if p.suffix.lower().lstrip(".") not in kinds:
        known = ", ".join(f".{k}" for k in sorted(kinds))
        raise InputError(f"{option}: expected a figure file name ending in one of {known}", p)
    return p


#: errno values of an OSError that concern a path the user gave (not a bug of reachirl)
PATH_ERRNOS = frozenset(
    getattr(errno, n)
    for n in (
        "EACCES",
        "EPERM",
        "EROFS",
        "ENOSPC",
        "EDQUOT",
        "ENAMETOOLONG",
        "ENOTDIR",
        "EISDIR",
        "EEXIST",
        "ENOENT",
        "ELOOP",
        "EFBIG",
        "EMFILE",
    )
    if hasattr(errno, n)
)


# ---------------------------------------------------------------------- files
def check_file_size(path: Path, limit: int = MAX_FILE_BYTES) -> None:
    """A regular file of at most ``limit`` bytes (devices and FIFOs have no size to trust)."""
    try:
        st = path.stat()
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except OSError as e:
        raise InputError(f"cannot read ({e.strerror or e})", path) from None
    import stat

    if stat.S_ISDIR(st.st_mode):
        raise InputError("is a directory, expected a file", path)
    if not stat.S_ISREG(st.st_mode):
        raise InputError("is not a regular file (a device, pipe or socket)", path)
    if st.st_size > limit:
        raise InputError(f"file is {st.st_size / 1024**2:.0f} MB, more than the {limit / 1024**2:.0f} MB limit", path)


def check_npz_file(path: Path, max_entry: int = MAX_NPZ_ENTRY_BYTES) -> None:
    """An NPZ that numpy can read without surprises: a regular file of sane size, a valid zip whose entries'
    CRCs match, every entry a ``.npy`` of a plain numeric or fixed-width text dtype (no object arrays) whose
    declared shape fits in ``max_entry`` bytes. Checked before any array is allocated (a declared shape of 2e11
    would exhaust the memory)."""
    check_file_size(path)
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            for info in infos:
                if info.file_size > max_entry:
                    raise InputError(
                        f"entry {info.filename} is {info.file_size / 1024**2:.0f} MB uncompressed, more than "
                        f"{max_entry / 1024**2:.0f} MB",
                        path,
                    )
            for info in infos:
                if not info.filename.endswith(".npy"):
                    raise InputError(f"entry {info.filename} is not a .npy array", path)
                with zf.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    if version == (1, 0):
                        shape, _fortran, dtype = np.lib.format.read_array_header_1_0(fh)
                    elif version == (2, 0):
                        shape, _fortran, dtype = np.lib.format.read_array_header_2_0(fh)
                    else:
                        raise InputError(f"entry {info.filename}: unsupported .npy version {version}", path)
                    if dtype.hasobject or dtype.kind not in "biufU":
                        raise InputError(f"entry {info.filename} has dtype {dtype}, expected numbers or text", path)
                    n_bytes = int(np.prod([int(s) for s in shape], dtype=object) or 0) * dtype.itemsize
                    if n_bytes > max_entry or n_bytes > info.file_size:
                        raise InputError(
                            f"entry {info.filename} declares shape {tuple(shape)} ({brief(n_bytes)} bytes) but holds "
                            f"{info.file_size} bytes",
                            path,
                        )
            bad = zf.testzip()  # decompresses every entry and checks its CRC
            if bad is not None:
                raise InputError(f"entry {bad} is damaged (CRC mismatch)", path)
    except InputError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, ValueError, OSError, NotImplementedError) as e:
        raise InputError(f"not a readable NPZ file ({_short(e)})", path) from None
    except Exception as e:  # zlib.error and friends from a damaged stream
        raise InputError(f"damaged NPZ file ({type(e).__name__}: {_short(e)})", path) from None


def _short(e: BaseException) -> str:
    s = str(e).replace("\n", " ")
    return s if len(s) <= 120 else s[:117] + "..."


# ---------------------------------------------------------------------- file content
def require(cond: bool, message: str, where) -> None:
    """Raise :class:`~reachirl.errors.InputError` (``message`` at ``where``) unless ``cond``."""
    if not cond:
        raise InputError(message, where)
