"""TRC, MOT and C3D writers: write, read back, values within the written precision; same input, same bytes."""

import ezc3d
import numpy as np
import pytest

from reachirl.data.writers import read_mot_simple, read_trc_simple, write_c3d, write_mot, write_trc


@pytest.fixture
def markers(rng):
    n = 57
    t = np.arange(n) / 100.0
    return t, {name: rng.normal(0, 500, size=(n, 3)) for name in ("SHO", "ELB", "WRI", "FTP")}


def test_trc_round_trip_and_header(tmp_path, markers):
    t, m = markers
    path = write_trc(tmp_path / "a.trc", t, m, units="mm", rate=100.0)
    lines = path.read_text().splitlines()
    assert lines[0] == "PathFileType\t4\t(X/Y/Z)\ta.trc"
    assert lines[1].split("\t") == [
        "DataRate",
        "CameraRate",
        "NumFrames",
        "NumMarkers",
        "Units",
        "OrigDataRate",
        "OrigDataStartFrame",
        "OrigNumFrames",
    ]
    assert lines[2].split("\t") == ["100.00", "100.00", "57", "4", "mm", "100.00", "1", "57"]
    assert lines[3].split("\t")[:3] == ["Frame#", "Time", "SHO"]
    assert lines[4].split("\t")[2:5] == ["X1", "Y1", "Z1"]
    assert lines[5] == "" and lines[6].startswith("1\t0.00000\t")
    t2, m2, hdr = read_trc_simple(path)
    assert hdr["Units"] == "mm" and float(hdr["DataRate"]) == 100.0
    np.testing.assert_allclose(t2, t, atol=5e-6)
    assert list(m2) == list(m)
    for k in m:
        np.testing.assert_allclose(m2[k], m[k], atol=5e-4)  # 3 decimals


def test_trc_gaps_are_empty_fields(tmp_path, markers):
    t, m = markers
    m["FTP"][3:6] = np.nan
    path = write_trc(tmp_path / "g.trc", t, m)
    rows = [line.split("\t") for line in path.read_text().splitlines()[6:]]
    assert [r[11:14] for r in rows[3:6]] == [["", "", ""]] * 3  # FTP, the 4th marker: frames 4-6 empty
    assert all(len(r) == 14 and "" not in r for i, r in enumerate(rows) if i not in (3, 4, 5))
    assert all("" not in r[:11] for r in rows[3:6])  # the other markers are there
    _, m2, _ = read_trc_simple(path)
    assert np.isnan(m2["FTP"][3:6]).all() and np.isfinite(m2["FTP"][6:]).all()


def test_trc_no_negative_zero(tmp_path):
    t = np.arange(3) / 100.0
    m = {"A": np.array([[-1e-9, 0.0, 1.0]] * 3)}
    assert "-0.000" not in write_trc(tmp_path / "z.trc", t, m).read_text()


def test_mot_round_trip(tmp_path, rng):
    t = np.arange(40) / 100.0
    q = rng.uniform(-150, 150, size=(40, 2))
    path = write_mot(tmp_path / "a.mot", t, q)
    lines = path.read_text().splitlines()
    assert lines[:6] == ["a.mot", "version=1", "nRows=40", "nColumns=3", "inDegrees=yes", "endheader"]
    assert lines[6].split("\t") == ["time", "q1", "q2"]
    t2, cols, hdr = read_mot_simple(path)
    assert hdr["inDegrees"] == "yes"
    np.testing.assert_allclose(t2, t, atol=1e-8)
    np.testing.assert_allclose(np.column_stack([cols["q1"], cols["q2"]]), q, atol=5e-7)


def test_c3d_round_trip_with_ezc3d(tmp_path, markers):
    t, m = markers
    path = write_c3d(tmp_path / "a.c3d", t, m, units="mm", rate=100.0)
    c = ezc3d.c3d(str(path))
    pt = c["parameters"]["POINT"]
    assert list(pt["LABELS"]["value"]) == list(m)
    assert pt["RATE"]["value"][0] == pytest.approx(100.0)
    assert pt["UNITS"]["value"][0] == "mm"
    pts = c["data"]["points"]
    assert pts.shape == (4, 4, t.size)
    for i, k in enumerate(m):
        np.testing.assert_allclose(pts[:3, i, :].T, m[k], rtol=1e-6, atol=1e-3)  # float32 storage


@pytest.mark.parametrize("fmt", ["trc", "mot", "c3d"])
def test_same_input_same_bytes(tmp_path, markers, fmt):
    t, m = markers
    paths = []
    for d in ("x", "y"):
        (tmp_path / d).mkdir()
        p = tmp_path / d / f"f.{fmt}"
        if fmt == "trc":
            write_trc(p, t, m)
        elif fmt == "mot":
            write_mot(p, t, m["SHO"][:, :2])
        else:
            write_c3d(p, t, m)
        paths.append(p)
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert not [f for f in tmp_path.rglob(".*")]  # no temporary file left behind


def test_writers_check_shapes(tmp_path, markers):
    t, m = markers
    with pytest.raises(ValueError, match="shape"):
        write_trc(tmp_path / "bad.trc", t, {"A": np.zeros((3, 3))})
    with pytest.raises(ValueError, match="increasing"):
        write_trc(tmp_path / "bad.trc", t[::-1], m)
    with pytest.raises(ValueError, match="whitespace"):
        write_trc(tmp_path / "bad.trc", t, {"A B": m["SHO"]})
    with pytest.raises(ValueError, match="shape"):
        write_mot(tmp_path / "bad.mot", t, np.zeros((t.size, 3)))
    assert not (tmp_path / "bad.trc").exists()


def _awkward_numbers(rng, n: int) -> np.ndarray:
    """Values whose text is easy to get wrong: negative zeros, numbers that round to zero from below, halves,
    tiny and huge magnitudes, and non-finite ones."""
    special = [0.0, -0.0, -1e-9, 1e-9, -4e-7, -5e-7, -5.000001e-7, 0.5, -0.5, 2.5e-7, 1e300, -1e300, 5e-324, -5e-324]
    special += [123456.7890125, -0.0000004999, np.nan, np.inf, -np.inf, 1 / 3, -2 / 3]
    a = np.concatenate([special, rng.normal(0, 100, n), rng.normal(0, 1e-6, n), 10 ** rng.uniform(-12, 12, n)])
    return a * rng.choice([-1.0, 1.0], a.size)


def test_mot_text_is_the_cell_by_cell_formatting(tmp_path, rng):
    from reachirl.data.writers import _fixed_lines, _fmt

    a = _awkward_numbers(rng, 300)
    a = a[: a.size // 3 * 3].reshape(-1, 3)
    for decimals in ([8, 6, 6], [0, 3, 1]):
        want = "\n".join("\t".join(_fmt(v, d) for v, d in zip(row, decimals, strict=True)) for row in a)
        assert _fixed_lines(a, decimals) == want
    t = np.arange(a.shape[0]) / 100.0
    body = write_mot(tmp_path / "a.mot", t, a[:, 1:]).read_text().splitlines()[7:]
    assert body == ["\t".join([_fmt(t[k], 8), *(_fmt(v, 6) for v in a[k, 1:])]) for k in range(t.size)]
    assert not any(c.startswith("-") and float(c) == 0 for line in body for c in line.split("\t"))
