"""Fill an off-policy algorithm's replay buffer with demonstration transitions before learning (paper 6.1.5)."""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

TRANSITION_KEYS = ("observations", "actions", "rewards", "next_observations", "dones")


def prefill_replay_buffer(model: OffPolicyAlgorithm, transitions: dict[str, np.ndarray]) -> int:
    """Write demonstration transitions into ``model.replay_buffer`` (one env), as if they had been collected.

    :param model: an SB3 off-policy algorithm (SAC, TD3, ...) with a plain ``ReplayBuffer`` and one env
    :param transitions: arrays ``observations`` (N, obs), ``actions`` (N, act), ``rewards`` (N,),
        ``next_observations`` (N, obs), ``dones`` (N,) - the format of :func:`sb3_genrl.data.load_transitions`
    :return: the number of transitions written
    """
    missing = [key for key in TRANSITION_KEYS if key not in transitions]
    if missing:
        raise ValueError(f"transitions lack {missing}; expected keys {TRANSITION_KEYS}")
    buffer = model.replay_buffer
    if buffer is None or buffer.n_envs != 1:
        raise ValueError("prefill_replay_buffer needs a model with a replay buffer over exactly one env")
    n = len(transitions["observations"])
    if any(len(transitions[key]) != n for key in TRANSITION_KEYS):
        raise ValueError(f"transition arrays differ in length: { {key: len(transitions[key]) for key in TRANSITION_KEYS} }")
    if n > buffer.buffer_size:
        raise ValueError(f"{n} demonstration transitions do not fit a replay buffer of size {buffer.buffer_size}")
    actions = np.asarray(transitions["actions"], dtype=np.float32)
    low, high = model.action_space.low, model.action_space.high
    if np.any(actions < low) or np.any(actions > high):
        raise ValueError("demonstration actions lie outside the env's action space")
    buffer.observations[:n, 0] = transitions["observations"]
    buffer.actions[:n, 0] = model.policy.scale_action(actions)  # SB3 stores squashed algorithms' actions in [-1, 1]
    buffer.rewards[:n, 0] = transitions["rewards"]
    buffer.next_observations[:n, 0] = transitions["next_observations"]
    buffer.dones[:n, 0] = transitions["dones"]
    if hasattr(buffer, "timeouts"):
        buffer.timeouts[:n, 0] = 0.0
    buffer.pos = n % buffer.buffer_size
    buffer.full = n == buffer.buffer_size
    return n
