"""MuJoCo playback of predicted reaches: the arm as MJCF, open-loop and PD playback, offscreen rendering.

Importing this package defaults MuJoCo's OpenGL backend to OSMesa (CPU, offscreen) when no display is set, so
that rendering works on headless machines; set ``MUJOCO_GL`` yourself to choose another backend.
"""

from __future__ import annotations

import os

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "osmesa"
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

from .mjcf import arm_mjcf, arm_mujoco_model
from .playback import PlaybackResult, playback

__all__ = ["PlaybackResult", "arm_mjcf", "arm_mujoco_model", "playback"]
