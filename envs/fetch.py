"""Gymnasium-Robotics' Fetch tasks (``FetchReach-v4``, ``FetchPush-v4``, ``FetchSlide-v4``, ``FetchPickAndPlace-v4``)
as tasks of the package: their scripted experts, perturbations, validity check and registry entries.

The envs are Gymnasium-Robotics' own, unmodified (the optional extra ``robotics``; see
:mod:`sb3_genrl.envs.fetch_mujoco` for the one compatibility fix they need under MuJoCo 4.0). They are goal-conditioned
envs, so :class:`~sb3_genrl.LatentActionWrapper` takes its context (the goal and the reset observation: where the
gripper and the object start) and its hindsight relabelling (the object's or gripper's last position as goal, the
reward by ``compute_reward``) from their API, and GenRL scores an episode by the sparse reward of its last step (0 on
the goal, else -1) and ``info["is_success"]``.

**The scripted expert.** A Fetch action is a Cartesian displacement of the gripper (``dx, dy, dz`` in units of 5 cm,
moved by a mocap weld) and a gripper command, for 50 control steps. GenRL's episodes are open-loop trajectories, so the
expert is open-loop too: a function of the reset observation and an aim point, through a few straight moves between
waypoints (above the object, down to it, through it to the aim; for PickAndPlace a grasp and a carry; for Slide a
strike whose speed is read off a measured distance curve). The weld moves the gripper about :data:`GRIPPER_GAIN` of the
commanded displacement per step (measured), which the moves divide by. The demonstrations are its trajectories for
random reset states and aims drawn over the goal region, with smooth random bumps added to the commands, kept when
the object ends within the task's 5 cm of the aim and has not left the table: every demonstration is labelled with the
goal it reached. The generator thus learns a family of trajectories that varies with the object's start and the goal
(up to 5 numbers), and GenRL's policy maps the reset observation to the latent action.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from sb3_genrl.envs.fetch_mujoco import robotics_env_class

FETCH_HORIZON = 50  # Gymnasium-Robotics' max_episode_steps of every Fetch task
FETCH_ACTION_DIM = 4  # dx, dy, dz, gripper
STEP_METRES = 0.05  # Gymnasium-Robotics' pos_ctrl scale: metres of mocap displacement per unit of action
GRIPPER_GAIN = 0.64  # share of the commanded displacement the gripper moves per step (measured, 0.58-0.66 on every axis)
SUCCESS_DISTANCE = 0.05  # Gymnasium-Robotics' distance_threshold of every Fetch task (m)
# The goal regions' (x, y) boxes: the initial gripper position plus Gymnasium-Robotics' target_offset +- target_range
# (Reach, PickAndPlace: gripper at (1.342, 0.749), range 0.15; Push: (1.363, 0.749), 0.15; Slide: (1.013, 0.749)
# + (0.4, 0), 0.3).
GOAL_BOXES = {
    "Reach": ((1.19, 0.60), (1.49, 0.90)),
    "Push": ((1.21, 0.60), (1.51, 0.90)),
    "PickAndPlace": ((1.19, 0.60), (1.49, 0.90)),
    "Slide": ((1.11, 0.45), (1.71, 1.05)),
}
# The demonstrations' aims are drawn over the goal region widened by a margin on every side (m; Reach's height range
# too), so that a goal at the region's edge lies inside the demonstrations rather than at their edge, where a generator
# reproduces them least well. Reach's margin is the success distance (measured: docs/guide/tasks.md, the aims' margin).
AIM_MARGIN = 0.02
PERTURBATION = np.array([0.05, 0.05, 0.03, 0.0])  # m travelled by one bump per axis at level 1 (gripper untouched)
# Slide: the puck's travel (m) after a strike of each speed (units of action), measured on random reset states
SLIDE_DISTANCE_TO_SPEED = (
    np.array([0.0, 0.02, 0.068, 0.123, 0.19, 0.26, 0.437, 0.68]),
    np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0]),
)


def waypoint_actions(start: np.ndarray, moves: list[tuple[np.ndarray | None, float, int]]) -> np.ndarray:
    """The ``(50, 4)`` actions of straight gripper moves: each ``(target xyz or None to stay, gripper, steps)``.

    :param start: the gripper's start (m)
    :param moves: the moves, in order; the last gripper command is held after them
    :return: actions in ``[-1, 1]``
    """
    actions = np.zeros((FETCH_HORIZON, FETCH_ACTION_DIM))
    position, t, gripper = np.asarray(start, dtype=np.float64), 0, 0.0
    for target, gripper, steps in moves:
        target = position if target is None else np.asarray(target, dtype=np.float64)
        n = min(steps, FETCH_HORIZON - t)
        actions[t : t + n, :3] = (target - position) / steps / (STEP_METRES * GRIPPER_GAIN)
        actions[t : t + n, 3] = gripper
        t, position = t + n, target
    actions[t:, 3] = gripper
    return np.clip(actions, -1.0, 1.0)


def _approach(observation: np.ndarray, aim: np.ndarray, back: float, lift: float) -> tuple[np.ndarray, ...]:
    """The unit push direction (x, y) from the object to the aim, and the point ``back`` behind the object, at its
    height, from which to push, and the move above it at ``lift``."""
    grip, obj = observation[:3], observation[3:6]
    direction = aim[:2] - obj[:2]
    direction = direction / max(float(np.linalg.norm(direction)), 1e-6)
    behind = np.r_[obj[:2] - back * direction, obj[2] - 0.005]
    return direction, behind, [(grip + [0.0, 0.0, lift], 0.0, 5), (behind + [0.0, 0.0, lift], 0.0, 8), (behind, 0.0, 5)]


def reach_expert(observation: np.ndarray, aim: np.ndarray) -> np.ndarray:
    """Reach: move the gripper to ``aim`` in 15 steps and hold."""
    return waypoint_actions(observation[:3], [(aim, 0.0, 15)])


def push_expert(observation: np.ndarray, aim: np.ndarray) -> np.ndarray:
    """Push: lift, go behind the block (away from ``aim``), lower, push it through to ``aim`` in 25 steps."""
    direction, _, moves = _approach(observation, aim, back=0.07, lift=0.12)
    end = np.r_[aim[:2] - 0.045 * direction, observation[5] - 0.005]  # the gripper's centre 4.5 cm behind the block's
    return waypoint_actions(observation[:3], [*moves, (end, 0.0, 25)])


def slide_expert(observation: np.ndarray, aim: np.ndarray) -> np.ndarray:
    """Slide: lift, go behind the puck, lower, then strike it towards ``aim`` for 4 steps at the speed that the
    measured distance curve gives for the distance, and stop."""
    direction, _, moves = _approach(observation, aim, back=0.06, lift=0.1)
    actions = waypoint_actions(observation[:3], [*moves, (None, 0.0, 2)])
    speed = np.interp(np.linalg.norm(aim[:2] - observation[3:5]), *SLIDE_DISTANCE_TO_SPEED)
    actions[20:24, :2] = direction * speed
    return actions


def pick_and_place_expert(observation: np.ndarray, aim: np.ndarray) -> np.ndarray:
    """PickAndPlace: open and go above the block, lower, close, lift, carry it to ``aim`` and hold it there."""
    grip, obj = observation[:3], observation[3:6]
    grasp = obj + [0.0, 0.0, -0.005]
    carry = np.r_[aim[:2], max(aim[2], obj[2])]
    return waypoint_actions(
        grip,
        [
            (obj + [0.0, 0.0, 0.08], 1.0, 8),
            (grasp, 1.0, 6),
            (None, -1.0, 5),
            (grasp + [0.0, 0.0, 0.08], -1.0, 6),
            (carry, -1.0, 15),
        ],
    )


@dataclass(frozen=True)
class FetchFamily:
    """What differs between the Fetch tasks: the id, the expert, where the aims lie.

    :param name: ``Reach``, ``Push``, ``Slide`` or ``PickAndPlace``
    :param expert: ``(reset observation, aim) -> (50, 4)`` actions
    :param aim_height: ``(rng, env, margin) -> z`` of an aim (m), over its task's heights widened by ``margin`` where
        the task's goals vary in height over a range (Reach)
    :param aim_margin: how far the aims' region reaches beyond the goal region on every side (m)
    """

    name: str
    expert: Callable[[np.ndarray, np.ndarray], np.ndarray]
    aim_height: Callable[[np.random.Generator, Any, float], float]
    aim_margin: float = AIM_MARGIN

    @property
    def env_id(self) -> str:
        return f"Fetch{self.name}-v4"

    def sample_aim(self, rng: np.random.Generator, env: Any) -> np.ndarray:
        """An aim uniform over the goal region widened by ``aim_margin``, its height by the task."""
        low, high = (np.asarray(corner) for corner in GOAL_BOXES[self.name])
        xy = rng.uniform(low - self.aim_margin, high + self.aim_margin)
        return np.r_[xy, self.aim_height(rng, env, self.aim_margin)]


def _on_table(rng: np.random.Generator, env: Any, margin: float) -> float:
    return float(env.height_offset)


def _reach_height(rng: np.random.Generator, env: Any, margin: float) -> float:  # the env's goals: start +- 0.15
    return float(env.initial_gripper_xpos[2] + rng.uniform(-0.15 - margin, 0.15 + margin))


def _table_or_air(rng: np.random.Generator, env: Any, margin: float) -> float:  # as Gymnasium-Robotics samples them
    return float(env.height_offset + (rng.uniform(0.0, 0.45) if rng.uniform() < 0.5 else 0.0))


FAMILIES = {
    family.name: family
    for family in (
        FetchFamily("Reach", reach_expert, _reach_height, aim_margin=SUCCESS_DISTANCE),
        FetchFamily("Push", push_expert, _on_table),
        FetchFamily("Slide", slide_expert, _on_table),
        FetchFamily("PickAndPlace", pick_and_place_expert, _table_or_air),
    )
}
FETCH_IDS = tuple(family.env_id for family in FAMILIES.values())


def _make(name: str, **kwargs: Any) -> Any:
    return robotics_env_class(FAMILIES[name].env_id, FETCH_IDS)(**kwargs)


def make_fetch_reach(**kwargs: Any) -> Any:
    """Gymnasium-Robotics' ``FetchReach-v4`` env (``MujocoFetchReachEnv``), made with ``kwargs``."""
    return _make("Reach", **kwargs)


def make_fetch_push(**kwargs: Any) -> Any:
    """Gymnasium-Robotics' ``FetchPush-v4`` env (``MujocoFetchPushEnv``), made with ``kwargs``."""
    return _make("Push", **kwargs)


def make_fetch_slide(**kwargs: Any) -> Any:
    """Gymnasium-Robotics' ``FetchSlide-v4`` env (``MujocoFetchSlideEnv``), made with ``kwargs``."""
    return _make("Slide", **kwargs)


def make_fetch_pick_and_place(**kwargs: Any) -> Any:
    """Gymnasium-Robotics' ``FetchPickAndPlace-v4`` env (``MujocoFetchPickAndPlaceEnv``), made with ``kwargs``."""
    return _make("PickAndPlace", **kwargs)


def is_valid(info: dict[str, Any]) -> bool:
    """A played trajectory may be a demonstration when what it moves ended within 5 cm of its aim and the object (if
    any) is still on the table (``info`` from :func:`sb3_genrl.envs.demonstrations.fetch.play_expert`)."""
    return bool(info["aim_distance"] < SUCCESS_DISTANCE and info.get("on_table", True))
