"""The preprocessed-trials cache: a hit gives the very trials preprocessing gives; any change of a file read, an
option or the code preprocesses again; a damaged or unwritable cache costs only the speed."""

import numpy as np
import pytest

from reachirl.data import cache
from reachirl.data.trial import Trial
from reachirl.irl.provenance import fingerprint


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Recorded virtual reaches (TRC, manifest, subject info, truth): 1 subject, posture P2, 2 reaches."""
    from recordings import synth

    return synth(tmp_path_factory.mktemp("rec") / "raw", ("P2",), subjects=1, trials=2, seed=1)


@pytest.fixture
def counted(folder, monkeypatch, tmp_path):
    """``(load, calls)``: the folder's trials through the cache (under tmp_path), and how often they were
    preprocessed."""
    from reachirl.experiments.datasets import preprocess_folder

    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path / "cache"))
    calls = []

    def compute():
        calls.append(1)
        return preprocess_folder(folder)

    def load(files=None, options=None, sources=()):
        files = sorted(folder.iterdir()) if files is None else files
        return cache.cached_trials("rec", files, options or {"marker_map": None}, compute, sources=sources)

    return load, calls


def same(a: list[Trial], b: list[Trial]) -> bool:
    fields = ("subject", "posture", "trial_id", "side", "source", "target_x", "onset_threshold", "arm")
    return (
        len(a) == len(b)
        and fingerprint(a) == fingerprint(b)
        and all(getattr(x, f) == getattr(y, f) for x, y in zip(a, b, strict=True) for f in fields)
        and all(
            np.array_equal(getattr(x, f), getattr(y, f))
            for x, y in zip(a, b, strict=True)
            for f in ("t", "q", "qd", "qdd", "tau", "x0")
        )
    )


def cached_files(tmp_path):
    return sorted((tmp_path / "cache" / "trials").glob("*.npz"))


def test_a_hit_gives_the_trials_preprocessing_gives(counted, tmp_path):
    load, calls = counted
    first = load()
    assert len(calls) == 1 and len(cached_files(tmp_path)) == 1
    again = load()
    assert len(calls) == 1 and same(first, again)
    assert not [p for p in (tmp_path / "cache" / "trials").iterdir() if p.name.startswith(".")]  # no temporary


def test_a_changed_recording_is_preprocessed_again(counted, folder, tmp_path):
    load, calls = counted
    first = load()
    trc = sorted(folder.glob("*.trc"))[0]
    text = trc.read_text()
    lines = text.splitlines(keepends=True)
    row = lines[-1].split("\t")
    row[2] = f"{float(row[2]) + 0.5:.3f}"  # half a millimetre on the last frame's first coordinate
    try:
        trc.write_text("".join([*lines[:-1], "\t".join(row)]))
        second = load()
        assert len(calls) == 2 and not same(first, second)
        assert len(cached_files(tmp_path)) == 1  # the stale version was removed
    finally:
        trc.write_text(text)
    assert same(load(), first) and len(calls) == 3


def test_options_and_code_are_part_of_the_key(counted, tmp_path):
    load, calls = counted
    load()
    load(options={"marker_map": "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"})
    assert len(calls) == 2
    src = tmp_path / "loader.py"
    src.write_text("# version 1\n")
    load(sources=(src,))
    assert len(calls) == 3
    load(sources=(src,))
    assert len(calls) == 3
    src.write_text("# version 2\n")
    cache.code_version.cache_clear()  # a process sees one version of its code; a new one is a new process
    load(sources=(src,))
    assert len(calls) == 4


def test_a_damaged_cache_file_is_preprocessed_again_and_replaced(counted, tmp_path):
    load, calls = counted
    first = load()
    (path,) = cached_files(tmp_path)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    assert same(load(), first) and len(calls) == 2
    assert same(load(), first) and len(calls) == 2  # rewritten whole


def test_an_unwritable_cache_only_costs_speed(counted, monkeypatch, tmp_path):
    load, calls = counted
    (tmp_path / "file").write_text("x")
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path / "file"))  # a file where the folder would go
    assert len(load()) == 2 and len(load()) == 2 and len(calls) == 2


def test_an_unreadable_file_leaves_the_error_to_preprocessing(counted, folder):
    load, calls = counted
    assert len(load(files=[*folder.iterdir(), folder / "missing.trc"])) == 2 and len(calls) == 1


def test_the_key_is_the_content_not_the_order(folder):
    files = sorted(folder.iterdir())
    assert cache.content_key(files, {"a": 1}) == cache.content_key(files[::-1], {"a": 1})
    assert cache.content_key(files, {"a": 1}) != cache.content_key(files, {"a": 2})
    assert cache.content_key(files, {}) != cache.content_key(files[1:], {})
