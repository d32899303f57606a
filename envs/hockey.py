"""``GenRL/Hockey-v0``: shoot a puck with a stick held by the arm to a target on the table (paper section 6.1.1)."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from sb3_genrl.envs.arm import task_mjcf
from sb3_genrl.envs.base import ArmTaskEnv

# Paper section 6.1.1: target uniform in x in [0.65, 1.3] m, y in [-0.4, 0.4] m from the robot; 69 control steps.
HOCKEY_GOAL_LOW = np.array([0.65, -0.4])
HOCKEY_GOAL_HIGH = np.array([1.3, 0.4])
HOCKEY_HORIZON = 69

BLADE_CLEARANCE = 0.008  # height of the blade's lower edge above the table at the home pose (m)
PUCK_RADIUS, PUCK_HALF_HEIGHT = 0.04, 0.0125

_TOOL = """
<geom name="shaft" type="capsule" fromto="0 0 0 0 0 0.2" size="0.012" density="600" rgba="0.55 0.35 0.2 1"/>
<geom name="blade" type="box" pos="0 0 0.225" size="0.012 0.07 0.03" density="600" friction="0.25 0.005 0.0001"
      rgba="0.15 0.15 0.15 1"/>
<site name="blade_tip" pos="0 0 0.255" size="0.005"/>
"""
_WORLD = f"""
<geom name="table" type="plane" size="2.5 2.5 0.1" material="grid" friction="0.25 0.005 0.0001"/>
<body name="puck" pos="0.45 0 {PUCK_HALF_HEIGHT}">
  <freejoint name="puck"/>
  <geom name="puck" type="cylinder" size="{PUCK_RADIUS} {PUCK_HALF_HEIGHT}" mass="0.17" friction="0.25 0.005 0.0001"
        rgba="0.05 0.05 0.05 1"/>
</body>
<body name="goal" mocap="true" pos="1.0 0 0.001">
  <geom type="cylinder" size="0.04 0.001" contype="0" conaffinity="0" rgba="0.9 0.1 0.1 1"/>
</body>
"""
_SENSORS = """
<clock/>
<framepos objtype="body" objname="puck"/>
<framelinvel objtype="body" objname="puck"/>
""" + "\n".join(f'<jointvel joint="joint{i}"/>' for i in range(1, 8)) + """
<contact subtree1="tool" geom2="table" num="1" data="found"/>
"""
_CAMERA = '<camera name="overview" pos="0.75 -1.75 1.55" xyaxes="1 0 0 0 0.7 0.714"/>'


class HockeyEnv(ArmTaskEnv):
    """Hit a puck with a stick to a goal on the table.

    ## Description
    A 7-DOF arm (see :mod:`sb3_genrl.envs.arm`) holds a stick whose blade hangs just above the table, behind a
    puck. The goal is uniform in ``x in [0.65, 1.3] m``, ``y in [-0.4, 0.4] m`` from the robot base (paper
    section 6.1.1). The puck slides with Coulomb friction (coefficient 0.25).

    ## Action Space
    ``Box(-max_joint_delta, max_joint_delta, (7,))``: the change of the 7 commanded joint positions (rad) for this
    control step (0.04 s). Commands beyond a joint's range are clipped to it (``info["joint_limit_clipped"]``).

    ## Observation Space
    ``Box(16,)``: goal (x, y) in metres, 7 joint positions (rad), 7 joint velocities (rad/s).

    ## Rewards
    0 until the end; then minus the Euclidean distance (m) between the puck's resting point and the goal.
    An unstable simulation gives ``worst_reward`` (-5 m) and ``info["unstable"] = True``.

    ## Starting State
    The arm at its home pose, the stick's blade ``BLADE_CLEARANCE`` above the table, the puck at rest in front
    of the blade. Only the goal is random.

    ## Episode End
    After ``horizon = 69`` actions the arm holds its last command and the simulation runs on until the puck
    rests (speed below 5 mm/s) or ``settle_steps`` more control steps have passed. ``info`` then holds
    ``reached`` (the puck's rest point), ``table_contacts`` (control steps in which the stick touched the table
    top), ``distance`` and ``reward``.

    ## Arguments
    ``max_joint_delta`` (0.5 rad), ``settle_steps`` (50 control steps = 2 s), ``render_mode`` (``"rgb_array"``),
    ``width``, ``height``.

    ## Version History
    * v0: initial version.
    """

    horizon = HOCKEY_HORIZON
    worst_reward = -5.0
    goal_low = HOCKEY_GOAL_LOW
    goal_high = HOCKEY_GOAL_HIGH

    def __init__(self, *, settle_steps: int = 50, **kwargs: Any) -> None:
        self.settle_steps = int(settle_steps)
        self._home = None
        super().__init__(settle_steps=settle_steps, **kwargs)

    def _mjcf(self) -> str:
        return task_mjcf(name="hockey", tool=_TOOL, world=_WORLD, sensors=_SENSORS, camera=_CAMERA)

    def home_qpos(self) -> np.ndarray:
        if self._home is None:
            self._home = _hockey_home(self.model)
        return self._home.copy()

    def sample_goal(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(self.goal_low, self.goal_high)

    def _place_objects(self) -> None:
        data = self.data
        mujoco.mj_kinematics(self.model, data)
        blade = data.geom("blade")
        front = blade.xpos + blade.xmat.reshape(3, 3)[:, 0] * 0.0  # blade centre
        puck_adr = self.model.joint("puck").qposadr[0]
        data.qpos[puck_adr:puck_adr + 3] = [front[0] + 0.012 + PUCK_RADIUS + 0.01, front[1], PUCK_HALF_HEIGHT]
        data.qpos[puck_adr + 3:puck_adr + 7] = [1, 0, 0, 0]

    def _settled(self, row: np.ndarray) -> bool:
        return bool(np.linalg.norm(row[4:7]) < 0.005)

    def _outcome(self, rows: np.ndarray, goal: np.ndarray) -> tuple[float, dict[str, Any]]:
        reached = rows[-1, 1:3].copy()
        distance = float(np.linalg.norm(reached - goal))
        contact = rows[:, 14] > 0
        n_steps = -(-len(rows) // self.frame_skip)
        padded = np.zeros(n_steps * self.frame_skip, dtype=bool)
        padded[: len(contact)] = contact
        table_contacts = int(padded.reshape(n_steps, self.frame_skip).any(axis=1).sum())
        return -distance, {"reached": reached, "distance": distance, "table_contacts": table_contacts}


def _hockey_home(model: mujoco.MjModel) -> np.ndarray:
    """The home pose: forearm vertical above the puck, blade lower edge ``BLADE_CLEARANCE`` above the table."""
    data = mujoco.MjData(model)
    qadr = [model.joint(f"joint{i}").qposadr[0] for i in range(1, 8)]

    def blade_bottom(shoulder: float) -> float:
        q = np.array([0.0, shoulder, 0.0, np.pi - shoulder, 0.0, 0.0, 0.0])
        data.qpos[qadr] = q
        mujoco.mj_kinematics(model, data)
        return float(data.site("blade_tip").xpos[2]) - BLADE_CLEARANCE

    low, high = 0.3, 1.4  # blade_bottom decreases with the shoulder angle in this interval
    for _ in range(60):
        mid = 0.5 * (low + high)
        if blade_bottom(mid) > 0:
            low = mid
        else:
            high = mid
    shoulder = 0.5 * (low + high)
    return np.array([0.0, shoulder, 0.0, np.pi - shoulder, 0.0, 0.0, 0.0])
