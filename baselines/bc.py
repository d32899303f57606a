"""Behaviour cloning of a PPO actor on demonstration state-action pairs (paper section 6.1.5).

As a careful practitioner does it:

- whole demonstration episodes are held out (``holdout``), so the held-out loss measures states the actor never saw;
- the actor's mean is fitted by mean squared error with Adam, and training stops when the held-out loss has not
  improved for ``patience`` epochs; the weights of the best epoch are restored;
- the actor's (state-independent) standard deviation is then set to the held-out residual standard deviation of
  each action dimension, clipped to ``std_range``: PPO starts exploring with the spread of the actor's own
  errors, not with a fitted likelihood's std, which a few epochs of negative log-likelihood leave far too wide.

The observations are normalised by the policy's features extractor with the demonstrations' statistics (see
:mod:`sb3_genrl.baselines.normalization`), so nothing here rescales them.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy

from sb3_genrl.genrl.policies import actor_parameters

# Bounds of the actor's exploration std after cloning (rad per control step): positive, and a tenth of the action
# bound at most. On hockey the held-out residual std is 1e-4 to 6e-4 and lies inside.
STD_RANGE = (1e-4, 0.05)


def split_episodes(dones: np.ndarray, holdout: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the training and held-out transitions, holding out whole episodes.

    :param dones: ``(N,)`` True on each episode's last transition (the format of ``load_transitions``)
    :param holdout: share of the episodes held out, in ``(0, 1)``
    :param seed: seed of the episodes' draw
    :return: training indices, held-out indices (each sorted)
    """
    dones = np.asarray(dones, dtype=bool)
    ends = np.flatnonzero(dones)
    if len(ends) == 0 or ends[-1] != len(dones) - 1:
        raise ValueError("dones must mark the end of every episode, the last transition included")
    if not 0 < holdout < 1:
        raise ValueError(f"holdout must lie in (0, 1), got {holdout}")
    n_heldout = int(round(holdout * len(ends)))
    if n_heldout < 1 or n_heldout >= len(ends):
        raise ValueError(f"holding out {holdout:.0%} of {len(ends)} episodes leaves an empty split")
    episode = np.concatenate([[0], np.cumsum(dones)[:-1]])  # the episode index of each transition
    heldout_episodes = np.random.default_rng(seed).choice(len(ends), size=n_heldout, replace=False)
    heldout = np.isin(episode, heldout_episodes)
    return np.flatnonzero(~heldout), np.flatnonzero(heldout)


def behaviour_cloning(
    policy: ActorCriticPolicy,
    observations: np.ndarray,
    actions: np.ndarray,
    dones: np.ndarray,
    *,
    holdout: float = 0.1,
    seed: int = 0,
    **fit_kwargs: Any,
) -> dict[str, Any]:
    """Fit ``policy``'s actor to demonstrations, holding out whole episodes (see the module docstring).

    :param policy: an SB3 actor-critic policy with a diagonal Gaussian action distribution (PPO's ``MlpPolicy``)
    :param observations: ``(N, obs_dim)`` demonstration states, as the policy observes them
    :param actions: ``(N, action_dim)`` demonstration actions, in the env's action units
    :param dones: ``(N,)`` True on each episode's last transition
    :param holdout: share of the episodes held out for early stopping and the exploration std
    :param seed: seed of the split and of the minibatch order
    :param fit_kwargs: passed to :func:`fit_actor` (``max_epochs``, ``patience``, ``batch_size``, ...)
    :return: :func:`fit_actor`'s record, with ``train_episodes`` and ``heldout_episodes``
    """
    observations = np.asarray(observations, dtype=np.float32)
    actions = np.asarray(actions, dtype=np.float32)
    if observations.ndim != 2 or observations.shape[1:] != policy.observation_space.shape:
        raise ValueError(f"observations must have shape (N, {policy.observation_space.shape[0]}), got {observations.shape}")
    if actions.shape != (len(observations), *policy.action_space.shape):
        raise ValueError(f"actions must have shape ({len(observations)}, {policy.action_space.shape[0]}), got {actions.shape}")
    if len(dones) != len(observations):
        raise ValueError(f"dones must have length {len(observations)}, got {len(dones)}")
    train, heldout = split_episodes(dones, holdout, seed)
    record = fit_actor(
        policy, (observations[train], actions[train]), (observations[heldout], actions[heldout]), seed=seed, **fit_kwargs
    )
    dones = np.asarray(dones, dtype=bool)
    return record | {"train_episodes": int(dones[train].sum()), "heldout_episodes": int(dones[heldout].sum())}


def fit_actor(
    policy: ActorCriticPolicy,
    train: tuple[np.ndarray, np.ndarray],
    heldout: tuple[np.ndarray, np.ndarray],
    *,
    max_epochs: int = 200,
    patience: int = 10,
    batch_size: int = 512,
    learning_rate: float = 1e-3,
    std_range: tuple[float, float] = STD_RANGE,
    seed: int = 0,
) -> dict[str, Any]:
    """Fit the actor's mean by MSE with early stopping on ``heldout``; set its std to the held-out residual std.

    :param policy: an SB3 actor-critic policy with a state-independent ``log_std`` (PPO without gSDE)
    :param train: training ``(observations, actions)``
    :param heldout: held-out ``(observations, actions)``
    :param max_epochs: most passes over ``train``
    :param patience: epochs without a lower held-out loss before stopping
    :param batch_size: pairs per gradient step
    :param learning_rate: Adam learning rate
    :param std_range: bounds of the exploration std set after fitting (action units)
    :param seed: seed of the minibatch order
    :return: ``train_loss`` and ``heldout_loss`` per epoch (mean squared error per action dimension),
        ``best_epoch`` (1-based), ``epochs`` run, ``residual_std`` and the ``action_std`` set, per dimension
    """
    if max_epochs < 1 or patience < 1 or batch_size < 1:
        raise ValueError(f"max_epochs, patience and batch_size must be positive, got {max_epochs}, {patience}, {batch_size}")
    if not 0 < std_range[0] <= std_range[1]:
        raise ValueError(f"std_range must be (low, high) with 0 < low <= high, got {std_range}")
    if not hasattr(policy, "log_std"):
        raise ValueError("fit_actor needs a policy with a state-independent log_std (a Gaussian PPO policy without gSDE)")
    train_obs, train_act = (th.as_tensor(np.asarray(a, dtype=np.float32), device=policy.device) for a in train)
    heldout_obs, heldout_act = (th.as_tensor(np.asarray(a, dtype=np.float32), device=policy.device) for a in heldout)
    actor = [p for p in actor_parameters(policy) if p is not policy.log_std]  # the mean's; the std is set after
    optimizer = th.optim.Adam(actor, lr=learning_rate)
    generator = th.Generator().manual_seed(seed)
    history: dict[str, list[float]] = {"train_loss": [], "heldout_loss": []}
    best, best_state, best_epoch, epoch = np.inf, copy.deepcopy(policy.state_dict()), 0, 0
    policy.set_training_mode(True)
    for epoch in range(1, max_epochs + 1):
        history["train_loss"].append(_train_epoch(policy, optimizer, train_obs, train_act, batch_size, generator))
        history["heldout_loss"].append(float(_residuals(policy, heldout_obs, heldout_act).pow(2).mean()))
        if history["heldout_loss"][-1] < best:
            best, best_state, best_epoch = history["heldout_loss"][-1], copy.deepcopy(policy.state_dict()), epoch
        elif epoch - best_epoch >= patience:
            break
    policy.load_state_dict(best_state)
    policy.set_training_mode(False)
    residual_std = _residuals(policy, heldout_obs, heldout_act).std(dim=0).cpu().numpy()
    action_std = np.clip(residual_std, *std_range)
    with th.no_grad():
        policy.log_std.copy_(th.as_tensor(np.log(action_std), dtype=policy.log_std.dtype))
    return history | {
        "best_epoch": best_epoch,
        "epochs": epoch,
        "residual_std": residual_std.tolist(),
        "action_std": action_std.tolist(),
    }


def _train_epoch(
    policy: ActorCriticPolicy,
    optimizer: th.optim.Optimizer,
    observations: th.Tensor,
    actions: th.Tensor,
    batch_size: int,
    generator: th.Generator,
) -> float:
    """One pass of MSE steps over shuffled minibatches; returns the mean of the minibatch losses."""
    losses = []
    for batch in th.randperm(len(observations), generator=generator).split(batch_size):
        loss = ((actor_mean(policy, observations[batch]) - actions[batch]) ** 2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    return float(np.mean(losses))


def actor_mean(policy: ActorCriticPolicy, observations: th.Tensor) -> th.Tensor:
    """The mean action of ``policy``'s Gaussian actor for a batch of observations."""
    return policy.get_distribution(observations).distribution.mean


def _residuals(policy: ActorCriticPolicy, observations: th.Tensor, actions: th.Tensor, chunk: int = 65536) -> th.Tensor:
    """Demonstrated minus predicted mean actions, in eval mode and without gradients."""
    training = policy.training
    policy.set_training_mode(False)
    with th.no_grad():
        residuals = th.cat(
            [
                actions[i : i + chunk] - actor_mean(policy, observations[i : i + chunk])
                for i in range(0, len(observations), chunk)
            ]
        )
    policy.set_training_mode(training)
    return residuals
