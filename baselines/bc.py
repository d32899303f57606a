"""Behaviour cloning of a PPO actor on demonstration state-action pairs (paper section 6.1.5).

The loss is the negative log-likelihood of the demonstrated actions under the actor's diagonal Gaussian, so the
mean and the (state-independent) standard deviation are both fitted to the demonstrations; PPO then starts
exploring with the spread the demonstrations showed. ``loss="mse"`` fits only the mean.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy


def behaviour_cloning(
    policy: ActorCriticPolicy,
    observations: np.ndarray,
    actions: np.ndarray,
    *,
    epochs: int = 5,
    batch_size: int = 4096,
    learning_rate: float = 1e-3,
    loss: Literal["nll", "mse"] = "nll",
    seed: int = 0,
) -> list[float]:
    """Fit ``policy``'s actor to demonstrations; returns the mean loss of each epoch.

    :param policy: an SB3 actor-critic policy with a Gaussian action distribution (PPO's ``MlpPolicy``)
    :param observations: ``(N, obs_dim)`` demonstration states
    :param actions: ``(N, action_dim)`` demonstration actions, in the env's action units
    :param epochs: passes over the demonstrations
    :param batch_size: pairs per gradient step
    :param learning_rate: Adam learning rate
    :param loss: ``"nll"`` (negative log-likelihood, fits mean and std) or ``"mse"`` (mean only)
    :param seed: seed of the minibatch order
    """
    observations = np.asarray(observations, dtype=np.float32)
    actions = np.asarray(actions, dtype=np.float32)
    if observations.ndim != 2 or observations.shape[1:] != policy.observation_space.shape:
        raise ValueError(f"observations must have shape (N, {policy.observation_space.shape[0]}), got {observations.shape}")
    if actions.shape != (len(observations), *policy.action_space.shape):
        raise ValueError(f"actions must have shape ({len(observations)}, {policy.action_space.shape[0]}), got {actions.shape}")
    if loss not in ("nll", "mse"):
        raise ValueError(f"loss must be 'nll' or 'mse', got {loss!r}")
    critic = ("value_net", "mlp_extractor.value")
    actor_parameters = [p for name, p in policy.named_parameters() if not name.startswith(critic)]
    optimizer = th.optim.Adam(actor_parameters, lr=learning_rate)
    rng = np.random.default_rng(seed)
    policy.set_training_mode(True)
    history = []
    for _ in range(epochs):
        order = rng.permutation(len(observations))
        losses = []
        for start in range(0, len(order), batch_size):
            batch = order[start:start + batch_size]
            obs = th.as_tensor(observations[batch], device=policy.device)
            act = th.as_tensor(actions[batch], device=policy.device)
            value = imitation_loss(policy, obs, act, loss)
            optimizer.zero_grad()
            value.backward()
            optimizer.step()
            losses.append(value.item())
        history.append(float(np.mean(losses)))
    policy.set_training_mode(False)
    return history


def imitation_loss(policy: ActorCriticPolicy, observations: th.Tensor, actions: th.Tensor,
                   loss: Literal["nll", "mse"] = "nll") -> th.Tensor:
    """The behaviour cloning loss of ``policy`` on a batch (see :func:`behaviour_cloning`)."""
    distribution = policy.get_distribution(observations)
    if loss == "nll":
        return -distribution.log_prob(actions).mean()
    return ((distribution.distribution.mean - actions) ** 2).sum(dim=1).mean()
