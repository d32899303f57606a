"""The feedback baselines' SB3 models, set up as :mod:`sb3_genrl.baselines.hyperparameters` says.

Each model observes the observations normalised with the demonstrations' statistics
(:mod:`sb3_genrl.baselines.normalization`); the demonstrations enter as behaviour cloning (PPO), as the replay
buffer's first transitions (SAC prefilled) or as HER episodes (SAC + HER).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.baselines.bc import behaviour_cloning
from sb3_genrl.baselines.her import add_goal_demonstrations, goal_statistics
from sb3_genrl.baselines.hyperparameters import baseline_settings, zoo_hyperparams
from sb3_genrl.baselines.normalization import NormalizedCombined, NormalizedFlatten, observation_statistics
from sb3_genrl.baselines.prefill import prefill_replay_buffer
from stable_baselines3 import PPO, SAC
from stable_baselines3.her import HerReplayBuffer


def normalized_policy(policy_kwargs: dict[str, Any], observations: np.ndarray) -> dict[str, Any]:
    """``policy_kwargs`` with the features extractor that normalises with ``observations``' statistics."""
    return policy_kwargs | {
        "features_extractor_class": NormalizedFlatten,
        "features_extractor_kwargs": observation_statistics(observations),
    }


def ppo_with_behaviour_cloning(
    env: gym.Env,
    transitions: dict[str, np.ndarray],
    *,
    task: str,
    seed: int,
    bc_kwargs: dict[str, Any] | None = None,
    settings: dict[str, Any] | None = None,
    **common: Any,
) -> tuple[PPO, dict[str, Any]]:
    """PPO (rl-zoo3's HalfCheetah-v4 settings, ``hyperparams/ppo.yml``) whose actor is cloned from the demonstrations.

    :param env: the feedback env (with the time feature)
    :param task: the task it plays (its entry in ``ppo.yml``)
    :param transitions: demonstrations as the env observes them
    :param seed: seed of the model, the held-out split and the minibatches
    :param bc_kwargs: passed to :func:`~sb3_genrl.baselines.bc.behaviour_cloning` (``holdout``, ``max_epochs``, ...)
    :param settings: changes to the zoo's settings (``PPO`` arguments, see
        :func:`~sb3_genrl.baselines.hyperparameters.check_algorithm_kwargs`)
    :param common: passed to ``PPO`` (``device``, ``verbose``, ``tensorboard_log``)
    :return: the model and behaviour cloning's record
    """
    zoo, policy_kwargs = baseline_settings("ppo", task)
    model = PPO(
        zoo_hyperparams("ppo", task)["policy"],
        env,
        seed=seed,
        **(zoo | (settings or {})),
        **common,
        policy_kwargs=normalized_policy(policy_kwargs, transitions["observations"]),
    )
    record = behaviour_cloning(
        model.policy, transitions["observations"], transitions["actions"], transitions["dones"], seed=seed, **(bc_kwargs or {})
    )
    return model, record


def sac_with_demonstrations(
    env: gym.Env,
    transitions: dict[str, np.ndarray],
    *,
    task: str,
    steps: int,
    prefill: bool,
    seed: int,
    settings: dict[str, Any] | None = None,
    **common: Any,
) -> SAC:
    """SAC (rl-zoo3's MuJoCo defaults, ``hyperparams/sac.yml``), its buffer prefilled with the demonstrations or not
    (then with the zoo's random warm-up).

    :param env: the feedback env (with the time feature)
    :param task: the task it plays (its entry in ``sac.yml``)
    :param transitions: demonstrations as the env observes them (their statistics normalise the observations)
    :param steps: environment steps of the run (the buffer keeps them all)
    :param prefill: write the demonstrations into the buffer and learn from the first step
    :param seed: seed of the model
    :param settings: changes to the zoo's settings (``SAC`` arguments)
    :param common: passed to ``SAC``
    """
    method = "sac" if prefill else "sac-no-prefill"
    zoo, policy_kwargs = baseline_settings(method, task)
    n_demos = len(transitions["observations"]) if prefill else 0
    model = SAC(
        zoo_hyperparams(method, task)["policy"],
        env,
        buffer_size=n_demos + steps,
        seed=seed,
        policy_kwargs=normalized_policy(policy_kwargs, transitions["observations"]),
        **(zoo | (settings or {})),
        **common,
    )
    if prefill:
        prefill_replay_buffer(model, transitions)
    return model


def sac_her_with_demonstrations(
    env: gym.Env,
    episodes: dict[str, Any],
    *,
    task: str,
    steps: int,
    seed: int,
    settings: dict[str, Any] | None = None,
    **common: Any,
) -> SAC:
    """SAC with a ``HerReplayBuffer`` (rl-zoo3's FetchReach-v1 settings, ``final`` goals, ``hyperparams/sac.yml``)
    holding the demonstrations.

    :param env: the task's goal-conditioned env
    :param task: the task (the entry of its goal-conditioned variant in ``sac.yml``)
    :param episodes: :func:`~sb3_genrl.baselines.her.goal_episodes` of the demonstrations
    :param steps: environment steps of the run
    :param seed: seed of the model
    :param settings: changes to the zoo's settings (``SAC`` arguments)
    :param common: passed to ``SAC``
    """
    n_demos = int(np.prod(episodes["rewards"].shape))
    zoo, policy_kwargs = baseline_settings("sac-her", task)
    entry = zoo_hyperparams("sac-her", task)
    if entry.get("replay_buffer_class") != "HerReplayBuffer":
        raise ValueError(f"sac-her needs replay_buffer_class HerReplayBuffer, got {entry.get('replay_buffer_class')!r}")
    policy_kwargs = policy_kwargs | {
        "features_extractor_class": NormalizedCombined,
        "features_extractor_kwargs": {"statistics": goal_statistics(episodes)},
    }
    model = SAC(
        entry["policy"],
        env,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs=entry["replay_buffer_kwargs"],
        policy_kwargs=policy_kwargs,
        buffer_size=n_demos + steps,
        seed=seed,
        **(zoo | (settings or {})),
        **common,
    )
    add_goal_demonstrations(model, episodes)
    return model
