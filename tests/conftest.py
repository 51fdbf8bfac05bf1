import os

import numpy as np
import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

from reachirl import ArmModel


@pytest.fixture(scope="session")
def arm() -> ArmModel:
    return ArmModel.from_anthropometrics(1.76, 70.0, "M")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)
