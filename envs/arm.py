"""A 7-DOF arm built from primitive geoms, and the MJCF of the two tasks that use it.

The arm follows the common 7-DOF layout (yaw, pitch, roll, pitch, roll, pitch, roll) with a 0.45 m shoulder,
0.45 m upper arm and 0.45 m forearm. Every joint is driven by a position actuator that tracks the commanded
joint position; bodies carry gravity compensation, as the torque-controlled arms of the paper's experiments do,
so tracking does not depend on the pose. The physics runs at 500 Hz and a control step lasts ``frame_skip = 20``
physics steps (25 Hz), so the paper's 69 (hockey) and 78 (basketball) control steps are 2.8 s and 3.1 s of motion.

Nothing is loaded from disk or the web: the model is MJCF text written here.
"""

from __future__ import annotations

import numpy as np

TIMESTEP = 0.002
FRAME_SKIP = 20
JOINT_NAMES = tuple(f"joint{i}" for i in range(1, 8))
# Joint ranges in radians, as on common 7-DOF arms.
JOINT_RANGE = np.array([[-2.9, 2.9], [-2.0, 2.0], [-2.9, 2.9], [-2.8, 2.8], [-2.9, 2.9], [-2.5, 2.5], [-2.9, 2.9]])
# Position servo gains (N m / rad), damping (N m s / rad), torque limits (N m) and reflected motor inertia.
KP = (1500.0, 1500.0, 600.0, 1000.0, 300.0, 300.0, 150.0)
KV = (60.0, 60.0, 20.0, 35.0, 8.0, 8.0, 4.0)
TORQUE = (400.0, 400.0, 200.0, 300.0, 100.0, 100.0, 60.0)
ARMATURE = (0.3, 0.3, 0.1, 0.15, 0.05, 0.05, 0.03)


def _actuators() -> str:
    lines = []
    for i, name in enumerate(JOINT_NAMES):
        low, high = JOINT_RANGE[i]
        lines.append(
            f'<position name="act{i + 1}" joint="{name}" kp="{KP[i]}" kv="{KV[i]}" ctrlrange="{low} {high}" '
            f'forcerange="{-TORQUE[i]} {TORQUE[i]}"/>'
        )
    return "\n    ".join(lines)


def _joint(i: int, axis: str) -> str:
    low, high = JOINT_RANGE[i - 1]
    return f'<joint name="joint{i}" axis="{axis}" range="{low} {high}" armature="{ARMATURE[i - 1]}" damping="0.5"/>'


# The arm's links, base to flange: joint axis, the link's geom (MJCF attributes) and where the next link starts
# (its offset along the link's z axis). Joints alternate between yaw (z) and pitch (y).
_LINKS = (
    ("0 0 1", 'type="cylinder" size="0.07 0.03" pos="0 0 0.03" rgba="0.9 0.9 0.92 1"', 0.05),
    ("0 1 0", 'type="capsule" fromto="0 0 0 0 0 0.2" size="0.05" rgba="0.9 0.9 0.92 1"', 0.2),
    ("0 0 1", 'type="capsule" fromto="0 0 0 0 0 0.25" size="0.045" rgba="0.95 0.55 0.1 1"', 0.25),
    ("0 1 0", 'type="capsule" fromto="0 0 0 0 0 0.2" size="0.04" rgba="0.9 0.9 0.92 1"', 0.2),
    ("0 0 1", 'type="capsule" fromto="0 0 0 0 0 0.25" size="0.035" rgba="0.95 0.55 0.1 1"', 0.25),
    ("0 1 0", 'type="capsule" fromto="0 0 0 0 0 0.05" size="0.03" rgba="0.9 0.9 0.92 1"', 0.05),
    ("0 0 1", 'name="flange" type="cylinder" size="0.03 0.01" pos="0 0 0.01" rgba="0.2 0.2 0.2 1"', 0.02),
)


def arm_mjcf(tool: str) -> str:
    """The arm's kinematic tree with ``tool`` (MJCF body content) mounted on the flange (the flange's +z axis)."""
    inner = f'<body name="tool" pos="0 0 {_LINKS[-1][2]:g}">{tool}</body>'
    for i in range(len(_LINKS), 0, -1):  # from the flange inwards: each link's body holds the next one
        axis, geom, _ = _LINKS[i - 1]
        start = 0.4 if i == 1 else _LINKS[i - 2][2]  # link 1 sits on the 0.4 m pedestal
        inner = f'<body name="link{i}" pos="0 0 {start:g}" gravcomp="1">{_joint(i, axis)}<geom {geom}/>{inner}</body>'
    return (
        '<body name="base" pos="0 0 0" childclass="arm"><geom name="pedestal" type="cylinder" size="0.09 0.2" '
        f'pos="0 0 0.2" rgba="0.25 0.25 0.28 1"/>{inner}</body>'
    )


def task_mjcf(*, name: str, tool: str, world: str, sensors: str, camera: str) -> str:
    """A complete MJCF document: arm with ``tool``, ``world`` bodies, ``sensors`` and a camera, on a floor."""
    return f"""
<mujoco model="{name}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{TIMESTEP}" integrator="implicitfast" cone="elliptic"/>
  <visual>
    <global offwidth="640" offheight="480"/>
    <quality shadowsize="2048"/>
    <headlight ambient="0.4 0.4 0.4" diffuse="0.6 0.6 0.6"/>
  </visual>
  <asset>
    <texture name="grid" type="2d" builtin="checker" rgb1="0.32 0.36 0.42" rgb2="0.28 0.32 0.38" width="512" height="512"/>
    <material name="grid" texture="grid" texrepeat="8 8" reflectance="0.05"/>
  </asset>
  <default>
    <!-- The world's geoms collide with everything; the arm's (and its tool's) with the world only, not with
         each other: its links touch where they are jointed, as a real arm's housings do. -->
    <geom contype="1" conaffinity="3" friction="0.8 0.005 0.0001" solref="0.004 1"/>
    <default class="arm">
      <geom contype="2" conaffinity="1"/>
    </default>
  </default>
  <worldbody>
    <light pos="0 0 4" dir="0 0 -1" diffuse="0.7 0.7 0.7"/>
    {camera}
    {arm_mjcf(tool)}
    {world}
  </worldbody>
  <actuator>
    {_actuators()}
  </actuator>
  <sensor>
    {sensors}
  </sensor>
</mujoco>
"""
