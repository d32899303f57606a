"""GenRL's hindsight regression: the policy's mean fitted to the relabelled pulls, exact (context, latent action) pairs.

A relabelled pull ``(context', alpha)`` (:mod:`sb3_genrl.genrl.hindsight`) is a latent action together with the context it
solves best, so it is a sample of the answer itself: the map from contexts to the latent actions that solve them. A
few Adam steps per iteration on ``|mu(context') - alpha|^2`` over the kept pulls teach the policy's mean that map
directly, as supervised learning on relabelled goals does (Ghosh et al., 2021, "Learning to Reach Goals via
Iterated Supervised Learning"), while the E-step keeps shaping it through the rewards.
"""

from __future__ import annotations

import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy

from sb3_genrl.genrl.policies import actor_parameters

# Names of the parameters that set the spread alone: MlpPolicy's log_std, ContextStdPolicy's log_std_net.
SPREAD_PREFIX = "log_std"


def mean_parameters(policy: ActorCriticPolicy) -> list[th.nn.Parameter]:
    """The parameters of the policy's mean: the actor's (:func:`actor_parameters`) but those of its spread."""
    spread = {id(parameter) for name, parameter in policy.named_parameters() if name.startswith(SPREAD_PREFIX)}
    return [parameter for parameter in actor_parameters(policy) if id(parameter) not in spread]


def policy_mean(policy: ActorCriticPolicy, contexts: th.Tensor) -> th.Tensor:
    """The policy's mean at ``contexts``: ``get_distribution(contexts).distribution.mean``, computed without building
    the distribution (its spread is not needed), which makes a regression step about a third cheaper."""
    features = policy.extract_features(contexts, policy.pi_features_extractor)
    return policy.action_net(policy.mlp_extractor.forward_actor(features))


def fixed_features(policy: ActorCriticPolicy, contexts: th.Tensor) -> th.Tensor | None:
    """The policy's features of all ``contexts`` at once, when its features extractor trains no parameters
    (:class:`~sb3_genrl.genrl.policies.BoxScaler`, a flatten): each row is then its context's alone, so a fit's steps
    take their rows instead of computing them again; ``None`` for an extractor that trains."""
    extractor = policy.pi_features_extractor
    if any(parameter.requires_grad for parameter in extractor.parameters()):
        return None
    with th.no_grad():
        return policy.extract_features(contexts, extractor)


def regress_mean(policy: ActorCriticPolicy, optimizer: th.optim.Optimizer, contexts: th.Tensor, actions: th.Tensor, *,
                 steps: int, batch_size: int, weighted: bool = False) -> list[float]:
    """Fit the policy's mean to ``actions`` at ``contexts`` by ``steps`` steps of ``optimizer`` (over
    :func:`mean_parameters`) on minibatches of ``batch_size`` pairs drawn with replacement.

    With ``weighted``, each pair's squared error is weighted by ``exp(-|(action - mean) / std|^2 / 2)``, the current
    policy's density at the action relative to its mode (no gradient through the weight). Where two distant actions
    solve one context (two branches of the map), the plain fit lands between them; the weighted one keeps to the
    branch the policy is on.

    :return: the loss (the mean squared error over the latent dimensions, weighted) of every minibatch
    """
    losses = []  # kept as tensors, read once at the end (one .item() per step costs about 2% of a step)
    features = None if weighted else fixed_features(policy, contexts)
    for _ in range(steps):
        indices = th.randint(len(actions), (min(batch_size, len(actions)),), device=actions.device)
        target = actions[indices]
        if weighted:  # one forward pass gives the mean and the spread
            distribution = policy.get_distribution(contexts[indices]).distribution  # type: ignore[attr-defined]
            mean = distribution.mean
            with th.no_grad():
                weights = th.exp(-0.5 * ((target - mean) / distribution.stddev).pow(2).sum(1))
            loss = (weights * (mean - target).pow(2).mean(1)).sum() / weights.sum().clamp_min(1e-8)
        elif features is not None:
            loss = (policy.action_net(policy.mlp_extractor.forward_actor(features[indices])) - target).pow(2).mean()
        else:
            loss = (policy_mean(policy, contexts[indices]) - target).pow(2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.detach())
    return th.stack(losses).tolist() if losses else []
