"""Atomic writes: the file appears whole or not at all, with the usual permissions, and no pickle."""

import io
import os
import stat
import zipfile

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
