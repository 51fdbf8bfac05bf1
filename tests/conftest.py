import os

import numpy as np
import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

from reachirl import ArmModel  # noqa: E402

# Start postures (q1, q2) in degrees used across tests: a spread of the workspace with the fingertip short of a
# bar at 90 % of arm length.
TEST_POSTURES_DEG = [(-60.0, 90.0), (0.0, 90.0), (30.0, 120.0), (-60.0, 60.0), (50.0, 80.0)]


@pytest.fixture(scope="session")
def arm() -> ArmModel:
    return ArmModel.from_anthropometrics(1.76, 70.0, "M")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)
