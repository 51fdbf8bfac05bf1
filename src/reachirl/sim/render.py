"""Offscreen rendering of a MuJoCo playback to GIF or MP4, with the demonstration as a translucent ghost arm.

The scene is the sagittal plane seen from the side (x to the right, y up): the simulated arm (blue), the
target bar (red) and, when given, the demonstrated reach drawn as a translucent orange arm at the same
instant.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from ..arm import ArmModel
from ..io import atomic_path
from .mjcf import arm_mujoco_model

__all__ = ["RenderClip", "osmesa_available", "render_available", "render_frames", "write_animation"]

log = logging.getLogger(__name__)

GHOST_RGBA = np.array([1.0, 0.5, 0.0, 0.45], dtype=np.float32)


@dataclass(frozen=True)
class RenderClip:
    """One reach to draw: the arm, MuJoCo's joint angles ``q (n, 2)`` at times ``t (n,)``, the target, and an
    optional demonstration ``demo_q(t) -> (2,)`` drawn as a ghost.
    """

    arm: ArmModel
    t: np.ndarray
    q: np.ndarray
    target_x: float
    demo_q: Callable[[float], np.ndarray] | None = None


def osmesa_available() -> tuple[bool, str]:
    """Whether offscreen rendering can work here, and why not."""
    import ctypes.util
    import os

    backend = os.environ.get("MUJOCO_GL", "")
    if backend and backend != "osmesa":
        return True, f"MUJOCO_GL={backend}"
    for name in ("OSMesa", "OSMesa.so.8"):
        if ctypes.util.find_library(name):
            break
    else:
        try:
            ctypes.CDLL("libOSMesa.so.8")
        except OSError as e:
            return False, f"libOSMesa cannot be loaded ({e}); install Debian's libosmesa6"
    return True, "osmesa"


def render_available() -> tuple[bool, str]:
    """Whether MuJoCo can render offscreen here, tried on a tiny scene (the library :func:`osmesa_available` looks
    for, then an OpenGL context of the ``MUJOCO_GL`` backend: an unknown value, or ``glfw`` without a display,
    fails only there), and why not: a reason in one line."""
    import os
    import warnings

    ok, why = osmesa_available()
    if not ok:
        return ok, why
    backend = os.environ.get("MUJOCO_GL") or "(unset)"
    try:
        with warnings.catch_warnings():  # GLFW warns on stderr before it fails: the reason is said once, below
            warnings.simplefilter("ignore")
            model = mujoco.MjModel.from_xml_string("<mujoco/>")
            renderer = mujoco.Renderer(model, height=16, width=16)
            renderer.close()
    except Exception as e:  # ImportError, RuntimeError (an unknown MUJOCO_GL), mujoco.FatalError (no context)
        text = " ".join(str(e).split())[:200]
        return False, (
            f"MuJoCo cannot make an OpenGL context with MUJOCO_GL={backend} ({type(e).__name__}: {text}); set "
            "MUJOCO_GL=osmesa (Debian's libosmesa6) or egl"
        )
    return True, why


def _add_ghost(scene, arm: ArmModel, q: np.ndarray) -> None:
    """Append the ghost arm (two translucent capsules and a fingertip dot) to the scene's geoms."""
    shoulder = np.zeros(3)
    elbow = np.r_[arm.elbow(q), 0.0]
    tip = np.r_[arm.fk(q), 0.0]
    for a, b, width in ((shoulder, elbow, 0.028), (elbow, tip, 0.022)):
        if scene.ngeom >= scene.maxgeom:
            return
        g = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), np.eye(3).ravel(), GHOST_RGBA)
        mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, width, a - [0, 0, 0.03], b - [0, 0, 0.03])
        scene.ngeom += 1
    if scene.ngeom < scene.maxgeom:
        g = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(
            g,
            mujoco.mjtGeom.mjGEOM_SPHERE,
            np.array([0.018, 0, 0]),
            tip - [0, 0, 0.03],
            np.eye(3).ravel(),
            GHOST_RGBA,
        )
        scene.ngeom += 1


def render_frames(
    clips: Sequence[RenderClip], fps: float = 30.0, width: int = 480, height: int = 480, hold_s: float = 0.5
) -> list[np.ndarray]:
    """RGB frames ``(height, width, 3)`` of every clip in turn, at ``fps`` of simulated time, each clip's last
    frame held for ``hold_s`` seconds. The renderer is closed before returning.
    """
    frames: list[np.ndarray] = []
    for clip in clips:
        model = arm_mujoco_model(clip.arm, 0.001, clip.target_x)
        data = mujoco.MjData(model)
        renderer = mujoco.Renderer(model, height=height, width=width)
        try:
            t_end = float(clip.t[-1])
            times = np.arange(0.0, t_end, 1.0 / fps)
            times = np.r_[times, np.full(max(1, round(hold_s * fps)), t_end)]
            for t in times:
                data.qpos[:] = [np.interp(t, clip.t, clip.q[:, j]) for j in range(2)]
                mujoco.mj_forward(model, data)
                renderer.update_scene(data, camera="side")
                if clip.demo_q is not None:
                    _add_ghost(renderer.scene, clip.arm, np.asarray(clip.demo_q(t), dtype=float))
                frames.append(renderer.render().copy())
        finally:
            renderer.close()
    return frames


def _merge_repeats(frames: Sequence[np.ndarray], dt_ms: float) -> tuple[list[np.ndarray], list[float]]:
    """Consecutive identical frames as one frame shown longer (GIF writers merge them anyway, so the file's
    frame count is the count returned here)."""
    out: list[np.ndarray] = []
    durations: list[float] = []
    for f in frames:
        if out and np.array_equal(out[-1], f):
            durations[-1] += dt_ms
        else:
            out.append(f)
            durations.append(dt_ms)
    return out, durations


def write_animation(path: str | Path, frames: Sequence[np.ndarray], fps: float = 30.0) -> tuple[Path, int]:
    """Write frames to a GIF or an MP4 (H.264 through imageio-ffmpeg), atomically; returns the path and the
    number of frames in the file (a GIF shows a run of identical frames as one longer frame).
    """
    import imageio.v3 as iio

    if len(frames) == 0:
        raise ValueError("no frames to write")
    path = Path(path)
    suffix = path.suffix.lower()
    with atomic_path(path, suffix=suffix) as tmp:
        if suffix == ".gif":
            frames, durations = _merge_repeats(frames, 1000.0 / fps)
            iio.imwrite(tmp, np.stack(frames), duration=durations, loop=0)
        elif suffix == ".mp4":
            video = np.stack(frames)
            h, w = video.shape[1:3]  # H.264 with yuv420p needs even sizes: repeat the last row/column
            video = np.pad(video, ((0, 0), (0, h % 2), (0, w % 2), (0, 0)), mode="edge")
            iio.imwrite(tmp, video, plugin="FFMPEG", fps=fps, codec="libx264", macro_block_size=1)
        else:
            raise ValueError(f"animations are written as .gif or .mp4, got {path}")
    log.info("wrote %d frames to %s", len(frames), path)
    return path, len(frames)
