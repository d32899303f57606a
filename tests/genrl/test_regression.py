"""The regression of the policy's mean (sb3_genrl/genrl/regression.py) against known maps."""

from __future__ import annotations

import numpy as np
import pytest
import torch as th
from conftest import (
    FastReachEnv,
    LinearGenerator,
)

from sb3_genrl import GenRL


@pytest.mark.parametrize("policy_name", ["MlpPolicy", "ContextStdPolicy"])
def test_mean_parameters_are_the_actors_without_its_spread(policy_name):
    from sb3_genrl.genrl.policies import actor_parameters
    from sb3_genrl.genrl.regression import mean_parameters

    policy = GenRL(policy_name, FastReachEnv(), LinearGenerator(), seed=0).policy
    names = {id(parameter): name for name, parameter in policy.named_parameters()}
    chosen = {names[id(parameter)] for parameter in mean_parameters(policy)}
    spread = {names[id(parameter)] for parameter in actor_parameters(policy)} - chosen
    assert chosen and all(name.startswith(("mlp_extractor.policy_net.", "action_net.")) for name in chosen)
    assert spread == ({"log_std"} if policy_name == "MlpPolicy" else {"log_std_net.weight", "log_std_net.bias"})
    # the mean's gradient reaches every chosen parameter and nothing else of the actor
    observations = th.rand(8, 2) * 1.6 - 0.8
    policy.get_distribution(observations).distribution.mean.sum().backward()
    assert {names[id(p)] for p in actor_parameters(policy) if p.grad is not None and p.grad.abs().sum() > 0} == chosen


@pytest.mark.parametrize("policy_name", ["MlpPolicy", "ContextStdPolicy"])
def test_policy_mean_is_the_distributions_mean(policy_name):
    from sb3_genrl.genrl.regression import policy_mean

    policy = GenRL(
        policy_name, FastReachEnv(), LinearGenerator(), seed=0, policy_kwargs={"net_arch": {"pi": [16, 16, 16], "vf": [8]}}
    ).policy
    with th.no_grad():  # move the mean off its near-zero start, so that a wrong path would show
        for parameter in policy.action_net.parameters():
            parameter.add_(th.randn(parameter.shape, generator=th.Generator().manual_seed(1)))
    observations = th.rand(32, 2, generator=th.Generator().manual_seed(0)) * 1.6 - 0.8
    expected = policy.get_distribution(observations).distribution.mean
    assert expected.abs().max() > 0.1
    th.testing.assert_close(policy_mean(policy, observations), expected, rtol=0, atol=0)


def test_regress_mean_fits_a_known_linear_map_and_leaves_the_rest():
    from sb3_genrl.genrl.regression import mean_parameters, regress_mean

    policy = GenRL(FastReachEnv(), LinearGenerator(), seed=0).policy
    generator = th.Generator().manual_seed(0)
    contexts = th.rand(512, 2, generator=generator) * 1.6 - 0.8
    weights, bias = th.tensor([[1.5, -0.5], [0.3, 2.0]]), th.tensor([0.2, -0.4])
    targets = contexts @ weights.T + bias  # the answer, computed here
    untouched = {
        name: value.clone()
        for name, value in policy.state_dict().items()
        if name.startswith(("log_std", "value_net", "mlp_extractor.value_net"))
    }
    optimizer = th.optim.Adam(mean_parameters(policy), lr=1e-3)
    losses = regress_mean(policy, optimizer, contexts, targets, steps=1500, batch_size=64)
    assert len(losses) == 1500 and np.mean(losses[-50:]) < 0.01 * np.mean(losses[:50])
    test = th.rand(200, 2, generator=generator) * 1.6 - 0.8
    with th.no_grad():
        error = policy.get_distribution(test).distribution.mean - (test @ weights.T + bias)
    assert error.abs().max() < 0.1
    for name, value in untouched.items():
        th.testing.assert_close(policy.state_dict()[name], value)


def test_weighted_regress_mean_keeps_to_the_branch_the_policy_is_on():
    """Two latent actions solve every context, f(c) + b and f(c) - b: the plain fit lands on their average f(c), the
    weighted one, started on the first branch with a narrow spread, on that branch."""
    from sb3_genrl.genrl.regression import mean_parameters, policy_mean, regress_mean

    generator = th.Generator().manual_seed(0)
    contexts = th.rand(1024, 2, generator=generator) * 1.6 - 0.8
    weights, shift = th.tensor([[0.5, -0.2], [0.1, 0.4]]), th.tensor([1.0, -0.5])
    answer = contexts @ weights.T  # f(c), computed here
    branch = th.rand(1024, generator=generator) < 0.5
    targets = th.where(branch[:, None], answer + shift, answer - shift)
    test = th.rand(200, 2, generator=generator) * 1.6 - 0.8
    errors = {}
    for weighted in (False, True):
        policy = GenRL(FastReachEnv(), LinearGenerator(), seed=0, policy_kwargs={"log_std_init": np.log(0.2)}).policy
        with th.no_grad():
            policy.action_net.bias.copy_(shift)  # the policy starts near the first branch
        optimizer = th.optim.Adam(mean_parameters(policy), lr=1e-3)
        regress_mean(policy, optimizer, contexts, targets, steps=1500, batch_size=64, weighted=weighted)
        with th.no_grad():
            mean = policy_mean(policy, test)
        expected = test @ weights.T
        errors[weighted] = ((mean - expected).abs().max().item(), (mean - expected - shift).abs().max().item())
    assert errors[False][0] < 0.25 and errors[False][1] > 0.75  # the average of the branches, on neither
    assert errors[True][1] < 0.1 and errors[True][0] > 0.9  # the first branch


def _autograd_regression(policy, optimizer, contexts, actions, *, steps, batch_size):
    """The regression's steps as autograd and torch.optim take them: one minibatch draw, forward, backward and Adam
    step at a time (the independent computation of the fused steps)."""
    features = policy.extract_features(contexts, policy.pi_features_extractor).detach()
    losses = []
    for _ in range(steps):
        indices = th.randint(len(actions), (min(batch_size, len(actions)),))
        loss = (policy.action_net(policy.mlp_extractor.forward_actor(features[indices])) - actions[indices]).pow(2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    return losses


def assert_same_fit(first, second, first_optimizer, second_optimizer):
    """Two fitted policies and their Adam optimizers hold the same numbers, bit for bit."""
    for (name, value), other in zip(first.state_dict().items(), second.state_dict().values(), strict=True):
        th.testing.assert_close(value, other, rtol=0, atol=0, msg=name)
    for parameter, other in zip(first.parameters(), second.parameters(), strict=True):
        assert (parameter.grad is None) == (other.grad is None)
        if parameter.grad is not None:
            th.testing.assert_close(parameter.grad, other.grad, rtol=0, atol=0)
    states, other_states = first_optimizer.state_dict()["state"], second_optimizer.state_dict()["state"]
    assert states.keys() == other_states.keys()
    for key, state in states.items():
        for field, value in state.items():
            assert value.dtype == other_states[key][field].dtype
            th.testing.assert_close(value, other_states[key][field], rtol=0, atol=0)


@pytest.mark.parametrize(
    ("policy_name", "activation", "foreach"),
    [("MlpPolicy", th.nn.Tanh, True), ("ContextStdPolicy", th.nn.Tanh, True), ("MlpPolicy", th.nn.ReLU, False)],
)
def test_fused_regression_is_autograd_and_adam_bit_for_bit(policy_name, activation, foreach):
    import copy

    from sb3_genrl.genrl.regression import fused_mean, mean_parameters, regress_mean

    policy = GenRL(
        policy_name,
        FastReachEnv(),
        LinearGenerator(),
        seed=0,
        policy_kwargs={"net_arch": {"pi": [32, 32, 32], "vf": [8]}, "activation_fn": activation},
    ).policy
    generator = th.Generator().manual_seed(0)
    contexts = th.rand(300, 2, generator=generator) * 1.6 - 0.8
    actions = th.randn(300, 2, generator=generator)
    fits = []
    for fit in (regress_mean, _autograd_regression):
        copied = copy.deepcopy(policy)
        optimizer = th.optim.Adam(mean_parameters(copied), lr=1e-3, foreach=foreach)
        assert fit is _autograd_regression or fused_mean(copied, optimizer) is not None  # the fused steps are taken
        th.manual_seed(1)
        # from a fresh optimizer, then from its moments; a batch larger than the pulls takes them all each step
        losses = fit(copied, optimizer, contexts, actions, steps=40, batch_size=64)
        losses += fit(copied, optimizer, contexts[:50], actions[:50], steps=30, batch_size=64)
        fits.append((copied, optimizer, losses))
    (fused, fused_optimizer, fused_losses), (expected, expected_optimizer, expected_losses) = fits
    assert fused_losses == expected_losses and len(fused_losses) == 70
    assert_same_fit(fused, expected, fused_optimizer, expected_optimizer)
    assert not th.equal(fused.action_net.weight, policy.action_net.weight)  # it did fit


def test_regress_mean_takes_autograd_steps_where_the_fused_ones_do_not_apply():
    from sb3_genrl.genrl.regression import fused_mean, mean_parameters, regress_mean

    policy = GenRL(FastReachEnv(), LinearGenerator(), seed=0).policy
    sgd = th.optim.SGD(mean_parameters(policy), lr=1e-2)
    assert fused_mean(policy, sgd) is None
    assert fused_mean(policy, th.optim.Adam(mean_parameters(policy), weight_decay=1e-4)) is None
    assert fused_mean(policy, th.optim.Adam(mean_parameters(policy)[:2])) is None  # not all of the mean's parameters
    contexts = th.rand(64, 2, generator=th.Generator().manual_seed(0)) * 1.6 - 0.8
    losses = regress_mean(policy, sgd, contexts, contexts.flip(1), steps=200, batch_size=32)
    assert np.mean(losses[-20:]) < 0.5 * np.mean(losses[:20])
