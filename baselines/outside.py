"""SAC with demonstrations on a task from outside the package (``genrl baseline sac --task metaworld/push-v3 --demos D``).

A task without a :class:`~sb3_genrl.envs.spec.TaskSpec` has no entry in the baselines' rl-zoo3 files, no time feature
and no goals to score on: SAC learns with SB3's defaults (``learning_starts`` 0, the demonstrations' statistics
normalising the observations, the demonstrations in its buffer for ``sac``), in the env the task's demonstrations were
recorded in (:attr:`~sb3_genrl.envs.external.Task.recording_kwargs`: Meta-World's training env, which runs on after a
success, as Meta-World trains step-based learners; else the env GenRL plays), for episodes of the demonstrations'
horizon, and its policy is scored closed loop on the held-out seeded resets that GenRL's are scored on
(:func:`evaluate_step_policy`).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.baselines.models import normalized_policy
from sb3_genrl.baselines.prefill import prefill_replay_buffer
from sb3_genrl.envs.external import HELD_OUT_RESETS, HELD_OUT_SEED, held_out_result, resolve_task, task_env_and_horizon
from stable_baselines3 import SAC

from sb3_genrl.checks import check_positive_int
from sb3_genrl.data import dataset_info, load_transitions

OUTSIDE_BASELINES = ("sac", "sac-no-prefill")  # the baselines a task from outside the package takes
OUTSIDE_SETTINGS = {"learning_starts": 0}  # SB3's SAC defaults but this: it learns from the first step


def outside_horizon(demos: Any) -> int:
    """The control steps of an episode: those the demonstrations were recorded with (a recorded dataset's ``horizon``).

    :raises ValueError: for demonstrations that are not a recorded dataset's folder
    """
    if not isinstance(demos, str | os.PathLike) or not Path(demos).is_dir():
        raise ValueError(
            "a task from outside the package learns from a dataset folder of recorded demonstrations (genrl demos), "
            f"whose horizon its episodes take; got {demos!r}"
        )
    return int(dataset_info(demos)["horizon"])


def outside_env(task: str, horizon: int) -> gym.Env:
    """The env SAC learns in: the one the task's demonstrations are recorded in, ``horizon`` steps an episode."""
    return task_env_and_horizon(task, horizon, "is_success", recording=True)[0]


def outside_transitions(task: str, demos: Any) -> dict[str, np.ndarray]:
    """The demonstrations' transitions, checked to be the task's. Where the task records in an env that runs on after a
    success (Meta-World's training env), the last step of a demonstration is no terminal state there."""
    resolved = resolve_task(task)
    recorded = dataset_info(demos).get("env_id")
    if recorded is not None and recorded != resolved.env_id:
        raise ValueError(f"the demonstrations {str(demos)!r} are of {recorded}, not of {task} ({resolved.env_id})")
    transitions = load_transitions(demos)
    if resolved.recording_kwargs:
        transitions["dones"] = np.zeros_like(transitions["dones"])
    return transitions


def outside_sac(algorithm: str, env: gym.Env, transitions: dict[str, np.ndarray], steps: int, seed: int, **common: Any) -> SAC:
    """SB3's SAC with :data:`OUTSIDE_SETTINGS`, observations normalised with the demonstrations' statistics, its buffer
    holding the run's steps and (``sac``) the demonstrations."""
    prefill = algorithm == "sac"
    model = SAC(
        "MlpPolicy",
        env,
        buffer_size=(len(transitions["observations"]) if prefill else 0) + steps,
        seed=seed,
        policy_kwargs=normalized_policy({}, transitions["observations"]),
        **OUTSIDE_SETTINGS,
        **common,
    )
    if prefill:
        prefill_replay_buffer(model, transitions)
    return model


def evaluate_step_policy(
    policy: Callable[[Any], np.ndarray], task: str, *, horizon: int, resets: int = HELD_OUT_RESETS
) -> dict[str, Any]:
    """A step-based policy's success on the held-out seeded resets GenRL's policies are scored on
    (:func:`~sb3_genrl.envs.external.evaluate_success`): from each reset seed ``HELD_OUT_SEED + i``, the policy plays
    closed loop (its actions clipped to the action space) until the episode ends (in the env GenRL plays: Meta-World's
    at its first success) or ``horizon`` steps; a success is ``info["is_success"]`` at the last step.

    :param policy: observation -> action (e.g. ``lambda o: model.predict(o, deterministic=True)[0]``)
    :param task: a task name (:func:`~sb3_genrl.envs.external.resolve_task`)
    :param horizon: control steps of an episode
    :param resets: held-out resets to play
    :return: ``success_rate``, ``successes`` (one 0/1 per reset), ``resets`` and ``seeds`` (first and last + 1)
    """
    check_positive_int(resets, "resets")
    env, steps = task_env_and_horizon(task, horizon, "is_success")
    low, high = env.action_space.low, env.action_space.high
    successes = []
    for i in range(resets):
        observation, _ = env.reset(seed=HELD_OUT_SEED + i)
        info: dict[str, Any] = {}
        for _ in range(steps):
            action = np.clip(np.asarray(policy(observation), dtype=env.action_space.dtype), low, high)
            observation, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        successes.append(float(bool(info.get("is_success", False))))
    env.close()
    return held_out_result(successes)
