"""Play a DOC solution's torques back in MuJoCo, open loop or with joint-space PD tracking, and measure the
drift.

Torques are held constant over each DOC interval (zero-order hold). MuJoCo steps ``substeps`` times per
interval (timestep ``dt / substeps``). With ``substeps=1`` the simulation is the DOC's own semi-implicit Euler
step and the open-loop drift is round-off; more substeps approach the continuous dynamics, and the open-loop
drift then shows how sensitive the plan is to its discretisation. ``"pd"`` adds ``Kp (q_ref − q) + Kd (q̇_ref
− q̇)`` to the feed-forward torque, with the reference interpolated linearly between knots. The PD law is
explicit, so stiff gains need substeps (the defaults, Kp = 50 N·m/rad and Kd = 5 N·m·s/rad, are stable from
about 3 substeps at dt = 7 ms).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from ..arm import ArmModel
from ..doc.evaluation import rmse_deg
from ..doc.task import DocSolution
from .mjcf import arm_mujoco_model

__all__ = ["MODES", "PlaybackResult", "playback"]

MODES = ("open-loop", "pd")


@dataclass(frozen=True)
class PlaybackResult:
    """MuJoCo's trajectory sampled at the DOC knots (``t (N+1,)``, ``q``/``qd (N+1, 2)``), the torques it
    applied at the start of each interval (``tau (N, 2)``), and its drift from the DOC plan.
    """

    mode: str
    substeps: int
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray
    rmse_deg: dict  # {"q1", "q2", "q"}: RMSE of MuJoCo's joint angles against the DOC's, degrees
    final_x_error: float  # MuJoCo's final fingertip x minus the DOC's final fingertip x (m)
    max_abs_deg: float  # largest joint-angle deviation along the way, degrees

    def summary(self) -> dict:
        return {
            "mode": self.mode,
            "substeps": self.substeps,
            "rmse_deg": dict(self.rmse_deg),
            "final_x_error_m": self.final_x_error,
            "max_abs_deg": self.max_abs_deg,
        }


def playback(
    arm: ArmModel,
    solution: DocSolution,
    mode: str = "open-loop",
    substeps: int = 10,
    kp: float | tuple[float, float] = 50.0,
    kd: float | tuple[float, float] = 5.0,
    target_x: float | None = None,
    model: mujoco.MjModel | None = None,
    record: bool = False,
) -> tuple[PlaybackResult, np.ndarray | None]:
    """Simulate ``solution``'s torques on ``arm`` in MuJoCo from the solution's initial state.

    Returns the result and, with ``record=True``, MuJoCo's joint angles at every simulation step
    (``(N·substeps + 1, 2)``, for rendering), else ``None``.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps}")
    t = np.asarray(solution.t, dtype=float)
    q_ref, qd_ref, tau_ff = (np.asarray(a, dtype=float) for a in (solution.q, solution.qd, solution.tau))
    n = tau_ff.shape[0]
    dt = float(t[-1] - t[0]) / n
    h = dt / substeps
    if model is None:
        model = arm_mujoco_model(arm, h, target_x)
    elif not np.isclose(model.opt.timestep, h):
        raise ValueError(f"model timestep {model.opt.timestep} differs from dt/substeps = {h}")
    data = mujoco.MjData(model)
    data.qpos[:] = q_ref[0]
    data.qvel[:] = qd_ref[0]
    mujoco.mj_forward(model, data)
    kp_v = np.broadcast_to(np.asarray(kp, dtype=float), (2,))
    kd_v = np.broadcast_to(np.asarray(kd, dtype=float), (2,))

    q_out = np.empty((n + 1, 2))
    qd_out = np.empty((n + 1, 2))
    tau_out = np.empty((n, 2))
    q_out[0], qd_out[0] = data.qpos, data.qvel
    trace = [data.qpos.copy()] if record else None
    for k in range(n):
        for j in range(substeps):
            tau = tau_ff[k].copy()
            if mode == "pd":
                s = j / substeps
                qr = (1 - s) * q_ref[k] + s * q_ref[k + 1]
                vr = (1 - s) * qd_ref[k] + s * qd_ref[k + 1]
                tau += kp_v * (qr - data.qpos) + kd_v * (vr - data.qvel)
            if j == 0:
                tau_out[k] = tau
            data.ctrl[:] = tau
            mujoco.mj_step(model, data)
            if record:
                trace.append(data.qpos.copy())
        q_out[k + 1], qd_out[k + 1] = data.qpos, data.qvel

    err = np.rad2deg(q_out - q_ref)
    rmse = dict(zip(("q1", "q2", "q"), rmse_deg(q_out, q_ref), strict=True))
    x_err = float(arm.fk(q_out[-1])[0] - arm.fk(q_ref[-1])[0])
    result = PlaybackResult(
        mode=mode,
        substeps=int(substeps),
        t=t.copy(),
        q=q_out,
        qd=qd_out,
        tau=tau_out,
        rmse_deg=rmse,
        final_x_error=x_err,
        max_abs_deg=float(np.abs(err).max()),
    )
    return result, (np.array(trace) if record else None)
