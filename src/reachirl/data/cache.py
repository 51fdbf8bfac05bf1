"""Preprocessed trials kept on disk: a folder of recordings is preprocessed once, and later loads read the
trials back from a trials file (:func:`reachirl.data.trial.save_trials`' packed NPZ, no pickle) instead.

The key is a SHA-256 of the content of every file the preprocessing reads, the options it was given, and the
code that preprocesses (the source of ``reachirl.data``, the arm and the features, any further sources the caller
names, and the numpy and scipy versions): editing a recording, the manifest, an option or the code gives a new
key, and the trials are preprocessed again. The files live under ``cache_root()/trials/``, one per data set
name (the newest key; older ones are removed when a new one is written), each written atomically. A cache file
that cannot be read, or does not hold valid trials, is ignored and written anew; a cache folder that cannot be
written only costs the speed.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

from ..errors import InputError
from ..io import cache_root
from .trial import TRIALS_FORMAT, Trial, load_trials, save_trials

__all__ = ["CACHE_FORMAT", "cache_dir", "cache_path", "cached_trials", "code_version", "content_key"]

log = logging.getLogger(__name__)

CACHE_FORMAT = "reachirl-trials-cache/2"
"""Bump when what a cached file holds changes for the same key."""

_PACKAGE = Path(__file__).resolve().parent.parent  # src/reachirl
#: the sources every preprocessed trial depends on, besides the whole of ``reachirl/data``
_SOURCES = ("arm.py", "features.py", "io.py", "errors.py", "validation.py")


def cache_dir() -> Path:
    """Where preprocessed trials are kept: ``cache_root()/trials``."""
    return cache_root() / "trials"


@functools.lru_cache(maxsize=8)
def code_version(extra_sources: tuple[str, ...] = ()) -> str:
    """A hash of the preprocessing code: every module under ``reachirl/data`` and its marker sets, the modules in
    ``_SOURCES``, ``extra_sources`` (paths), and the numpy and scipy versions."""
    import numpy
    import scipy

    h = hashlib.sha256()
    h.update(f"{CACHE_FORMAT}\0{TRIALS_FORMAT}\0numpy {numpy.__version__}\0scipy {scipy.__version__}\0".encode())
    data = sorted([*(_PACKAGE / "data").rglob("*.py"), *(_PACKAGE / "data" / "markersets").glob("*.json")])
    files = [*data, *(_PACKAGE / s for s in _SOURCES), *(Path(s) for s in extra_sources)]
    for f in files:
        h.update(str(f.relative_to(_PACKAGE) if f.is_relative_to(_PACKAGE) else f.name).encode() + b"\0")
        h.update(f.read_bytes() if f.is_file() else b"<missing>")
        h.update(b"\0")
    return h.hexdigest()


def content_key(files: Iterable[str | Path], options: Mapping[str, object], sources: Sequence[str | Path] = ()) -> str:
    """The cache key of trials preprocessed from ``files`` (read in full; their order does not matter) with
    ``options`` (JSON-able) by the current code (:func:`code_version` with ``sources``). Raises ``OSError`` when a
    file cannot be read."""
    h = hashlib.sha256()
    h.update(code_version(tuple(str(Path(s).resolve()) for s in sources)).encode())
    h.update(json.dumps(dict(options), sort_keys=True, default=str).encode())
    for f in sorted({Path(f).resolve() for f in files}):
        h.update(b"\0" + str(f).encode() + b"\0")
        h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


def cache_path(name: str, key: str) -> Path:
    """The cache file of data set ``name`` under ``key``."""
    return cache_dir() / f"{_safe(name)}-{key[:32]}.npz"


def cached_trials(
    name: str,
    files: Iterable[str | Path],
    options: Mapping[str, object],
    compute: Callable[[], list[Trial]],
    sources: Sequence[str | Path] = (),
) -> list[Trial]:
    """The trials ``compute()`` returns for data set ``name``, read from the cache when it holds them for the same
    ``files`` (content), ``options`` and code (:func:`content_key`), else computed and stored there."""
    try:
        key = content_key(files, options, sources)
    except OSError as e:  # a file that cannot be read: the preprocessing says what is wrong with it
        log.debug("trials cache: not used for %s (%s)", name, e)
        return compute()
    path = cache_path(name, key)
    if path.is_file():
        try:
            return load_trials(path)
        except InputError as e:  # damaged, truncated, or removed meanwhile: compute it again
            log.debug("trials cache: %s unusable (%s); preprocessing again", path, e.reason)
    trials = compute()
    if trials:
        _store(path, name, trials)
    return trials


def _store(path: Path, name: str, trials: Sequence[Trial]) -> None:
    try:
        save_trials(path, trials, packed=True)  # a few entries: read ten times faster than one per array
    except OSError as e:  # a read-only or full cache folder: the trials are still returned
        log.debug("trials cache: cannot write %s (%s)", path, e)
        return
    stale = re.compile(rf"^{re.escape(_safe(name))}-[0-9a-f]{{32}}\.npz$")
    for other in path.parent.iterdir():
        if other != path and stale.match(other.name):
            other.unlink(missing_ok=True)


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]", "-", str(name)) or "trials"
