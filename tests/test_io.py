"""Atomic writes: the file appears whole or not at all, with the usual permissions, and no pickle."""

import io
import json
import os
import stat
import zipfile
from pathlib import Path

import numpy as np
import pytest

from reachirl.errors import InputError
from reachirl.io import atomic_path, atomic_write_json, npz_bytes, read_json


def test_atomic_write_leaves_nothing_on_error(tmp_path):
    target = tmp_path / "out.json"
    with pytest.raises(RuntimeError, match="boom"), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_atomic_write_has_umask_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_json(tmp_path / "r.json", {"a": np.float64(1.5), "b": np.arange(3), "c": float("nan")})
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "r.json").stat().st_mode) == 0o644
    assert read_json(tmp_path / "r.json") == {"a": 1.5, "b": [0, 1, 2], "c": None}


def test_npz_bytes_is_deterministic_and_pickle_free(tmp_path):
    arrays = {"x": np.arange(5.0), "meta": np.frombuffer(b"{}", dtype=np.uint8)}
    assert npz_bytes(arrays) == npz_bytes({k: v.copy() for k, v in arrays.items()})
    # two calls a moment apart match even with the clock in the zip headers: the timestamps must be fixed
    with zipfile.ZipFile(io.BytesIO(npz_bytes(arrays))) as z:
        assert [(i.filename, i.date_time) for i in z.infolist()] == [
            ("x.npy", (1980, 1, 1, 0, 0, 0)),
            ("meta.npy", (1980, 1, 1, 0, 0, 0)),
        ]
    (tmp_path / "a.npz").write_bytes(npz_bytes(arrays))
    with np.load(tmp_path / "a.npz", allow_pickle=False) as z:
        np.testing.assert_array_equal(z["x"], np.arange(5.0))
    with pytest.raises(TypeError, match="never hold pickles"):
        npz_bytes({"o": np.array([{}], dtype=object)})


@pytest.mark.parametrize(("text", "match"), [("", "file is empty"), ("{x", r"line 1: invalid JSON")])
def test_read_json_errors_name_the_file(tmp_path, text, match):
    p = tmp_path / "m.json"
    p.write_text(text)
    with pytest.raises(InputError, match=rf"m\.json: {match}"):
        read_json(p)
    with pytest.raises(InputError, match=r"nope\.json: file not found"):
        read_json(tmp_path / "nope.json")


def test_a_write_that_fails_names_the_file_being_written(tmp_path, monkeypatch):
    """A full disk (or a folder made read-only while a command runs) is said of the file being written: the
    write's own error names no file ("a file: No space left on device"), the temporary's is a random name."""
    import errno
    import re
    import tempfile

    from reachirl.io import atomic_write_bytes

    target = tmp_path / "table.csv"
    with pytest.raises(OSError, match=re.escape(f"No space left on device: '{target}'")) as e:
        with atomic_path(target):
            raise OSError(errno.ENOSPC, "No space left on device")
    assert e.value.errno == errno.ENOSPC and os.listdir(tmp_path) == []

    def read_only(*args, dir=None, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", os.path.join(dir, ".table.csv.x1y2z3w4.tmp"))

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(OSError, match=re.escape(f"Read-only file system: '{target}'")):
        atomic_write_bytes(target, b"x")


def _record_syncs(monkeypatch, fail_folders: bool = False, fail_files: bool = False) -> list:
    """Record, in order, each fsync (of a file: its inode; of a folder: 'folder', inode) and each rename; a folder's
    sync may be refused as some file systems refuse it (EINVAL), or a file's fail as a failing disk does (EIO)."""
    import errno

    events: list = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        st = os.fstat(fd)
        kind = "folder" if stat.S_ISDIR(st.st_mode) else "file"
        events.append((f"fsync {kind}", st.st_ino))
        if kind == "folder" and fail_folders:
            raise OSError(errno.EINVAL, "Invalid argument")
        if kind == "file" and fail_files:
            raise OSError(errno.EIO, "Input/output error")
        return real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", os.stat(src).st_ino))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    return events


def test_an_atomic_write_reaches_the_disk_before_and_after_its_rename(tmp_path, monkeypatch):
    """The new content is synced before the rename makes it the file, and the folder after (the rename itself): a
    crash of the system leaves the earlier file or the new one, never an empty one under the name."""
    path = tmp_path / "results.json"
    path.write_text("earlier")
    events = _record_syncs(monkeypatch)
    atomic_write_json(path, {"a": 1})
    ino, folder = path.stat().st_ino, tmp_path.stat().st_ino
    assert events == [("fsync file", ino), ("replace", ino), ("fsync folder", folder)]
    assert json.loads(path.read_text()) == {"a": 1}


def test_a_folder_that_cannot_be_synced_still_gets_its_file(tmp_path, monkeypatch):
    events = _record_syncs(monkeypatch, fail_folders=True)
    atomic_write_json(tmp_path / "table.json", [1, 2])
    assert [e[0] for e in events] == ["fsync file", "replace", "fsync folder"]
    assert json.loads((tmp_path / "table.json").read_text()) == [1, 2]


def test_a_sync_that_fails_names_the_file_and_keeps_the_earlier_one(tmp_path, monkeypatch):
    path = tmp_path / "table.csv"
    path.write_text("earlier")
    _record_syncs(monkeypatch, fail_files=True)
    with pytest.raises(OSError, match=r"Input/output error.*table\.csv"):
        atomic_write_json(path, [1])
    assert path.read_text() == "earlier" and sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


def test_a_bulk_exports_files_are_not_synced_one_by_one_but_its_index_and_folder_are(tmp_path, monkeypatch):
    """~1,200 prediction files a run: a sync each cost over a second; the index (written last) and the folder are
    synced once."""
    from reachirl.data.exports import TrajectoryExport, export_trajectories

    t = np.linspace(0.0, 1.0, 5)
    demo = {"q": np.zeros((5, 2)), "qd": np.zeros((5, 2)), "tau": np.zeros((4, 2))}
    events = _record_syncs(monkeypatch)
    export_trajectories(tmp_path, [TrajectoryExport(f"S1/T{i}", t, demo) for i in range(3)])
    index = (tmp_path / "index.csv").stat().st_ino
    syncs = [e for e in events if e[0] != "replace"]
    assert syncs == [("fsync file", index), ("fsync folder", tmp_path.stat().st_ino)]
    assert len(events) == 2 + 8  # the pending list, six trajectory files and the index renamed into place


def test_to_jsonable_gives_json_of_numpy_values_and_null_for_non_finite_numbers(tmp_path):
    from types import MappingProxyType

    from reachirl.io import to_jsonable

    class Ratio(float):  # a float subclass takes the general path, as numpy's float64 does
        pass

    value = MappingProxyType(
        {
            "a": np.array([[1.5, np.nan], [np.inf, -2.0]]),
            1: (np.float32(0.25), np.int64(3), np.bool_(True), True, None, "x", Path("/p/q"), Ratio(float("nan"))),
            "plain": [1.0, float("-inf"), 2, False],
        }
    )
    got = to_jsonable(value)
    assert got == {
        "a": [[1.5, None], [None, -2.0]],
        "1": [0.25, 3, True, True, None, "x", "/p/q", None],
        "plain": [1.0, None, 2, False],
    }
    assert [type(v) for v in got["1"][:4]] == [float, int, bool, bool]
    assert type(got["plain"][3]) is bool and type(got["plain"][2]) is int
    atomic_write_json(tmp_path / "v.json", value)
    assert json.loads((tmp_path / "v.json").read_text()) == got
