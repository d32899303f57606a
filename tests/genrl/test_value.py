"""GenRL's value function (sb3_genrl/genrl/value.py): the batches it remembers and its least-squares fit."""

from __future__ import annotations

import collections

import numpy as np
import pytest
import torch as th
from conftest import (
    FastReachEnv,
    LinearGenerator,
)
from stable_baselines3.common.callbacks import BaseCallback

from sb3_genrl import GenRL


class _BatchRecorder(BaseCallback):
    """Each iteration's observations and returns, as collected."""

    def __init__(self) -> None:
        super().__init__()
        self.batches: list[tuple[np.ndarray, np.ndarray]] = []

    def _on_rollout_end(self) -> None:
        buffer = self.model.rollout_buffer
        self.batches.append(
            (buffer.observations.reshape(-1, buffer.observations.shape[-1]).copy(), buffer.returns.flatten().copy())
        )

    def _on_step(self) -> bool:
        return True


def test_value_memory_holds_the_last_value_history_batches():
    recorder = _BatchRecorder()
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, value_history=3)
    model.learn(5 * 16, callback=recorder)
    assert len(recorder.batches) == 5 and len(model._value_memory) == 3
    for (observations, returns), (expected_observations, expected_returns) in zip(
        model._value_memory, recorder.batches[-3:], strict=True
    ):  # the same rows, in another order
        observations, returns = observations.cpu().numpy(), returns.cpu().numpy()
        order, expected_order = np.argsort(returns), np.argsort(expected_returns)
        np.testing.assert_allclose(observations[order], expected_observations[expected_order])
        np.testing.assert_allclose(returns[order], expected_returns[expected_order])


@pytest.mark.parametrize(("value_history", "expected"), [(1, 1.0), (2, 0.5)])
def test_value_function_is_the_least_squares_fit_over_the_remembered_batches(value_history, expected):
    # The same contexts with returns 0 in the remembered batch and 1 in the current one: the least-squares value is
    # 1 when only the current batch counts, and the mean 0.5 over both batches.
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, value_history=value_history, n_critic_updates=2000)
    model.learn(16)
    observations = next(model.rollout_buffer.get(batch_size=None)).observations
    model._value_memory.clear()
    model._value_memory.append((observations, th.zeros(16, device=model.device)))
    model.rollout_buffer.returns[:] = 1.0
    model._fit_value_function()
    with th.no_grad():
        values = model.policy.predict_values(observations).flatten().cpu().numpy()
    assert abs(values.mean() - expected) < 0.02
    np.testing.assert_allclose(values, expected, atol=0.1)


def test_value_history_is_checked_and_not_saved(tmp_path):
    with pytest.raises(ValueError, match="value_history must be a positive integer, got 0"):
        GenRL(FastReachEnv(), LinearGenerator(), value_history=0)
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, value_history=4)
    model.learn(32)
    model.save(tmp_path / "model")
    loaded = GenRL.load(tmp_path / "model.zip", env=FastReachEnv(), generator=LinearGenerator())
    assert loaded.value_history == 4 and len(loaded._value_memory) == 0 and loaded._value_memory.maxlen == 4


def test_observation_batches_join_and_index_as_tensors_and_dicts():
    from sb3_genrl.genrl.value import concatenate, take

    first, second = th.arange(6.0).reshape(3, 2), th.arange(6.0, 10.0).reshape(2, 2)
    joined = concatenate([first, second])
    th.testing.assert_close(joined, th.arange(10.0).reshape(5, 2))
    th.testing.assert_close(take(joined, th.tensor([4, 0])), th.tensor([[8.0, 9.0], [0.0, 1.0]]))
    dicts = concatenate([{"goal": first, "t": th.zeros(3)}, {"goal": second, "t": th.ones(2)}])
    th.testing.assert_close(dicts["goal"], joined)
    th.testing.assert_close(take(dicts, th.tensor([3]))["t"], th.ones(1))


def _autograd_value_fit(policy, memory, *, epochs, batch_size):
    """The value fit as autograd and torch.optim take it, one minibatch at a time (the independent computation of
    the fused steps)."""
    from torch.nn import functional as F

    from sb3_genrl.genrl.policies import actor_parameters

    observations, returns = th.cat([o for o, _ in memory]), th.cat([r for _, r in memory])
    for group in policy.optimizer.param_groups:
        group["foreach"] = True
    losses = []
    for _ in range(epochs):
        permutation = th.randperm(len(returns))
        for start in range(0, len(returns), batch_size):
            indices = permutation[start : start + batch_size]
            loss = F.mse_loss(policy.predict_values(observations[indices]).flatten(), returns[indices])
            policy.optimizer.zero_grad()
            loss.backward()
            for parameter in actor_parameters(policy):
                parameter.grad = None
            policy.optimizer.step()
            losses.append(loss.item())
    return losses


@pytest.mark.parametrize("policy_name", ["MlpPolicy", "ContextStdPolicy"])
def test_fused_value_fit_is_autograd_and_adam_bit_for_bit(policy_name):
    import copy

    from test_regression import assert_same_fit

    from sb3_genrl.genrl.value import fit_value_function, fused_value

    policy = GenRL(
        policy_name, FastReachEnv(), LinearGenerator(), seed=0, policy_kwargs={"net_arch": {"pi": [8], "vf": [32, 32]}}
    ).policy
    generator = th.Generator().manual_seed(0)
    observations = th.rand(90, 2, generator=generator) * 1.6 - 0.8
    returns = th.randn(90, generator=generator)
    memory = collections.deque([(observations[:50], returns[:50]), (observations[50:], returns[50:])])
    fits = []
    for fit in (fit_value_function, _autograd_value_fit):
        copied = copy.deepcopy(policy)
        assert fit is _autograd_value_fit or fused_value(copied, observations) is not None  # the fused steps are taken
        for parameter in copied.parameters():  # gradients left by an earlier fit (the regression's) are cleared
            parameter.grad = th.ones_like(parameter)
        th.manual_seed(1)
        losses = fit(copied, memory, epochs=3, batch_size=32)  # 90 returns: minibatches of 32, 32 and 26
        losses += fit(copied, collections.deque([memory[0]]), epochs=2, batch_size=64)
        fits.append((copied, losses))
    (fused, fused_losses), (expected, expected_losses) = fits
    assert fused_losses == expected_losses and len(fused_losses) == 9 + 2
    assert_same_fit(fused, expected, fused.optimizer, expected.optimizer)
    assert not th.equal(fused.value_net.weight, policy.value_net.weight)  # it did fit


def test_the_default_minibatch_is_at_most_one_iterations_episodes():
    """With fewer episodes per iteration than ``batch_size``, the value fit's minibatches are one iteration's episodes:
    16 episodes an iteration over 4 remembered batches give the run of ``batch_size=16``, not one minibatch of 64."""

    def trained(**kwargs):
        model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, value_history=4, **kwargs)
        model.learn(6 * 16)
        return model

    default, sixteen, whole = trained(), trained(batch_size=16), trained(batch_size=10_000)
    assert default.minibatch_size == 16 and whole.minibatch_size == 16
    for model in (sixteen, whole):
        for ours, theirs in zip(default.policy.parameters(), model.policy.parameters(), strict=True):
            assert th.equal(ours, theirs)
    # (the value fit is what differs with another minibatch)
    eight = trained(batch_size=8)
    assert not all(th.equal(a, b) for a, b in zip(default.policy.parameters(), eight.policy.parameters(), strict=True))
