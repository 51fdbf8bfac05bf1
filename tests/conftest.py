import os
import sys
from pathlib import Path

import numpy as np
import pytest

# the shared helpers (moirl_settings, attack_cli) live here and are imported as top-level modules by the tests in
# the subfolders, which mirror src/reachirl/
sys.path.insert(0, str(Path(__file__).resolve().parent))

os.environ.setdefault("OMP_NUM_THREADS", "1")
# no background compilation into the user's cache from a test run (tests/doc/test_compiled.py sets its own)
os.environ.setdefault("REACHIRL_COMPILE", "off")
os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

from reachirl import ArmModel


@pytest.fixture(scope="session")
def arm() -> ArmModel:
    return ArmModel.from_anthropometrics(1.76, 70.0, "M")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


def run_reachirl(*args, timeout: float = 300, cwd=None):
    """Run the installed ``reachirl`` console script (not ``main()`` in-process); returns the CompletedProcess."""
    import subprocess
    import sys
    from pathlib import Path

    exe = Path(sys.executable).parent / "reachirl"
    return subprocess.run(
        [str(exe), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )


@pytest.fixture(scope="session")
def cli():
    """``cli("fit", ...)`` runs the installed console script: see :func:`run_reachirl`."""
    return run_reachirl


@pytest.fixture(scope="session")
def tiny_trials(tmp_path_factory, arm):
    """A trials file of 6 DOC reaches (2 subjects × 3 trials, posture P2, 20 knots) for the CLI tests."""
    from reachirl import ReachingTask, solve_doc
    from reachirl.data.trial import save_trials, trial_from_solution

    rng = np.random.default_rng(0)
    w = np.array([[0.05, 0.5, 0.05, 3.0, 0.2, 0.05, 0.5]]) / np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])
    trials = []
    for s in ("S1", "S2"):
        for i in range(3):
            q0 = np.deg2rad([0.0, 90.0]) + np.deg2rad(rng.normal(0, 2, 2))
            task = ReachingTask(arm, q0, 0.9 * arm.length, 0.7 + 0.03 * rng.normal(), n_nodes=20)
            sol = solve_doc(task, w * np.exp(0.1 * rng.normal(size=w.shape)))
            assert sol.converged
            trials.append(trial_from_solution(sol, arm, task.target_x, subject=s, posture="P2", trial_id=f"T{i}"))
    path = tmp_path_factory.mktemp("tiny") / "trials.npz"
    save_trials(path, trials)
    return path


@pytest.fixture(scope="session")
def recorded(tmp_path_factory):
    """Virtual subjects recorded as real ones are: markers with noise at 100 Hz, rest before and after, run
    through ``reachirl synth`` and ``reachirl preprocess`` (trials cut at a fingertip-speed threshold). Two
    subjects, postures P2 and P4, 4 reaches each; returns the folder (``trials.npz``, ``truth.json``)."""
    from recordings import preprocess, synth

    d = tmp_path_factory.mktemp("recorded")
    preprocess(synth(d / "raw", ("P2", "P4"), subjects=2, trials=4, seed=3), d / "trials.npz")
    return d
