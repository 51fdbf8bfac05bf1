"""The arm as a MuJoCo model (MJCF), with the same inertias as :class:`~reachirl.arm.ArmModel`.

The arm moves in the vertical x-y plane (x forward, y up) with gravity ``(0, -g, 0)``: two hinge joints about
z, no joint damping, armature, friction or limits, no contacts, torque motors with unit gear. Each segment's
inertial matches :meth:`ArmModel.pinocchio_model` (CoM at ``c`` on the segment's x axis, ``izz = i``; the two
out-of-plane moments, which never act, are ``0.6 i`` so that MuJoCo's A + B ≥ C check holds after rounding).
MuJoCo's ``Euler`` integrator is semi-implicit Euler,
the DOC's own discretisation, so a playback with the timestep equal to the DOC's ``dt`` reproduces the plan to
round-off.
"""

from __future__ import annotations

import mujoco

from ..arm import ArmModel

__all__ = ["arm_mjcf", "arm_mujoco_model"]

_RADIUS = 0.03  # drawing radius of the segments (m); geoms carry no mass and no contacts


def arm_mjcf(arm: ArmModel, timestep: float = 0.005, target_x: float | None = None) -> str:
    """MJCF text of ``arm``; ``target_x`` adds the vertical target bar at that fingertip x (m)."""
    if not timestep > 0:
        raise ValueError(f"timestep must be > 0, got {timestep}")
    half_view = 1.0 * arm.length
    bar = ""
    if target_x is not None:
        bar = (
            f'<geom name="target_bar" type="box" pos="{target_x:.9g} 0 0" size="0.006 {half_view:.9g} 0.006" '
            'rgba="0.85 0.2 0.15 1" contype="0" conaffinity="0"/>'
        )
    return f"""<mujoco model="reachirl_arm">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="{timestep:.12g}" gravity="0 {-arm.gravity:.12g} 0" integrator="Euler">
    <flag contact="disable"/>
  </option>
  <visual>
    <global offwidth="1280" offheight="1280"/>
    <quality shadowsize="0"/>
  </visual>
  <asset>
    <texture name="sky" type="skybox" builtin="gradient" rgb1="0.97 0.97 0.97" rgb2="0.85 0.87 0.9" width="64"
             height="64"/>
  </asset>
  <default>
    <joint type="hinge" axis="0 0 1" damping="0" armature="0" frictionloss="0" limited="false"/>
    <geom contype="0" conaffinity="0" mass="0"/>
    <motor gear="1" ctrllimited="false"/>
  </default>
  <worldbody>
    <light name="key" pos="0 0 3" dir="0 0 -1" directional="true" diffuse="0.9 0.9 0.9"/>
    <camera name="side" pos="{0.35 * arm.length:.6g} 0 {2.3 * arm.length:.6g}" xyaxes="1 0 0 0 1 0"
            fovy="45"/>
    <geom name="shoulder_marker" type="sphere" size="0.03" rgba="0.3 0.3 0.3 1"/>
    {bar}
    <body name="upper_arm">
      <joint name="shoulder"/>
      <inertial pos="{arm.c1:.12g} 0 0" mass="{arm.m1:.12g}"
                diaginertia="{arm.i1 * 0.6:.12g} {arm.i1 * 0.6:.12g} {arm.i1:.12g}"/>
      <geom name="upper_arm" type="capsule" fromto="0 0 0 {arm.l1:.12g} 0 0" size="{_RADIUS}"
            rgba="0.2 0.45 0.8 1"/>
      <body name="forearm" pos="{arm.l1:.12g} 0 0">
        <joint name="elbow"/>
        <inertial pos="{arm.c2:.12g} 0 0" mass="{arm.m2:.12g}"
                  diaginertia="{arm.i2 * 0.6:.12g} {arm.i2 * 0.6:.12g} {arm.i2:.12g}"/>
        <geom name="forearm" type="capsule" fromto="0 0 0 {arm.l2:.12g} 0 0" size="{_RADIUS * 0.8}"
              rgba="0.2 0.45 0.8 1"/>
        <site name="fingertip" pos="{arm.l2:.12g} 0 0" size="0.012" rgba="1 0.8 0.1 1"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="shoulder" joint="shoulder"/>
    <motor name="elbow" joint="elbow"/>
  </actuator>
</mujoco>
"""


def arm_mujoco_model(arm: ArmModel, timestep: float = 0.005, target_x: float | None = None) -> mujoco.MjModel:
    """The compiled :func:`arm_mjcf` model."""
    return mujoco.MjModel.from_xml_string(arm_mjcf(arm, timestep, target_x))
