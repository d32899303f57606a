"""The feedback baselines' envs, demonstrations and evaluation on held-out goals.

The feedback baselines act at every control step on the task's observation (goal, joint positions, joint
velocities) plus sb3-contrib's ``TimeFeatureWrapper`` feature, the remaining share of the episode ``1 - t / T``:
the tasks have a fixed horizon and the demonstrations start their hit or throw at a fixed control step, so without
it a policy cannot tell "wait" from "swing now" in the resting start pose (rl-zoo3 adds the same feature to its
fixed-horizon robotics tasks).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from sb3_contrib.common.wrappers import TimeFeatureWrapper
from sb3_genrl.envs import get_task


def make_feedback_env(task: str, *, time_feature: bool = True, **kwargs: Any) -> gym.Env:
    """The task's step env as the feedback baselines see it (with the time feature unless ``time_feature=False``)."""
    env = gym.make(get_task(task).env_id, **kwargs)
    return TimeFeatureWrapper(env) if time_feature else env


def add_time_feature(transitions: dict[str, np.ndarray], horizon: int) -> dict[str, np.ndarray]:
    """Demonstration transitions with the time feature appended to ``observations`` and ``next_observations``,
    as :class:`TimeFeatureWrapper` computes it (``1 - t / horizon`` after ``t`` steps).

    :param transitions: the format of :func:`sb3_genrl.data.load_transitions` (episodes of ``horizon`` steps)
    :param horizon: the task's episode length
    """
    n = len(transitions["observations"])
    if n % horizon or not np.array_equal(np.flatnonzero(transitions["dones"]), np.arange(horizon - 1, n, horizon)):
        raise ValueError(f"the transitions are not whole episodes of {horizon} steps")
    steps = np.tile(np.arange(horizon, dtype=np.float32), n // horizon)
    out = dict(transitions)
    for key, offset in (("observations", 0), ("next_observations", 1)):
        feature = (1 - (steps + offset) / horizon).astype(np.float32)
        out[key] = np.concatenate([np.asarray(transitions[key], dtype=np.float32), feature[:, None]], axis=1)
    return out


def held_out_goals(task: str, goals: int, seed: int) -> np.ndarray:
    """``goals`` goals drawn from the task's goal distribution with ``np.random.default_rng(seed)``, as
    :func:`sb3_genrl.run.evaluate_on_goals` draws them (the same seed gives the same goals)."""
    env = gym.make(get_task(task).env_id).unwrapped
    rng = np.random.default_rng(seed)
    return np.array([env.sample_goal(rng) for _ in range(goals)], dtype=np.float32)


def evaluate_feedback_policy(
    model: Any,
    task: str,
    *,
    goals: int | np.ndarray = 100,
    seed: int = 0,
    deterministic: bool = True,
    time_feature: bool = True,
    goal_conditioned: bool = False,
    allow_outside_region: bool = False,
) -> dict[str, Any]:
    """Play an SB3 feedback policy closed loop on held-out goals, all goals stepped together.

    :param model: an SB3 model (or anything with ``predict``) trained on :func:`make_feedback_env`'s observations, or
        on the goal-conditioned task's (``goal_conditioned``)
    :param task: ``hockey`` or ``basketball``
    :param goals: number of goals (see :func:`held_out_goals`), or the goals themselves, ``(G, 2)``
    :param seed: seed of the goals (when ``goals`` is a number), and of torch's sampling when ``deterministic=False``
    :param deterministic: the actor's mean (True) or samples from it (False)
    :param time_feature: whether the policy observes the time feature (the goal-conditioned task always has it)
    :param goal_conditioned: play the task's goal-conditioned variant (dict observations, e.g. SAC + HER's policy)
    :param allow_outside_region: accept goals outside the task's goal region (demonstrations' own goals)
    :return: ``goals`` (G, 2), ``rewards`` (G,), ``infos`` (the episodes' last infos), ``actions`` (G, T, 7)
    """
    goal_array = np.asarray(goals, dtype=np.float32) if np.ndim(goals) else held_out_goals(task, goals, seed)
    spec = get_task(task)
    if goal_conditioned and spec.goal_env_id is None:
        raise ValueError(f"{spec.name} has no goal-conditioned variant")
    envs = [
        gym.make(spec.goal_env_id) if goal_conditioned else make_feedback_env(task, time_feature=time_feature)
        for _ in goal_array
    ]
    options = {"allow_outside_region": True} if allow_outside_region else {}
    first = [env.reset(options={"goal": goal, **options})[0] for env, goal in zip(envs, goal_array, strict=True)]
    # One array per observation key (a dict observation) or one array, a row per goal.
    observations = {key: np.stack([obs[key] for obs in first]) for key in first[0]} if goal_conditioned else np.stack(first)
    horizon = envs[0].unwrapped.horizon
    actions = np.zeros((len(envs), horizon, 7), dtype=np.float32)
    rewards, infos = np.zeros(len(envs)), [{} for _ in envs]
    active = np.ones(len(envs), dtype=bool)
    th.manual_seed(seed)
    for t in range(horizon):
        batch, _ = model.predict(observations, deterministic=deterministic)
        actions[:, t] = batch
        for i in np.flatnonzero(active):
            obs, reward, terminated, truncated, info = envs[i].step(batch[i])
            if goal_conditioned:
                for key, value in obs.items():
                    observations[key][i] = value
            else:
                observations[i] = obs
            if terminated or truncated:
                rewards[i], infos[i], active[i] = reward, info, False
    for env in envs:
        env.close()
    return {"goals": goal_array, "rewards": rewards, "infos": infos, "actions": actions}


def open_loop_rewards(task: str, actions: np.ndarray, goals: np.ndarray, *, allow_outside_region: bool = False) -> np.ndarray:
    """Rewards of action sequences played open loop (the task's fast path), e.g. the actions a policy predicts
    along a demonstration's own states: what its per-step errors cost without compounding.

    :param allow_outside_region: accept goals outside the task's goal region (demonstrations' own goals)
    """
    env = gym.make(get_task(task).env_id).unwrapped
    rewards, _ = env.play_trajectories(
        np.clip(actions, -env.max_joint_delta, env.max_joint_delta), goals, allow_outside_region=allow_outside_region
    )
    env.close()
    return rewards
