"""A critic over latent actions as GenRL's baseline: ``Q(s0, alpha)`` fitted to the pulls of the last batches, and the
E-step's advantage ``A = r - E_{alpha' ~ pi(.|s0)}[Q(s0, alpha')]`` in place of the paper's ``A = r - V(s0)``.

The paper's value function ``V(s0)`` is the expected reward of the *current* policy, so it is fitted to the current
batch alone: one pull per context, ``batch_episodes`` (``n_steps * n_envs``) pulls. Its error at a context is a bias
shared by that context's pull, and where it exceeds the reward differences within the policy's spread (a policy near
its goal) the E-step's step follows the baseline's error, not the reward (``docs/guide/search.md`` measures this on a
small bandit). In a one-step bandit the reward of a pull does not depend on the policy that drew it, so a critic over
(context, latent action) can learn from the pulls of many batches; averaged over draws from the policy's own spread at
each context it is a baseline for the current policy. The direction of DSRL (Wagenmaker et al., 2025), which learns a
critic over a diffusion policy's noise; here the critic only replaces the baseline, the E-step and its KL bound stay
the paper's.

Switched on by GenRL's ``latent_critic_kwargs`` (``{}``: the defaults of :data:`DEFAULTS`). The critic and its pulls are
not saved with the model: a loaded model's critic starts afresh.
"""

from __future__ import annotations

import collections
from collections.abc import Mapping
from typing import Any

import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy
from torch import nn

from sb3_genrl.genrl.value import concatenate

DEFAULTS: dict[str, Any] = {
    "history": 16,  # batches whose pulls the critic is fitted to
    "net_arch": (64, 64),  # hidden layers of the critic (ReLU)
    "steps": 64,  # Adam steps of the critic's fit per iteration
    "batch_size": 256,  # pulls per step
    "learning_rate": 1e-3,
    "draws": 32,  # draws from the policy per context that the baseline averages
}


def check_latent_critic_kwargs(latent_critic_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """Refuse latent critic settings that :class:`LatentCritic` would not take, naming the setting.

    :param latent_critic_kwargs: some of :data:`DEFAULTS`' keys
    :return: the settings with :data:`DEFAULTS` for those not given
    """
    if not isinstance(latent_critic_kwargs, Mapping):
        raise ValueError(f"latent_critic_kwargs must be a dict or None, got {latent_critic_kwargs!r}")
    unknown = sorted(set(latent_critic_kwargs) - set(DEFAULTS))
    if unknown:
        raise ValueError(
            f"latent_critic_kwargs: {', '.join(map(repr, unknown))} not among its settings ({', '.join(DEFAULTS)})"
        )
    settings = DEFAULTS | dict(latent_critic_kwargs)
    for key in ("history", "steps", "batch_size", "draws"):
        value = settings[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"latent_critic_kwargs['{key}'] must be a positive integer, got {value!r}")
    rate = settings["learning_rate"]
    if isinstance(rate, bool) or not isinstance(rate, int | float) or not 0 < rate < float("inf"):
        raise ValueError(f"latent_critic_kwargs['learning_rate'] must be a finite number > 0, got {rate!r}")
    sizes = settings["net_arch"]
    if not isinstance(sizes, list | tuple) or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in sizes):
        raise ValueError(f"latent_critic_kwargs['net_arch'] must be a list of positive layer sizes, got {sizes!r}")
    return settings


class LatentCritic:
    """``Q(s0, alpha)``, the reward of latent action ``alpha`` at context ``s0``, on the policy's features of ``s0``.

    :param policy: the GenRL policy (its features extractor reads the contexts; the critic lives on its device)
    :param history: batches whose pulls the critic is fitted to (the current one and those before it)
    :param net_arch: hidden layer sizes of the critic (ReLU)
    :param steps: Adam steps of the critic's fit per iteration
    :param batch_size: pulls per step, drawn with replacement from the kept pulls
    :param learning_rate: Adam learning rate of the critic
    :param draws: draws from ``pi(.|s0)`` per context that the baseline averages
    """

    def __init__(
        self,
        policy: ActorCriticPolicy,
        *,
        history: int,
        net_arch: tuple[int, ...] | list[int],
        steps: int,
        batch_size: int,
        learning_rate: float,
        draws: int,
    ) -> None:
        sizes = [policy.features_dim + int(policy.action_space.shape[0]), *net_arch]
        layers: list[nn.Module] = []
        for size_in, size_out in zip(sizes[:-1], sizes[1:], strict=True):
            layers += [nn.Linear(size_in, size_out), nn.ReLU()]
        self.q = nn.Sequential(*layers, nn.Linear(sizes[-1], 1)).to(policy.device)
        self.optimizer = th.optim.Adam(self.q.parameters(), lr=learning_rate)
        self.memory: collections.deque[tuple[Any, th.Tensor, th.Tensor]] = collections.deque(maxlen=history)
        self.steps, self.batch_size, self.draws = steps, batch_size, draws

    def value(self, features: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """``Q`` at features ``(..., features_dim)`` and latent actions ``(..., latent_dim)``: shape ``(...)``."""
        return self.q(th.cat([features, actions], dim=-1)).squeeze(-1)

    def advantages(
        self, policy: ActorCriticPolicy, observations: Any, actions: th.Tensor, returns: th.Tensor
    ) -> tuple[th.Tensor, dict[str, float]]:
        """Keep a batch's pulls, fit the critic to the kept pulls, and return the batch's advantages
        ``r - mean_k Q(s0, alpha_k)``, ``alpha_k ~ pi(.|s0)`` (the draws clipped to the action box), with the fit's
        mean loss (``latent_critic_loss``).

        :param policy: the policy whose draws the baseline averages (evaluated without gradient)
        :param observations: the batch's contexts (a tensor, or a dict of tensors for a Dict context)
        :param actions: the batch's latent actions ``(N, latent_dim)``
        :param returns: the batch's rewards ``(N,)``
        """
        self.memory.append((observations, actions, returns))
        with th.no_grad():
            features = policy.extract_features(concatenate([o for o, _, _ in self.memory]), policy.pi_features_extractor)
        kept_actions = th.cat([a for _, a, _ in self.memory])
        kept_returns = th.cat([r for _, _, r in self.memory])
        losses = []
        for _ in range(self.steps):
            rows = th.randint(len(kept_returns), (min(self.batch_size, len(kept_returns)),), device=kept_returns.device)
            loss = (self.value(features[rows], kept_actions[rows]) - kept_returns[rows]).pow(2).mean()
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            losses.append(loss.detach())
        with th.no_grad():
            batch_features = features[-len(returns) :]
            distribution = policy.get_distribution(observations)
            draws = distribution.distribution.sample((self.draws,))  # (draws, N, latent_dim)
            low = th.as_tensor(policy.action_space.low, device=draws.device)
            high = th.as_tensor(policy.action_space.high, device=draws.device)
            draws = th.maximum(th.minimum(draws, high), low)
            baseline = self.value(batch_features.expand(self.draws, -1, -1), draws).mean(dim=0)
        return returns - baseline, {"latent_critic_loss": th.stack(losses).mean().item() if losses else float("nan")}
