"""Demonstrations for SAC with hindsight experience replay on the goal-conditioned tasks (paper section 6.1.5).

The demonstration datasets store the plain tasks' observations (goal, joints), not the object's path, which the
goal-conditioned tasks observe as ``achieved_goal``. :func:`goal_episodes` replays each demonstration open loop
through the goal-conditioned task's fast path to recover it (and basketball's crossing points), checks that the
replay reaches the stored reward, and :func:`add_goal_demonstrations` writes the episodes into a
``HerReplayBuffer`` through its ``add``, transition by transition, as if SAC had collected them, so HER relabels
them like its own episodes.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.baselines.normalization import observation_statistics
from sb3_genrl.envs import get_task
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.her import HerReplayBuffer

REPLAY_TOLERANCE = 1e-6  # m: a replayed demonstration must reach its stored terminal reward this closely


def goal_episodes(task: str, transitions: dict[str, np.ndarray]) -> dict[str, Any]:
    """Demonstration transitions as goal-conditioned episodes.

    :param task: ``hockey`` or ``basketball``
    :param transitions: whole episodes in the format of :func:`sb3_genrl.data.load_transitions`
    :return: ``observation`` (N, T + 1, 15), ``achieved_goal`` and ``desired_goal`` (N, T + 1, 2) float64,
        ``actions`` (N, T, 7), ``rewards`` (N, T) and the terminal ``infos`` (N dicts)
    """
    spec = get_task(task)
    if spec.goal_env_id is None:
        raise ValueError(f"task {spec.name!r} has no goal-conditioned variant (TaskSpec.goal_env_id)")
    env = gym.make(spec.goal_env_id).unwrapped
    horizon = env.horizon
    n = len(transitions["observations"]) // horizon
    if n == 0 or not np.array_equal(np.flatnonzero(transitions["dones"]), np.arange(horizon - 1, n * horizon, horizon)):
        raise ValueError(f"the transitions are not whole {task} episodes of {horizon} steps")
    states = np.asarray(transitions["observations"], dtype=np.float32).reshape(n, horizon, -1)
    last = np.asarray(transitions["next_observations"], dtype=np.float32).reshape(n, horizon, -1)[:, -1:]
    states = np.concatenate([states, last], axis=1)
    actions = np.asarray(transitions["actions"], dtype=np.float32).reshape(n, horizon, -1)
    goals = states[:, 0, :2].astype(np.float64)
    paths, infos = env.object_paths(actions, goals)
    rewards = np.zeros((n, horizon))
    rewards[:, -1] = env.compute_reward(paths[:, -1], goals, infos)
    stored = np.asarray(transitions["rewards"], dtype=np.float64).reshape(n, horizon)[:, -1]
    worst = int(np.argmax(np.abs(rewards[:, -1] - stored)))
    if abs(rewards[worst, -1] - stored[worst]) > REPLAY_TOLERANCE:
        raise ValueError(
            f"demonstration {worst} replays to reward {rewards[worst, -1]:.6g}, not its stored "
            f"{stored[worst]:.6g}: the dataset was made with another version of the {task} task"
        )
    time_left = (1 - np.arange(horizon + 1) / horizon).astype(np.float32)
    observation = np.concatenate([states[:, :, 2:], np.broadcast_to(time_left[None, :, None], (n, horizon + 1, 1))], axis=2)
    env.close()
    return {
        "observation": observation,
        "achieved_goal": paths,
        "desired_goal": np.repeat(goals[:, None], horizon + 1, 1),
        "actions": actions,
        "rewards": rewards,
        "infos": infos,
    }


def goal_statistics(episodes: dict[str, Any]) -> dict[str, dict[str, np.ndarray]]:
    """Normalisation statistics of each observation key over the demonstration episodes' states."""
    return {
        key: observation_statistics(episodes[key].reshape(-1, episodes[key].shape[-1]))
        for key in ("observation", "achieved_goal", "desired_goal")
    }


def add_goal_demonstrations(model: OffPolicyAlgorithm, episodes: dict[str, Any]) -> int:
    """Write goal-conditioned demonstration episodes into ``model``'s ``HerReplayBuffer`` (one env).

    :param model: SAC (or another off-policy algorithm) with a ``HerReplayBuffer`` made with ``copy_info_dict=True``
    :param episodes: :func:`goal_episodes`'s output
    :return: the number of transitions written
    """
    buffer = model.replay_buffer
    if not isinstance(buffer, HerReplayBuffer) or buffer.n_envs != 1:
        raise ValueError("add_goal_demonstrations needs a model with a HerReplayBuffer over exactly one env")
    if not buffer.copy_info_dict:
        raise ValueError("the HerReplayBuffer must keep the step infos (copy_info_dict=True) for compute_reward")
    n, horizon = episodes["rewards"].shape
    if n * horizon > buffer.buffer_size - buffer.size():
        raise ValueError(
            f"{n * horizon} demonstration transitions do not fit the replay buffer's free "
            f"{buffer.buffer_size - buffer.size()} places"
        )
    keys = ("observation", "achieved_goal", "desired_goal")
    scaled = model.policy.scale_action(episodes["actions"])  # SB3 stores squashed algorithms' actions in [-1, 1]
    for i in range(n):
        for t in range(horizon):
            terminal = t == horizon - 1
            buffer.add(
                {key: episodes[key][i, t][None] for key in keys},
                {key: episodes[key][i, t + 1][None] for key in keys},
                scaled[i, t][None],
                np.array([episodes["rewards"][i, t]]),
                np.array([terminal]),
                [episodes["infos"][i] if terminal else {"terminal": False}],
            )
    return n * horizon


def fetch_goal_episodes(task: str, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """A Fetch task's demonstrations (:func:`sb3_genrl.data.load_arrays` of its dataset) as goal-conditioned episodes
    for :func:`add_goal_demonstrations`: the env's observation at every step, its achieved goal read from it as
    Gymnasium-Robotics' ``_get_obs`` forms it (the gripper's position for Reach, the object's otherwise), the
    demonstration's aim as desired goal, and the rewards by the env's own ``compute_reward``.

    :param task: a Fetch task
    :param arrays: the dataset's ``observations`` (N, 51, 3 + D: the reached goal, then the observation), ``actions``
        (N, 50, 4) and ``sampled_goals`` (N, 3), the aims
    """
    spec = get_task(task)
    env = spec.env_class()  # Gymnasium-Robotics' env, its MuJoCo fix applied (sb3_genrl.envs.fetch_mujoco)
    observation = np.asarray(arrays["observations"][:, :, 3:], dtype=np.float64)
    if observation.shape[-1] != env.observation_space["observation"].shape[0]:
        raise ValueError(
            f"the demonstrations' observations have {observation.shape[-1]} numbers, {spec.env_id}'s "
            f"{env.observation_space['observation'].shape[0]}: not this task's dataset"
        )
    achieved = observation[:, :, 3:6] if env.has_object else observation[:, :, 0:3]
    n, steps = arrays["actions"].shape[:2]
    desired = np.repeat(np.asarray(arrays["sampled_goals"], dtype=np.float64)[:, None], steps + 1, axis=1)
    rewards = env.compute_reward(achieved[:, 1:].reshape(-1, 3), desired[:, 1:].reshape(-1, 3), None).reshape(n, steps)
    env.close()
    return {
        "observation": observation,
        "achieved_goal": achieved,
        "desired_goal": desired,
        "actions": np.asarray(arrays["actions"], dtype=np.float32),
        "rewards": rewards,
        "infos": [{"is_success": float(reward == 0.0)} for reward in rewards[:, -1]],
    }
