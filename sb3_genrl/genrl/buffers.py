"""GenRL's rollout buffers: SB3's, refusing a non-finite reward where it enters GenRL.

Every reward of a rollout reaches the algorithm through the rollout buffer's ``add``, whatever wrappers or VecEnv
wrappers lie around the latent-action env (:class:`~sb3_genrl.LatentActionWrapper` refuses the task's own non-finite
rewards; a reward transform above it may still make one). One NaN in a batch makes the normalised advantages NaN and
the E-step's step 0 at every iteration: the run would go on to its end without learning anything.
"""

from __future__ import annotations

import numpy as np
import torch as th
from stable_baselines3.common.buffers import DictRolloutBuffer, RolloutBuffer


def check_finite_rewards(rewards: np.ndarray, actions: np.ndarray) -> None:
    """Refuse a step's rewards (one per env) when one is not a finite number, naming it, its env and its action."""
    rewards = np.asarray(rewards)
    if np.all(np.isfinite(rewards)):
        return
    index = int(np.flatnonzero(~np.isfinite(rewards.ravel()))[0])
    action = np.asarray(actions).reshape(rewards.size, -1)[index]
    raise ValueError(
        f"the env returned the non-finite reward {float(rewards.ravel()[index])!r} (env {index} of {rewards.size}) for the "
        f"latent action {action.tolist()}: a reward must be a finite number; LatentActionWrapper refuses the task's "
        "own, so look at the wrappers and VecEnv wrappers around it"
    )


class FiniteRewardRolloutBuffer(RolloutBuffer):
    """SB3's :class:`~stable_baselines3.common.buffers.RolloutBuffer` that refuses a non-finite reward (see the module
    doc)."""

    def add(
        self,
        obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        episode_start: np.ndarray,
        value: th.Tensor,
        log_prob: th.Tensor,
    ) -> None:
        check_finite_rewards(reward, action)
        super().add(obs, action, reward, episode_start, value, log_prob)


class FiniteRewardDictRolloutBuffer(DictRolloutBuffer):
    """SB3's :class:`~stable_baselines3.common.buffers.DictRolloutBuffer` (a ``Dict`` context) that refuses a
    non-finite reward (see the module doc)."""

    def add(  # type: ignore[override]
        self,
        obs: dict[str, np.ndarray],
        action: np.ndarray,
        reward: np.ndarray,
        episode_start: np.ndarray,
        value: th.Tensor,
        log_prob: th.Tensor,
    ) -> None:
        check_finite_rewards(reward, action)
        super().add(obs, action, reward, episode_start, value, log_prob)
