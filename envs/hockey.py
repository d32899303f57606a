"""``GenRL/Hockey-v0``: shoot a puck with a stick held by the arm to a target on the table (paper section 6.1.1).

The module holds the whole task: the env, its goal region, its scripted expert and the registry entry
:data:`TASK`.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from sb3_genrl.envs.arm import task_mjcf
from sb3_genrl.envs.base import ArmTaskEnv
from sb3_genrl.envs.goal import GoalConditionedMixin
from sb3_genrl.envs.motions import bump
from sb3_genrl.envs.spec import TaskSpec

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
_SENSORS = (
    """
<clock/>
<framepos objtype="body" objname="puck"/>
<framelinvel objtype="body" objname="puck"/>
"""
    + "\n".join(f'<jointvel joint="joint{i}"/>' for i in range(1, 8))
    + """
<contact subtree1="tool" geom2="table" num="1" data="found"/>
"""
)
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
        centre = blade.xpos
        puck_adr = self.model.joint("puck").qposadr[0]
        data.qpos[puck_adr : puck_adr + 3] = [centre[0] + 0.012 + PUCK_RADIUS + 0.01, centre[1], PUCK_HALF_HEIGHT]
        data.qpos[puck_adr + 3 : puck_adr + 7] = [1, 0, 0, 0]

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


class HockeyGoalEnv(GoalConditionedMixin, HockeyEnv):
    """``GenRL/HockeyGoal-v0``: :class:`HockeyEnv` with dict observations (see :mod:`sb3_genrl.envs.goal`).

    The terminal reward is minus the distance between the puck's rest point (the terminal ``achieved_goal``) and
    the desired goal, bounded below by ``worst_reward``; an unstable simulation gives ``worst_reward``.
    """


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


def in_goal_region(points: np.ndarray) -> np.ndarray:
    """Per point ``(x, y)``: whether it lies in the goal rectangle."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return np.all((points >= HOCKEY_GOAL_LOW) & (points <= HOCKEY_GOAL_HIGH), axis=1)


# ----------------------------------------------------------------------------------------- the scripted expert
# Perturbation sizes per joint (rad moved by one bump at level 1). They are small next to the base motions'
# strength and direction, so the demonstrations vary mainly along the task's factors (as a few demonstrations
# with changed joint velocities do) and a low-dimensional generator can capture them; the shoulder and elbow
# (which lower the blade onto the table) get the smallest.
HOCKEY_PERTURBATION = np.array([0.04, 0.02, 0.04, 0.02, 0.05, 0.04, 0.05])
# Control step at which every hit starts: timing changes nothing in the outcome, and whole-step shifts split the
# demonstrations into one cluster per start step, which a 2-D generator then lays out as separate patches of its
# latent space (each patch covering part of the goal region), so the latent action that reaches a goal jumps
# between patches.
HOCKEY_SWING_START = 25
# Aims: a target drawn uniformly in the goal region widened by HOCKEY_AIM_MARGIN (m) on each side, hit from the
# puck's start at HOCKEY_PUCK_X with direction = the target's bearing and a strength for its distance, read off the
# measured distance (m) -> strength curve of scripted_hit.
HOCKEY_AIM_MARGIN = 0.08
HOCKEY_PUCK_X = 0.36
HOCKEY_DISTANCE_TO_STRENGTH = (
    np.array([0.19, 0.256, 0.301, 0.362, 0.43, 0.49, 0.549, 0.612, 0.676, 0.765, 0.84, 0.92, 0.998, 1.079, 1.165, 1.252]),
    np.array([0.6, 0.7, 0.75, 0.8, 0.9, 0.95, 1.0, 1.05, 1.1, 1.15, 1.25, 1.3, 1.35, 1.4, 1.45, 1.5]),
)


def scripted_hit(*, strength: float = 1.0, direction: float = 0.0, swing_start: int = 25) -> np.ndarray:
    """A hit: turn the swing plane by ``direction`` (rad, forearm roll), wind up the wrist, swing through.

    :param strength: scales the swing's amplitude and speed; 0.75-1.3 sends the puck to x = 0.65-1.3 m, weaker hits
        fall short of the goal region
    :param direction: the shot's angle (rad) from the x axis, positive to the robot's right (negative y)
    :param swing_start: control step at which the forward swing starts
    :return: ``(69, 7)`` joint position deltas
    """
    trajectory = np.zeros((HOCKEY_HORIZON, 7))
    trajectory[:, 4] = bump(HOCKEY_HORIZON, 4, 8, direction)
    backswing = 0.35 * strength
    trajectory[:, 5] = bump(HOCKEY_HORIZON, 10, 10, backswing)
    trajectory[:, 5] += bump(HOCKEY_HORIZON, swing_start, 6, -2 * backswing)  # through the puck
    trajectory[:, 5] += bump(HOCKEY_HORIZON, swing_start + 10, 12, backswing)  # back to vertical, slowly
    return trajectory


def sample_hit(rng: np.random.Generator) -> np.ndarray:
    """The expert's base motion: a hit aimed at a random target around the goal region (see the constants above).

    :param rng: the random generator
    :return: ``(69, 7)`` joint position deltas
    """
    target = rng.uniform(HOCKEY_GOAL_LOW - HOCKEY_AIM_MARGIN, HOCKEY_GOAL_HIGH + HOCKEY_AIM_MARGIN)
    offset = target - np.array([HOCKEY_PUCK_X, 0.0])
    strength = np.interp(np.linalg.norm(offset), *HOCKEY_DISTANCE_TO_STRENGTH) * rng.uniform(0.95, 1.05)
    return scripted_hit(strength=strength, direction=float(np.arctan2(-offset[1], offset[0])), swing_start=HOCKEY_SWING_START)


def is_valid(info: dict[str, Any]) -> bool:
    """A hit may be a demonstration when the stick never touched the table."""
    return info.get("table_contacts", 1) == 0


TASK = TaskSpec(
    name="hockey",
    env_id="GenRL/Hockey-v0",
    env_class=HockeyEnv,
    horizon=HOCKEY_HORIZON,
    goal_low=HOCKEY_GOAL_LOW,
    goal_high=HOCKEY_GOAL_HIGH,
    in_goal_region=in_goal_region,
    cell_size=0.05,
    sample_expert=sample_hit,
    perturbation_scales=HOCKEY_PERTURBATION,
    is_valid=is_valid,
    goal_env_id="GenRL/HockeyGoal-v0",
    goal_env_class=HockeyGoalEnv,
    # Half the generator stage's default: on 200 tuning goals, seeds 0 and 1, the quickstart's policy reaches 5.5 and
    # 5.5 mm from 2000 demonstrations against 5.8 and 6.0 mm from 4000, in half the demonstration and generator time
    # (docs/results.md, "The quickstart"). Basketball's does not: 8.1 cm from 2000 against 4.2 cm from 4000 (seed 0).
    quickstart_demo_episodes=2000,
)
