"""The banded solve of the Newton methods (reachirl.doc.banded): LAPACK's dgbsv, compiled, to the last bit."""

import numpy as np
import pytest
from scipy.linalg.lapack import dgbsv

from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.doc import banded, compiled, newton
from reachirl.doc.observation import observed_task
from reachirl.virtual import nominal_weights, posture_q


@pytest.fixture
def native(tmp_path, monkeypatch):
    """The compiled solve, from an empty cache (compiled here, a fraction of a second)."""
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    banded._loaded.cache_clear()
    with compiled.setting("on"):
        assert banded.native()
        yield
    banded._loaded.cache_clear()


def _band(a: np.ndarray, kl: int, ku: int) -> np.ndarray:
    """``a`` (dense, n × n) in LAPACK's band storage with ``kl`` rows of fill-in on top."""
    n = a.shape[0]
    ab = np.zeros((2 * kl + ku + 1, n), order="F")
    for j in range(n):
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            ab[kl + ku + i - j, j] = a[i, j]
    return ab


def _lapack(ab, b, kl, ku):
    _, _, x, info = dgbsv(kl, ku, ab.copy(order="F"), b.copy())
    return x, info


def _random_banded(rng, n, kl, ku, zero_diagonal=0.3):
    """A banded matrix whose diagonal is zero in a share of its rows (pivoting needed, as at a kink's row)."""
    a = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            a[i, j] = rng.normal()
    a[np.diag_indices(n)] *= rng.uniform(size=n) > zero_diagonal
    return a


@pytest.mark.parametrize(("n", "kl", "ku"), [(298, 10, 10), (199, 7, 7), (40, 3, 5), (1, 2, 2), (5, 10, 10)])
def test_the_compiled_solve_is_lapacks_to_the_last_bit(native, n, kl, ku):
    rng = np.random.default_rng(n + kl)
    for _ in range(20):
        a = _random_banded(rng, n, kl, ku, zero_diagonal=0.3 if n > 2 else 0.0)
        b = rng.normal(size=n)
        ab = _band(a, kl, ku)
        x_ref, info_ref = _lapack(ab, b, kl, ku)
        x = b.copy()
        info = banded.solve(kl, ku, ab, x)
        assert info == info_ref == 0
        assert np.array_equal(x, x_ref)
        assert np.allclose(a @ x, b, atol=1e-8 * np.abs(a).max() * np.abs(x).max())


def test_newtons_answers_are_the_same_with_the_compiled_solve_and_with_lapack(native):
    """A whole Newton solve (a real KKT system at every step, kinks and the bar included) through either solve:
    the same iterations and the same optimum, bit for bit."""
    arm = ArmModel.from_anthropometrics(1.75, 70.0, "male")
    task = ReachingTask(arm, posture_q("P2") + np.deg2rad([3.0, -2.0]), 0.95 * arm.length, 0.8, n_nodes=60)
    w = nominal_weights()
    with compiled.setting("off"):  # fatrop on CasADi's virtual machine (not compiled for these knots here)
        start = solve_doc(task, w * np.array([1.5, 0.7, 1.0, 1.3, 0.8, 1.0, 1.2]))  # the optimum under other weights
    assert start.converged
    found = newton.newton_solve(task, w, start.q)
    with compiled.setting("off"):
        assert not banded.native()
        lapack = newton.newton_solve(task, w, start.q)
    assert found is not None and lapack is not None
    assert found.iterations == lapack.iterations > 0
    assert np.array_equal(found.q, lapack.q)
    assert found.cost == lapack.cost


def test_an_exactly_zero_pivot_is_lapacks_info_and_leaves_the_right_hand_side(native):
    a = np.diag([2.0, 1.0, 0.0, 3.0])
    a[0, 1] = 1.0
    b = np.array([1.0, 2.0, 3.0, 4.0])
    ab = _band(a, 1, 1)
    _, info_ref = _lapack(ab, b, 1, 1)
    x = b.copy()
    assert banded.solve(1, 1, ab, x) == info_ref == 3
    with compiled.setting("off"):
        y = b.copy()
        assert banded.solve(1, 1, _band(a, 1, 1), y) == 3


def test_without_the_compiled_solve_lapack_solves_in_place():
    rng = np.random.default_rng(3)
    a = _random_banded(rng, 50, 4, 4)
    b = rng.normal(size=50)
    ab = _band(a, 4, 4)
    x_ref, _ = _lapack(ab, b, 4, 4)
    with compiled.setting("off"):
        x = b.copy()
        assert banded.solve(4, 4, ab, x) == 0
    assert np.array_equal(x, x_ref)


def test_storage_that_does_not_fit_is_refused():
    ab = np.zeros((7, 10), order="F")
    with pytest.raises(ValueError, match=r"band storage \(7, 10\) and right-hand side \(9,\) do not fit kl=2, ku=2"):
        banded.solve(2, 2, ab, np.zeros(9))
    with pytest.raises(ValueError, match="must be Fortran-ordered float64"):
        banded.solve(2, 2, np.zeros((7, 10)), np.zeros(10))
    with pytest.raises(ValueError, match="must be Fortran-ordered float64"):
        banded.solve(2, 2, ab, np.zeros(10, dtype=np.float32))


def test_lapack_only_switches_to_lapack_within_its_block(native):
    """What `reachirl bench predict` times against the compiled loop: LAPACK's dgbsv, and back after the block."""
    with banded.lapack_only():
        assert not banded.native()
        rng = np.random.default_rng(5)
        a = _random_banded(rng, 30, 3, 3)
        x = rng.normal(size=30)
        ab = _band(a, 3, 3)
        x_ref, _ = _lapack(ab, x, 3, 3)
        assert banded.solve(3, 3, ab, x) == 0
        assert np.array_equal(x, x_ref)
    assert banded.native()


def test_a_workers_preload_compiles_the_banded_lu(tmp_path, monkeypatch):
    """A unit worker readies the LU with Newton's functions, before its first unit (not in its first solve)."""
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    banded._loaded.cache_clear()
    try:
        with compiled.setting("on"):
            assert not list(tmp_path.rglob("fn-banded_lu-*.so"))
            newton.preload(12)
            assert len(list(tmp_path.rglob("fn-banded_lu-*.so"))) == 1
            assert banded._loaded.cache_info().currsize == 1  # loaded in this process
    finally:
        banded._loaded.cache_clear()


def test_a_damaged_library_in_the_cache_is_compiled_again(tmp_path, monkeypatch):
    """A cached library that does not load (a truncated copy, another file under its name) is replaced, once, by
    a new compilation: the compiled loop is used, not LAPACK's for ever after."""
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    banded._loaded.cache_clear()
    try:
        with compiled.setting("on"):
            path = compiled.compiled_library(banded.SOURCE)  # compiled, not loaded by this process
            path.write_bytes(b"not a shared library")
            assert banded.native()
            assert path.read_bytes() != b"not a shared library"
    finally:
        banded._loaded.cache_clear()


def test_predictions_of_recorded_trials_are_the_same_with_either_lu(recorded, tmp_path, monkeypatch):
    """Reaches recorded as real ones are (markers with noise, cut at a speed threshold), each predicted as
    ``reproduce`` predicts it (the observed DOC from another reach's solution moved to it, then the part seen):
    the compiled LU's predictions are LAPACK's, bit for bit, and answered by Newton."""
    from reachirl.data.trial import load_trials
    from reachirl.doc.observation import predict

    trials = [t for t in load_trials(recorded / "trials.npz") if t.posture == "P4"]
    w = nominal_weights()
    n = 60
    path = solve_doc(observed_task(trials[0], n, trials[0].onset_threshold), w).q  # the fit's own reach
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path))
    banded._loaded.cache_clear()
    answered = 0
    for trial in trials[1:]:
        with compiled.setting("auto"):  # the LU compiled; fatrop, where Newton gives way, on the VM (not compiled)
            assert banded.native()
            _, ours = predict(trial, w, n, trial.onset_threshold, path=path)
        with banded.lapack_only():
            _, lapack = predict(trial, w, n, trial.onset_threshold, path=path)
        assert np.array_equal(ours.q, lapack.q) and np.array_equal(ours.qd, lapack.qd)
        assert ours.cost == lapack.cost and ours.status == lapack.status
        answered += ours.status.startswith("newton")
    assert answered >= len(trials) - 2
    banded._loaded.cache_clear()
