"""``GenRL/Basketball-v0``: throw a ball from a cup held by the arm into a basket (paper section 6.1.1).

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

# Paper section 6.1.1: basket at radius 1-8 m and angle [-pi/2, pi/2] from the robot; 78 control steps.
BASKET_RADIUS_RANGE = (1.0, 8.0)
BASKET_ANGLE_RANGE = (-np.pi / 2, np.pi / 2)
BASKETBALL_HORIZON = 78
BASKET_HEIGHT = 0.4  # height of the basket's rim (m)
BALL_RADIUS = 0.05

# The cup opens towards the flange's +x axis, the direction in which positive pitch joint motion moves it, so the
# ball is pushed by the cup's bottom while the arm accelerates and flies on when the arm slows down.
_TOOL = f"""
<geom name="cup_stem" type="capsule" fromto="0 0 0 0 0 0.08" size="0.02" rgba="0.2 0.2 0.2 1"/>
<geom name="cup_bottom" type="box" pos="0 0 0.14" size="0.008 0.07 0.07" rgba="0.85 0.2 0.2 1"/>
<geom name="cup_side1" type="box" pos="0.035 0.075 0.14" size="0.035 0.006 0.07" rgba="0.85 0.2 0.2 1"/>
<geom name="cup_side2" type="box" pos="0.035 -0.075 0.14" size="0.035 0.006 0.07" rgba="0.85 0.2 0.2 1"/>
<geom name="cup_side3" type="box" pos="0.035 0 0.215" size="0.035 0.07 0.006" rgba="0.85 0.2 0.2 1"/>
<geom name="cup_side4" type="box" pos="0.035 0 0.065" size="0.035 0.07 0.006" rgba="0.85 0.2 0.2 1"/>
<site name="cup_centre" pos="{0.008 + BALL_RADIUS + 0.002} 0 0.14" size="0.005"/>
"""
_WORLD = f"""
<geom name="floor" type="plane" size="10 10 0.1" material="grid" solref="0.01 0.3"/>
<body name="ball" pos="0 0 1">
  <freejoint name="ball"/>
  <geom name="ball" type="sphere" size="{BALL_RADIUS}" mass="0.2" solref="0.01 0.3" rgba="0.95 0.45 0.1 1"/>
</body>
<body name="goal" mocap="true" pos="3 0 {BASKET_HEIGHT}">
  <geom type="cylinder" size="0.15 0.01" contype="0" conaffinity="0" rgba="0.9 0.1 0.1 0.6"/>
  <geom type="cylinder" size="0.01 {BASKET_HEIGHT / 2}" pos="0 0 {-BASKET_HEIGHT / 2}" contype="0" conaffinity="0"
        rgba="0.6 0.6 0.6 1"/>
</body>
"""
_SENSORS = """
<clock/>
<framepos objtype="body" objname="ball"/>
<framelinvel objtype="body" objname="ball"/>
""" + "\n".join(f'<jointvel joint="joint{i}"/>' for i in range(1, 8))
_CAMERA = '<camera name="overview" pos="-2.5 -7 4.5" xyaxes="0.94 -0.34 0 0.2 0.55 0.81"/>'


class BasketballEnv(ArmTaskEnv):
    """Throw a ball from a cup into a basket.

    ## Description
    The 7-DOF arm (see :mod:`sb3_genrl.envs.arm`) holds a ball in a cup (no gripper): the ball leaves the cup when
    the arm slows down after accelerating it. The basket is placed at radius ``[1, 8] m`` and angle
    ``[-pi/2, pi/2]`` from the robot (paper section 6.1.1), its rim ``BASKET_HEIGHT`` above the floor. The ball
    bounces on the floor, so throws that bounce before reaching the basket are possible.

    ## Action Space
    ``Box(-max_joint_delta, max_joint_delta, (7,))``: the change of the 7 commanded joint positions (rad) per
    control step (0.04 s), clipped to the joint ranges (``info["joint_limit_clipped"]``).

    ## Observation Space
    ``Box(16,)``: basket (x, y) in metres, 7 joint positions (rad), 7 joint velocities (rad/s).

    ## Rewards
    0 until the end; then minus the smallest horizontal distance (m) between the ball and the basket centre over
    the moments the ball crosses the rim's height going down (each crossing located by linear interpolation
    between physics steps). A ball that never crosses that height going down gets ``worst_reward`` (-16 m,
    twice the largest basket radius), as does an unstable simulation (``info["unstable"] = True``).

    ## Starting State
    The arm at its home pose with the cup open upwards behind the robot, the ball resting in it. Only the basket
    position is random.

    ## Episode End
    After ``horizon = 78`` actions the arm holds its last command and the flight runs on for up to
    ``settle_steps`` control steps, or until the ball rests on the floor. ``info`` then holds ``reached`` (the
    ball's position at the best crossing, or its last position), ``crossings``, ``distance`` and ``reward``.

    ## Arguments
    ``max_joint_delta`` (0.5 rad), ``settle_steps`` (50 control steps = 2 s), ``render_mode`` (``"rgb_array"``),
    ``width``, ``height``.

    ## Version History
    * v0: initial version.
    """

    horizon = BASKETBALL_HORIZON
    worst_reward = -2 * BASKET_RADIUS_RANGE[1]
    goal_low = np.array([0.0, -BASKET_RADIUS_RANGE[1]])
    goal_high = np.array([BASKET_RADIUS_RANGE[1], BASKET_RADIUS_RANGE[1]])

    def __init__(self, *, settle_steps: int = 50, **kwargs: Any) -> None:
        self.settle_steps = int(settle_steps)
        super().__init__(settle_steps=settle_steps, **kwargs)

    def _in_region(self, goals: np.ndarray) -> np.ndarray:
        # The half-annulus, with the slack of a float32 round trip (goals passed as the float32 context pass).
        return in_goal_region(goals, tolerance=1e-5)

    def goal_region_text(self, low: np.ndarray, high: np.ndarray) -> str:
        return (
            f"radius in [{BASKET_RADIUS_RANGE[0]}, {BASKET_RADIUS_RANGE[1]}] m, angle in [{BASKET_ANGLE_RANGE[0]:.4f}, "
            f"{BASKET_ANGLE_RANGE[1]:.4f}] rad"
        )

    def _mjcf(self) -> str:
        return task_mjcf(name="basketball", tool=_TOOL, world=_WORLD, sensors=_SENSORS, camera=_CAMERA)

    def home_qpos(self) -> np.ndarray:
        # Upper arm and forearm tilted back, wrist bent so the flange points backwards and the cup opens upwards.
        return np.array([0.0, -0.5, 0.0, -0.7, 0.0, -0.3707963267948966, 0.0])

    def sample_goal(self, rng: np.random.Generator) -> np.ndarray:
        radius = rng.uniform(*BASKET_RADIUS_RANGE)
        angle = rng.uniform(*BASKET_ANGLE_RANGE)
        return np.array([radius * np.cos(angle), radius * np.sin(angle)])

    def _place_objects(self) -> None:
        mujoco.mj_kinematics(self.model, self.data)
        ball_adr = self.model.joint("ball").qposadr[0]
        self.data.qpos[ball_adr : ball_adr + 3] = self.data.site("cup_centre").xpos
        self.data.qpos[ball_adr + 3 : ball_adr + 7] = [1, 0, 0, 0]

    def _settled(self, row: np.ndarray) -> bool:
        return bool(row[3] < BALL_RADIUS + 0.01 and np.linalg.norm(row[4:7]) < 0.05)

    def hindsight(self, info: dict[str, Any]) -> tuple[np.ndarray, float] | None:
        """As the base task's, and ``None`` when the ball never came down through the rim's height (``reached`` is
        then where it ended, which no basket position rewards)."""
        return super().hindsight(info) if info.get("crossings", 0) > 0 else None

    def _outcome(self, rows: np.ndarray, goal: np.ndarray) -> tuple[float, dict[str, Any]]:
        points = crossing_points(rows)
        if len(points) == 0:
            last = rows[-1, 1:3].copy()
            return self.worst_reward, {"reached": last, "crossings": 0, "distance": float(np.linalg.norm(last - goal))}
        distances = np.linalg.norm(points - goal, axis=1)
        best = int(np.argmin(distances))
        distance = float(distances[best])
        return -distance, {"reached": points[best], "crossings": len(points), "distance": distance}


def crossing_points(rows: np.ndarray) -> np.ndarray:
    """Where the ball came down through the rim's height, ``(K, 2)`` (x, y) in metres: each crossing between
    physics steps ``i`` and ``i + 1`` located by linear interpolation.

    :param rows: sensor rows, one per physics step
    """
    position = rows[:, 1:4]
    height = position[:, 2] - BASKET_HEIGHT
    crossing = np.flatnonzero((height[:-1] >= 0) & (height[1:] < 0))
    fraction = height[crossing] / (height[crossing] - height[crossing + 1])
    return position[crossing, :2] + fraction[:, None] * (position[crossing + 1, :2] - position[crossing, :2])


class BasketballGoalEnv(GoalConditionedMixin, BasketballEnv):
    """``GenRL/BasketballGoal-v0``: :class:`BasketballEnv` with dict observations (see :mod:`sb3_genrl.envs.goal`).

    The terminal info also holds ``crossing_points`` ``(K, 2)``, every point where the ball came down through the
    rim's height, so the terminal reward for any goal is minus its distance to the nearest of them (``worst_reward``
    when there is none or the simulation was unstable): the plain task's reward for that goal.
    """

    def _outcome(self, rows: np.ndarray, goal: np.ndarray) -> tuple[float, dict[str, Any]]:
        reward, info = super()._outcome(rows, goal)
        info["crossing_points"] = crossing_points(rows)
        return reward, info

    def _terminal_reward(self, achieved: np.ndarray, desired: np.ndarray, info: dict[str, Any]) -> float:
        points = np.asarray(info.get("crossing_points", np.zeros((0, 2))), dtype=np.float64).reshape(-1, 2)
        if info.get("unstable", False) or len(points) == 0:
            return float(self.worst_reward)
        return max(-float(np.min(np.linalg.norm(points - desired, axis=1))), float(self.worst_reward))


def in_goal_region(points: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """Per point ``(x, y)``: whether it lies in the goal region, the half-annulus of :data:`BASKET_RADIUS_RANGE`
    and :data:`BASKET_ANGLE_RANGE` (widened by ``tolerance``, in metres and radians)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    radius = np.linalg.norm(points, axis=1)
    angle = np.arctan2(points[:, 1], points[:, 0])
    return (
        (radius >= BASKET_RADIUS_RANGE[0] - tolerance)
        & (radius <= BASKET_RADIUS_RANGE[1] + tolerance)
        & (angle >= BASKET_ANGLE_RANGE[0] - tolerance)
        & (angle <= BASKET_ANGLE_RANGE[1] + tolerance)
    )


def region_patch() -> Any:
    """The goal region's outline for the coverage plot."""
    from matplotlib.patches import Wedge

    return Wedge(
        (0, 0),
        BASKET_RADIUS_RANGE[1],
        np.degrees(BASKET_ANGLE_RANGE[0]),
        np.degrees(BASKET_ANGLE_RANGE[1]),
        width=BASKET_RADIUS_RANGE[1] - BASKET_RADIUS_RANGE[0],
        fill=False,
        color="k",
        label="goal region",
    )


# ----------------------------------------------------------------------------------------- the scripted expert
# Perturbation sizes per joint (rad moved by one bump at level 1), small next to the base motions' amplitudes so
# the demonstrations vary mainly along the task's factors.
BASKETBALL_PERTURBATION = np.array([0.06, 0.04, 0.06, 0.04, 0.06, 0.04, 0.06])
# One family of throws: the base turns by the yaw, then shoulder and elbow swing forward together over
# BASKETBALL_SWING_STEPS control steps starting at BASKETBALL_THROW_START, the shoulder by the throw's strength (rad)
# and the elbow by BASKETBALL_ELBOW_SHARE of it. The ball lands at the yaw's bearing (within a degree beyond 0.3 rad
# of yaw) and at a distance that grows smoothly and monotonically with the strength, whatever the yaw: 1.1 m at
# 0.26, 4.3 m at 0.46, 8.2 m at 0.70 (measured), up to about 9 m at 0.76. Every throw starts at the same step and
# lasts as long: throws with whole-step random timing or several families fall into clusters, which a 2-D generator
# lays out as separate patches of its latent space.
BASKETBALL_THROW_START = 30
BASKETBALL_SWING_STEPS = 4
BASKETBALL_ELBOW_SHARE = 0.4
BASKETBALL_STRENGTH = (0.23, 0.72)  # the demonstrations' strengths: they land 0.9-8.5 m away
BASKETBALL_YAW = np.pi / 2 + 0.15  # rad, either side


def throw_motion(
    *,
    yaw: float = 0.0,
    shoulder: float = 0.7,
    elbow: float = 0.3,
    wrist: float = 0.15,
    duration: int = 4,
    throw_start: int = 30,
) -> np.ndarray:
    """A throw with separate joint amplitudes: turn the base slowly by ``yaw``, then swing fast.

    :param yaw: base rotation (rad), positive throws to the robot's left (positive y); spread over 18 steps so the
        ball stays in the cup
    :param shoulder: shoulder pitch travel of the swing (rad)
    :param elbow: elbow travel (rad)
    :param wrist: wrist pitch travel (rad)
    :param duration: control steps of the swing
    :param throw_start: control step at which the swing starts
    :return: ``(78, 7)`` joint position deltas
    """
    trajectory = np.zeros((BASKETBALL_HORIZON, 7))
    trajectory[:, 0] = bump(BASKETBALL_HORIZON, 1, 18, yaw)
    for joint, total in zip((1, 3, 5), (shoulder, elbow, wrist), strict=True):
        trajectory[:, joint] = bump(BASKETBALL_HORIZON, throw_start, duration, total)
    return trajectory


def scripted_throw(*, strength: float = 0.5, yaw: float = 0.0) -> np.ndarray:
    """The expert's throw (see :data:`BASKETBALL_STRENGTH`): turn the base by ``yaw``, then swing shoulder and elbow.

    :param strength: shoulder travel of the swing (rad); 0.23-0.72 throws the ball 0.9-8.5 m, 0.5 about 5 m
    :param yaw: base rotation (rad), positive throws to the robot's left (positive y); the ball lands at this bearing
    :return: ``(78, 7)`` joint position deltas
    """
    return throw_motion(
        yaw=yaw,
        shoulder=strength,
        elbow=BASKETBALL_ELBOW_SHARE * strength,
        wrist=0.0,
        duration=BASKETBALL_SWING_STEPS,
        throw_start=BASKETBALL_THROW_START,
    )


def sample_throw(rng: np.random.Generator) -> np.ndarray:
    """The expert's base motion: :func:`scripted_throw` with a yaw uniform in ``+-BASKETBALL_YAW`` and a strength
    uniform in :data:`BASKETBALL_STRENGTH` (so the landing points spread about uniformly in radius and angle, as
    the baskets do).

    :param rng: the random generator
    :return: ``(78, 7)`` joint position deltas
    """
    yaw = rng.uniform(-BASKETBALL_YAW, BASKETBALL_YAW)
    return scripted_throw(strength=rng.uniform(*BASKETBALL_STRENGTH), yaw=yaw)


def is_valid(info: dict[str, Any]) -> bool:
    """A throw may be a demonstration when the ball comes down through the rim's height."""
    return info.get("crossings", 0) > 0


TASK = TaskSpec(
    name="basketball",
    env_id="GenRL/Basketball-v0",
    env_class=BasketballEnv,
    horizon=BASKETBALL_HORIZON,
    goal_low=BasketballEnv.goal_low,
    goal_high=BasketballEnv.goal_high,
    in_goal_region=in_goal_region,
    cell_size=0.25,
    sample_expert=sample_throw,
    perturbation_scales=BASKETBALL_PERTURBATION,
    is_valid=is_valid,
    region_patch=region_patch,
    figure_size=(6.0, 8.0),
    goal_env_id="GenRL/BasketballGoal-v0",
    goal_env_class=BasketballGoalEnv,
)
