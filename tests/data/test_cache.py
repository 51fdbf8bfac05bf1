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


def _header(path) -> dict:
    import json

    with np.load(path, allow_pickle=False) as z:
        return json.loads(bytes(z["meta.json"]).decode())


def test_the_cache_keeps_its_trials_packed_and_reads_them_back_bit_for_bit(counted, tmp_path):
    """The cache's file holds each field's arrays end to end (a handful of entries, however many trials), and
    loading it gives the preprocessed trials to the last bit, as the per-trial layout of `preprocess --out` does."""
    import zipfile

    from reachirl.data.trial import load_trials, save_trials

    load, _ = counted
    first = load()
    (path,) = cached_files(tmp_path)
    assert _header(path)["layout"] == "packed"
    with zipfile.ZipFile(path) as zf:
        assert sorted(zf.namelist()) == sorted(
            f"{n}.npy" for n in ("meta.json", "t", "q", "qd", "qdd", "tau", "x0", "n_samples")
        )
    per_trial = save_trials(tmp_path / "per_trial.npz", first)
    assert "layout" not in _header(per_trial)
    assert same(load_trials(path), first) and same(load_trials(per_trial), first)
    for a, b in zip(load_trials(path), first, strict=True):
        assert all(getattr(a, f).tobytes() == getattr(b, f).tobytes() for f in ("t", "q", "qd", "qdd", "tau", "x0"))


def _rewritten(src, dst, change):
    """``src`` (a packed trials file) written again to ``dst`` with ``change(arrays, header)`` applied."""
    import json

    from reachirl.io import npz_bytes

    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(bytes(arrays.pop("meta.json")).decode())
    change(arrays, header)
    arrays["meta.json"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    dst.write_bytes(npz_bytes(arrays))
    return dst


@pytest.mark.parametrize(
    ("change", "said"),
    [
        (lambda a, h: a.pop("qd"), r"packed trials file lacks arrays \['qd'\]"),
        (lambda a, h: a.update(n_samples=a["n_samples"][:-1]), r"n_samples must be 2 counts \(one per trial\)"),
        (lambda a, h: a.update(n_samples=a["n_samples"] + 1), r"array t has shape \(\d+,\), expected \(\d+,\)"),
        (lambda a, h: a.update(q=a["q"][:, :1]), r"array q has shape \(\d+, 1\), expected \(\d+, 2\)"),
        (
            lambda a, h: a.update(x0=a["x0"][:1]),
            r"array x0 has shape \(1, 4\), expected \(2, 4\) \(one row per trial\)",
        ),
        (lambda a, h: a.update(n_samples=a["n_samples"].astype(float)), r"n_samples must be 2 counts"),
        (lambda a, h: h.update(layout="columns"), r"meta.json: unknown layout 'columns'"),
    ],
)
def test_a_damaged_packed_trials_file_is_refused_naming_what_is_wrong(counted, tmp_path, change, said):
    from reachirl.data.trial import load_trials
    from reachirl.errors import InputError

    load, _ = counted
    load()
    (path,) = cached_files(tmp_path)
    bad = _rewritten(path, tmp_path / "bad.npz", change)
    with pytest.raises(InputError, match=said) as e:
        load_trials(bad)
    assert e.value.path == bad
