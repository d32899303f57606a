"""GenRL's value function (paper Algorithm 1, last line): ``V = argmin_V' sum_i (V'(s_i) - r_i)^2`` over recent batches."""

from __future__ import annotations

from collections import deque
from typing import Any

import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy
from torch.nn import functional as F

from sb3_genrl.genrl.fused import FlatAdam, FlatMlp, mlp_layers
from sb3_genrl.genrl.policies import actor_parameters

# (observations, returns) of one batch; observations are a tensor, or a dict of tensors for Dict contexts
Batch = tuple[Any, th.Tensor]


def fit_value_function(policy: ActorCriticPolicy, memory: deque[Batch], *, epochs: int, batch_size: int) -> list[float]:
    """Fit the policy's value head to the returns of the batches in ``memory`` by Adam on shuffled minibatches.

    The actor's parameters, shared or not, keep their values: only the value function's gradients are applied.

    :param policy: the actor-critic policy (its own optimizer is used)
    :param memory: the batches to fit, oldest first
    :param epochs: passes over all of them
    :param batch_size: minibatch size
    :return: the loss of every minibatch
    """
    observations = concatenate([observations for observations, _ in memory])
    returns = th.cat([returns for _, returns in memory])
    use_foreach(policy.optimizer)
    fused = fused_value(policy, observations)
    if fused is not None:
        return fused_value_fit(*fused, returns, epochs=epochs, batch_size=batch_size)
    actor = actor_parameters(policy)
    losses = []
    for _ in range(epochs):
        permutation = th.randperm(len(returns), device=returns.device)
        for start in range(0, len(returns), batch_size):
            indices = permutation[start : start + batch_size]
            loss = F.mse_loss(policy.predict_values(take(observations, indices)).flatten(), returns[indices])
            policy.optimizer.zero_grad()
            loss.backward()
            for parameter in actor:  # shared parameters stay those of the M-step
                parameter.grad = None
            policy.optimizer.step()
            losses.append(loss.detach())
    return th.stack(losses).tolist() if losses else []


def fused_value(policy: ActorCriticPolicy, observations: Any) -> tuple[FlatMlp, FlatAdam, th.Tensor] | None:
    """The value function as a :class:`~sb3_genrl.genrl.fused.FlatMlp` with the policy optimizer's update of it, and
    the features of ``observations``; ``None`` when the features extractor trains, or the MLP or the optimizer is not
    one the fused steps know (then :func:`fit_value_function` takes autograd's steps)."""
    extractor = policy.vf_features_extractor
    layers = mlp_layers([policy.mlp_extractor.value_net, policy.value_net])
    if layers is None or any(parameter.requires_grad for parameter in extractor.parameters()):
        return None
    critic = [parameter for linear, _ in layers for parameter in (linear.weight, linear.bias)]
    trained = {id(p) for p in policy.parameters() if p.requires_grad} - {id(p) for p in actor_parameters(policy)}
    if trained != set(map(id, critic)):  # the fit would train parameters outside the value MLP
        return None
    adam = FlatAdam.build(policy.optimizer, critic)
    if adam is None:
        return None
    with th.no_grad():
        features = policy.extract_features(observations, extractor)
    return FlatMlp(layers, adam), adam, features


def fused_value_fit(
    mlp: FlatMlp, adam: FlatAdam, features: th.Tensor, returns: th.Tensor, *, epochs: int, batch_size: int
) -> list[float]:
    """:func:`fit_value_function`'s steps on fixed features, fused (:mod:`sb3_genrl.genrl.fused`): the same
    shuffles, the same arithmetic (the mean squared error's gradient by ``mse_loss_backward``, as autograd takes it).

    :return: the loss of every minibatch
    """
    losses = []
    with th.no_grad():
        one = th.ones((), dtype=returns.dtype, device=returns.device)  # the loss's own gradient, as backward() seeds it
        for _ in range(epochs):
            permutation = th.randperm(len(returns), device=returns.device)
            shuffled_features, shuffled_returns = features[permutation], returns[permutation]  # the epoch's rows, at once
            for start in range(0, len(returns), batch_size):
                outputs = mlp.forward(shuffled_features[start : start + batch_size])
                values, targets = outputs[-1].flatten(), shuffled_returns[start : start + batch_size]
                losses.append(F.mse_loss(values, targets))
                grad = th.ops.aten.mse_loss_backward(one, values, targets, 1)  # 1: the mean reduction
                mlp.backward(outputs, grad.view(-1, 1))
                adam.step()
    if losses:  # as autograd's steps leave them: the actor's gradients cleared, the value function's last ones kept
        adam.optimizer.zero_grad()
    adam.write_back()
    return th.stack(losses).tolist() if losses else []


def use_foreach(optimizer: th.optim.Optimizer) -> None:
    """Make ``optimizer`` (Adam) update all its parameters with torch's multi-tensor ("foreach") kernels, as it does on
    a GPU by default: the same arithmetic, about a third fewer Python calls per step on a CPU, where the default is one
    parameter at a time. Set again at each fit, since loading a saved optimizer restores its saved setting."""
    for group in optimizer.param_groups:
        group["foreach"] = True


def concatenate(batches: list[Any]) -> Any:
    """Observation batches (tensors, or dicts of tensors for Dict contexts) joined along the first axis."""
    if isinstance(batches[0], dict):
        return {key: th.cat([batch[key] for batch in batches]) for key in batches[0]}
    return th.cat(batches)


def take(observations: Any, indices: th.Tensor) -> Any:
    """Rows ``indices`` of an observation batch (a tensor or a dict of tensors)."""
    if isinstance(observations, dict):
        return {key: value[indices] for key, value in observations.items()}
    return observations[indices]
