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

from sb3_genrl.genrl.fused import FlatAdam, FlatMlp, mean_backward_scale, mlp_layers
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


def regress_mean(
    policy: ActorCriticPolicy,
    optimizer: th.optim.Optimizer,
    contexts: th.Tensor,
    actions: th.Tensor,
    *,
    steps: int,
    batch_size: int,
    weighted: bool = False,
) -> list[float]:
    """Fit the policy's mean to ``actions`` at ``contexts`` by ``steps`` steps of ``optimizer`` (over
    :func:`mean_parameters`) on minibatches of ``batch_size`` pairs drawn with replacement.

    With ``weighted``, each pair's squared error is weighted by ``exp(-|(action - mean) / std|^2 / 2)``, the current
    policy's density at the action relative to its mode (no gradient through the weight). Where two distant actions
    solve one context (two branches of the map), the plain fit lands between them; the weighted one keeps to the
    branch the policy is on.

    :return: the loss (the mean squared error over the latent dimensions, weighted) of every minibatch
    """
    features = None if weighted else fixed_features(policy, contexts)
    fused = None if features is None else fused_mean(policy, optimizer)
    if fused is not None:
        return fused_regression(*fused, features, actions, steps=steps, batch_size=batch_size)  # type: ignore[arg-type]
    losses = []  # kept as tensors, read once at the end (one .item() per step costs about 2% of a step)
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


def fit_mean(
    policy: ActorCriticPolicy, contexts: th.Tensor, actions: th.Tensor, *, steps: int, learning_rate: float, batch_size: int
) -> list[float]:
    """Fit the policy's mean to ``actions`` at ``contexts`` by ``steps`` steps of a new Adam over its mean
    (:func:`regress_mean`), in training mode; the loss of every minibatch."""
    optimizer = th.optim.Adam(mean_parameters(policy), lr=learning_rate)
    training = policy.training
    policy.set_training_mode(True)
    try:
        return regress_mean(policy, optimizer, contexts, actions, steps=steps, batch_size=batch_size)
    finally:
        policy.set_training_mode(training)


def fused_mean(policy: ActorCriticPolicy, optimizer: th.optim.Optimizer) -> tuple[FlatMlp, FlatAdam] | None:
    """The policy's mean as a :class:`~sb3_genrl.genrl.fused.FlatMlp` with ``optimizer``'s update of it, or ``None``
    when its MLP or its optimizer is not one the fused steps know (then :func:`regress_mean` takes autograd's steps)."""
    layers = mlp_layers([policy.mlp_extractor.policy_net, policy.action_net])
    parameters = mean_parameters(policy)
    if layers is None or {id(p) for linear, _ in layers for p in (linear.weight, linear.bias)} != set(map(id, parameters)):
        return None
    adam = FlatAdam.build(optimizer, parameters)
    return None if adam is None else (FlatMlp(layers, adam), adam)


def fused_regression(
    mlp: FlatMlp, adam: FlatAdam, features: th.Tensor, actions: th.Tensor, *, steps: int, batch_size: int
) -> list[float]:
    """:func:`regress_mean`'s unweighted steps on fixed features, fused (:mod:`sb3_genrl.genrl.fused`): the same draws
    of minibatches (one ``randint`` call for all steps draws what one call per step would), the same arithmetic.

    :return: the loss of every minibatch
    """
    size = min(batch_size, len(actions))
    indices = th.randint(len(actions), (steps, size), device=actions.device)
    scale = mean_backward_scale(size * actions[0].numel(), actions)
    losses = []
    with th.no_grad():
        for inputs, targets in zip(features[indices], actions[indices], strict=True):  # every step's rows, gathered once
            outputs = mlp.forward(inputs)
            error = outputs[-1] - targets
            losses.append(error.pow(2).mean())
            mlp.backward(outputs, (2.0 * error) * scale)  # autograd's backward of the mean of the squared errors
            adam.step()
    adam.write_back()
    return th.stack(losses).tolist() if losses else []
