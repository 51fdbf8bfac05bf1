"""Atomic file writes (temporary file in the same folder, then rename) and JSON helpers. No pickle anywhere."""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import tempfile
import zipfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import numpy as np

__all__ = [
    "MAX_FILE_BYTES",
    "MAX_JSON_DEPTH",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "cache_root",
    "check_regular_file",
    "csv_column",
    "hold_folder",
    "holding_folder",
    "json_depth",
    "npz_bytes",
    "read_json",
    "read_text",
    "reading_folder",
    "release_folder",
    "remove_temporaries",
    "sync_folder",
    "to_jsonable",
]

#: no input file of reachirl is anywhere near this size; a read stops here (a TRC from /dev/zero never ends)
MAX_FILE_BYTES = 512 * 1024**2
#: JSON nesting deeper than this is not a reachirl file
MAX_JSON_DEPTH = 64


def cache_root() -> Path:
    """reachirl's cache folder: ``$REACHIRL_CACHE``, else ``$XDG_CACHE_HOME/reachirl``, else
    ``~/.cache/reachirl``."""
    if os.environ.get("REACHIRL_CACHE"):
        return Path(os.environ["REACHIRL_CACHE"])
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "reachirl"
    return Path.home() / ".cache" / "reachirl"


#: the temporaries of this process's atomic writes in progress (:func:`atomic_path`)
_pending: set[Path] = set()


def remove_pending_temporaries() -> None:
    """Remove the temporaries of the atomic writes in progress: for a process about to be ended outright
    (``os._exit``: the command line's watchdog, after a signal that compiled code swallowed), which never reaches
    their own cleanup. Safe from another thread; what cannot be removed is left."""
    for tmp in list(_pending):
        with contextlib.suppress(OSError):
            tmp.unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None, *, durable: bool = True) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path``, on error it is removed.

    ``durable``: the temporary's content is synced to the disk (``fsync``) before the rename and the folder after
    it, so that a power loss or a crash of the system leaves the earlier file or the new one whole, never an empty
    or partly written file under the name (a folder whose file system refuses to sync it is not). ``False`` for
    the many small files of a bulk export (a sync each costs about a millisecond, more on a slow disk): they are
    renamed into place atomically, their content reaches the disk when the system writes it back (a crash of the
    system soon after may leave one short) and their renames with the next durable write into the folder
    (:func:`reachirl.data.exports.export_trajectories` writes its index last, durably).

    Nothing is replaced once the command has been interrupted (:func:`reachirl.errors.raise_if_signalled`): work
    finished after a Ctrl-C or SIGTERM that compiled code swallowed never becomes an output or a checkpoint."""
    from .errors import raise_if_signalled

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or ".tmp", dir=path.parent)
    except OSError as e:  # named as the file to be written, not as the temporary's random name
        raise OSError(e.errno, e.strerror or str(e), str(path)) from e
    os.close(fd)
    tmp = Path(tmp)
    _pending.add(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; a result file gets the usual permissions
    try:
        yield tmp
        raise_if_signalled()
        if durable:
            _fsync(tmp)  # the content on disk before the name points at it: a crash leaves the old file or the new
        os.replace(tmp, path)
        if durable:
            sync_folder(path.parent)  # and the rename itself (with every earlier one in the folder)
    except OSError as e:
        if e.filename is not None and e.filename not in (str(tmp), tmp):
            raise
        # a write that failed (a full disk, a folder made read-only meanwhile) names the file being written, not
        # nothing ("a file: No space left on device") nor its hidden temporary
        raise OSError(e.errno, e.strerror or str(e), str(path)) from e
    finally:
        tmp.unlink(missing_ok=True)
        _pending.discard(tmp)


def _fsync(path: Path) -> None:
    """Flush ``path``'s content to the disk (what its writer wrote and closed may sit in the page cache)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def sync_folder(folder: Path) -> None:
    """Flush ``folder``'s entries (the renames into it) to the disk; nothing where the file system or platform
    does not sync folders (it refuses with an error: some network and FUSE file systems, Windows)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


#: the name of a temporary that :func:`atomic_path` made and a killed process left: ``.<name>.<random>.<suffix>``
_TEMPORARY = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.(tmp|png|json|npz|csv|md|gif|mp4)$")


def remove_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Remove the temporaries of :func:`atomic_path` that a killed process left in ``folder`` (not below it);
    returns what was removed."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    removed = [f for f in folder.iterdir() if f.is_file() and _TEMPORARY.match(f.name)]
    for f in removed:
        f.unlink(missing_ok=True)
    return removed


#: the folders this process holds (:func:`hold_folder`, :func:`reading_folder`): their real path, the open
#: descriptor that holds the lock, and whether it is shared (read only) rather than exclusive (written)
_HELD: dict[str, tuple[int, bool]] = {}


def _in_use(folder: str | os.PathLike, fd: int, option: str | None):
    """The :class:`~reachirl.errors.InputError` of ``folder``, locked by another process (``fd``: open on it, and
    refused the lock asked for): whether that process is writing into it or reading it (a shared lock is still
    granted: no writer), whichever reachirl command it is. ``option``: the option that named the folder, if any."""
    import fcntl

    from .errors import InputError

    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        fcntl.flock(fd, fcntl.LOCK_UN)
        doing = "reading this folder"
    except OSError:
        doing = "writing into this folder"
    then = f", or choose another {option}" if option else ""
    return InputError(f"another reachirl command is {doing} now; wait for it to end{then}", folder, option)


def _lock(folder: str | os.PathLike, shared: bool, option: str | None) -> None:
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        return
    key = os.path.realpath(folder)
    if key in _HELD:
        if not shared and _HELD[key][1]:  # read, now written into: no other command may read it meanwhile
            _write_too(folder, key, option)
        return
    try:
        fd = os.open(key, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return  # not a folder (yet): the command's own checks say so
    try:
        fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
    except BlockingIOError:
        try:
            raise _in_use(folder, fd, option) from None
        finally:
            os.close(fd)
    except OSError:  # no locks here (some network file systems)
        os.close(fd)
        return
    _HELD[key] = (fd, shared)


def _write_too(folder: str | os.PathLike, key: str, option: str | None) -> None:
    """Turn this process's shared lock on ``folder`` (real path ``key``) into an exclusive one; refused, the
    :class:`~reachirl.errors.InputError` of :func:`_in_use`, while another process reads it too, the shared lock
    kept (the system drops it when it refuses the exchange: taken again)."""
    import fcntl

    fd = _HELD[key][0]
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        other = os.open(key, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))  # asks as another process would
        try:
            error = _in_use(folder, other, option)
        finally:
            os.close(other)
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        raise error from None
    except OSError:  # no locks here
        return
    _HELD[key] = (fd, False)


def hold_folder(folder: str | os.PathLike, option: str = "--out") -> None:
    """Hold an exclusive lock on the existing folder ``folder`` (on the folder itself: no file is made) until
    :func:`release_folder` or the end of the process; the system drops it with a killed process, so none is left
    stale. A second process writing into the same folder at once, or reading it (:func:`reading_folder`), is
    refused, an :class:`~reachirl.errors.InputError` naming the folder and ``option`` (the option that named
    it), whichever reachirl command holds it: it would remove the first one's temporaries and earlier outputs,
    and mix its checkpoints and ``run.toml`` with the first one's results. Held once per process (a second call
    is a no-op); a folder this process reads (:func:`reading_folder`) is held exclusively from then on, until it
    is released, or refused while another process reads it too. On a file system without locks, nothing is held."""
    _lock(folder, False, option)


@contextlib.contextmanager
def holding_folder(folder: str | os.PathLike, option: str = "--out") -> Iterator[Callable[[], Path]]:
    """:func:`hold_folder` on ``folder`` for the block, from its start when the folder exists (a second command
    is refused before any work), else from the call of the function it yields, which makes the folder and holds
    it (call it before the first write into the folder). Released at the block's end, unless it was held
    before."""
    folder = Path(folder)
    held_before = os.path.realpath(folder) in _HELD

    def make() -> Path:
        folder.mkdir(parents=True, exist_ok=True)
        hold_folder(folder, option)
        return folder

    hold_folder(folder, option)
    try:
        yield make
    finally:
        if not held_before:
            release_folder(folder)


@contextlib.contextmanager
def reading_folder(folder: str | os.PathLike, option: str | None = None) -> Iterator[None]:
    """A shared lock on the existing folder ``folder`` for the block, while a command reads it (``plot`` a run's
    folder): refused, an :class:`~reachirl.errors.InputError`, while another process writes into it
    (:func:`hold_folder`: a ``reproduce`` running into it), and a writer is refused meanwhile; readers do not
    refuse each other. Nothing when this process holds it already, or on a file system without locks."""
    held_before = os.path.realpath(folder) in _HELD
    _lock(folder, True, option)
    try:
        yield
    finally:
        if not held_before:
            release_folder(folder)


def release_folder(folder: str | os.PathLike) -> None:
    """Release the lock :func:`hold_folder` (or :func:`reading_folder`) took on ``folder`` (nothing when none is
    held)."""
    held = _HELD.pop(os.path.realpath(folder), None)
    if held is not None:
        os.close(held[0])


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, durable: bool = True) -> None:
    """Write ``data`` to ``path`` with :func:`atomic_path` (``durable``: synced to the disk)."""
    with atomic_path(path, durable=durable) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | os.PathLike, text: str, *, durable: bool = True) -> None:
    """Write ``text`` (UTF-8) to ``path`` with :func:`atomic_path` (``durable``: synced to the disk)."""
    atomic_write_bytes(path, text.encode("utf-8"), durable=durable)


def to_jsonable(obj):
    """Numpy arrays and scalars to plain lists and numbers, mappings (e.g. ``MappingProxyType``) to dicts;
    non-finite floats to None."""
    t = type(obj)
    if t is float:  # the leaves first: a model or a run holds hundreds of thousands of them
        return obj if math.isfinite(obj) else None
    if t is int or t is str or t is bool or obj is None:
        return obj
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def atomic_write_json(path: str | os.PathLike, obj, indent: int | None = 2) -> None:
    atomic_write_text(path, json.dumps(to_jsonable(obj), indent=indent, sort_keys=False) + "\n")


def check_regular_file(path: str | os.PathLike, option: str | None = None) -> Path:
    """``path`` as a :class:`Path` if it is an existing regular file (symlinks followed); else
    :class:`~reachirl.errors.InputError` naming it (and ``option``): missing, a folder, or a FIFO, device or
    socket, which reachirl never reads (a FIFO blocks until a writer comes, a device never ends)."""
    import stat

    from .errors import InputError

    p = Path(path)
    pre = f"{option}: " if option else ""
    try:
        st = p.stat()
    except FileNotFoundError:
        raise InputError(f"{pre}file not found", p) from None
    except OSError as e:
        raise InputError(f"{pre}cannot read ({e.strerror or e})", p) from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{pre}is a directory, expected a file", p)
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{pre}is not a regular file (a FIFO, device or socket); reachirl reads regular files only", p)
    try:  # readable by this user (a file of mode 000 was reported as "not a trials file")
        with open(p, "rb"):
            pass
    except OSError as e:
        raise InputError(f"{pre}cannot read ({e.strerror or e})", p) from None
    return p


def read_text(path: str | os.PathLike) -> str:
    """A text file's content (UTF-8, a byte-order mark dropped; UTF-16 with its byte-order mark, as some Windows
    exports write it; Latin-1 as the fallback), raising :class:`~reachirl.errors.InputError` naming the file when it
    is missing, unreadable or empty."""
    from .errors import InputError

    p = Path(path)
    check_regular_file(p)  # a FIFO would block the open() until a writer comes, a device never end
    try:
        with open(p, "rb") as fh:  # bounded
            raw = fh.read(65536)
            utf16 = raw[:2] in (b"\xff\xfe", b"\xfe\xff")  # its NUL bytes are text's
            if b"\0" not in raw or utf16:
                raw += fh.read(MAX_FILE_BYTES + 1 - len(raw))
    except FileNotFoundError:
        raise InputError("file not found", p) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a file", p) from None
    except OSError as e:
        raise InputError(f"cannot read ({e.strerror})", p) from None
    if len(raw) > MAX_FILE_BYTES:
        raise InputError(f"file is larger than {MAX_FILE_BYTES // 1024**2} MB, more than any input of reachirl", p)
    if raw.startswith(b"PK\x03\x04"):  # a ZIP archive: NumPy's .npz, a trials file given for a text file
        raise InputError("is a ZIP or NPZ archive (a trials file is one), expected text", p)
    if utf16:
        try:
            raw = raw.decode("utf-16").encode("utf-8")
        except UnicodeDecodeError:
            raise InputError("begins as UTF-16 text (its byte-order mark) but does not decode as it", p) from None
    if b"\0" in raw[:65536]:
        raise InputError("is a binary file (it holds NUL bytes), expected text", p)
    if not raw.strip():
        raise InputError("file is empty", p)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")  # decodes any bytes


def csv_column(path: str | os.PathLike, column: str) -> set[str]:
    """The non-empty values of ``column`` in the CSV at ``path`` (an earlier run's listing of what it wrote);
    none when the file is absent or unreadable."""
    import csv

    try:
        rows = list(csv.DictReader(io.StringIO(Path(path).read_text(encoding="utf-8"))))
    except (OSError, UnicodeDecodeError, csv.Error):
        return set()
    return {r.get(column) or "" for r in rows} - {""}


def read_json(path: str | os.PathLike):
    """Read JSON, raising :class:`~reachirl.errors.InputError` naming the file on any problem."""
    from .errors import InputError

    p = Path(path)
    text = read_text(p)
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"invalid JSON ({e.msg})", p, f"line {e.lineno}") from None
    except RecursionError:
        raise InputError("JSON nested too deeply", p) from None
    except ValueError as e:  # e.g. an integer of more than 4300 digits
        raise InputError(f"invalid JSON ({str(e).splitlines()[0][:100]})", p) from None
    if json_depth(obj) > MAX_JSON_DEPTH:
        raise InputError(f"JSON nested more than {MAX_JSON_DEPTH} levels deep", p)
    return obj


def json_depth(obj, limit: int = MAX_JSON_DEPTH) -> int:
    """Nesting depth of a parsed JSON value (stops counting past ``limit``)."""
    depth, level = 0, [obj]
    while level and depth <= limit:
        depth += 1
        nxt = []
        for v in level:
            if isinstance(v, dict):
                nxt.extend(v.values())
            elif isinstance(v, list):
                nxt.extend(v)
        level = nxt
    return depth


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """A compressed NPZ in memory, byte-identical for identical arrays (fixed zip timestamps, no pickle).

    ``numpy.load(..., allow_pickle=False)`` reads it.
    """
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, arr in arrays.items():
            arr = np.asarray(arr)
            if arr.dtype == object:
                raise TypeError(f"array {name!r} has dtype object; NPZ files here never hold pickles")
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            with zf.open(info, "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, arr, allow_pickle=False)
    return buf.getvalue()
