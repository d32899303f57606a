"""GenRL with several pulls per context (sb3_genrl.genrl.grouped_pulls): the groups' contexts and reset seeds, the
leave-one-out advantage against a loop, the same groups with one env or two, and the settings it refuses."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ContextReachEnv, FastReachEnv, LinearGenerator
from stable_baselines3.common.env_util import make_vec_env

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.genrl.grouped_pulls import ContextSeeds, context_seed, leave_one_out_advantages


def test_leave_one_out_advantages_are_each_reward_minus_the_mean_of_the_others_of_its_group():
    rewards = np.random.default_rng(0).normal(size=(6, 2))
    for pulls in (2, 3, 4):
        expected = np.empty(12)
        flat = rewards.reshape(-1)  # SB3's rows: step by step, the envs of a step in order
        for p in range(12):
            group = range(p - p % pulls, p - p % pulls + pulls)
            expected[p] = flat[p] - np.mean([flat[q] for q in group if q != p])
        got = leave_one_out_advantages(rewards, pulls)
        assert got.shape == rewards.shape
        np.testing.assert_allclose(got.reshape(-1), expected, rtol=1e-6)
    with pytest.raises(ValueError, match="multiple of 5"):
        leave_one_out_advantages(rewards, 5)


def test_context_seeds_follow_the_runs_pulls_whatever_the_number_of_envs():
    one = ContextSeeds(7, 4, 0, 1)
    two = [ContextSeeds(7, 4, index, 2) for index in range(2)]
    for pull in range(24):  # pull p: episode p // n_envs of env p % n_envs
        assert two[pull % 2](pull // 2) == one(pull) == context_seed(7, pull // 4)
    assert len({context_seed(7, group) for group in range(100)}) == 100
    assert all(0 <= context_seed(7, group) < 2**31 for group in range(100))


def _pull_order(model: GenRL, flat: np.ndarray) -> np.ndarray:
    """An array of the last rollout as SB3's ``get()`` left it (env by env) in the run's pull order (step by step, the
    envs of a step in order)."""
    n_envs = model.n_envs
    return flat.reshape(n_envs, -1, *flat.shape[1:]).swapaxes(0, 1).reshape(flat.shape)


def _contexts_and_rewards(model: GenRL) -> tuple[np.ndarray, np.ndarray]:
    """The last rollout's contexts and rewards in the run's pull order."""
    buffer = model.rollout_buffer  # SB3's get() flattened the contexts, not the rewards (n_steps, n_envs)
    return _pull_order(model, buffer.observations), buffer.rewards.reshape(-1)


@pytest.mark.parametrize("n_envs", [1, 2])
def test_each_context_is_pulled_k_times_and_each_pull_is_judged_against_the_others(n_envs):
    env = make_vec_env(lambda: LatentActionWrapper(FastReachEnv(), LinearGenerator()), n_envs=n_envs)
    model = GenRL(env, seed=0, n_steps=24 // n_envs, pulls_per_context=3).learn(48)
    contexts, rewards = _contexts_and_rewards(model)
    groups = contexts.reshape(8, 3, -1)
    assert np.all(groups == groups[:, :1])  # the three pulls of a group start from one context
    assert len({tuple(group[0]) for group in groups}) == 8  # and the groups from different ones
    assert len(set(rewards.tolist())) > 8  # from several latent actions each
    # the E-step's advantages are the leave-one-out ones, in SB3's buffer layout
    expected = (rewards.reshape(8, 3) - (rewards.reshape(8, 3).sum(1, keepdims=True) - rewards.reshape(8, 3)) / 2).reshape(-1)
    advantages = _pull_order(model, model.rollout_buffer.advantages.reshape(-1))
    np.testing.assert_allclose(advantages, expected, rtol=1e-5, atol=1e-6)


def test_the_groups_contexts_are_the_same_with_one_env_or_two():
    contexts = {}
    for n_envs in (1, 2):
        env = make_vec_env(lambda: LatentActionWrapper(FastReachEnv(), LinearGenerator()), n_envs=n_envs)
        model = GenRL(env, seed=4, n_steps=16 // n_envs, pulls_per_context=2).learn(32)
        contexts[n_envs] = _contexts_and_rewards(model)[0]
    np.testing.assert_array_equal(contexts[1], contexts[2])


def test_a_run_that_goes_on_keeps_its_groups_and_a_new_run_draws_new_contexts():
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=1, n_steps=8, pulls_per_context=2).learn(16)
    first = _contexts_and_rewards(model)[0].copy()
    model.learn(16, reset_num_timesteps=False)
    going_on = _contexts_and_rewards(model)[0]
    assert np.all(going_on.reshape(4, 2, -1) == going_on.reshape(4, 2, -1)[:, :1])
    model.learn(16)  # counted from 0 again: a new root seed, other contexts
    again = _contexts_and_rewards(model)[0]
    assert not np.array_equal(again[::2], first[::2])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"pulls_per_context": 0}, "pulls_per_context must be a positive integer, got 0"),
        ({"pulls_per_context": 3, "n_steps": 64}, r"pulls_per_context=3 needs batch_episodes = n_steps \* n_envs"),
        ({"pulls_per_context": 2, "latent_critic_kwargs": {}}, "both give the E-step its baseline"),
    ],
)
def test_pulls_per_context_that_cannot_work_are_refused_naming_the_setting(kwargs, message):
    with pytest.raises(ValueError, match=message):
        GenRL(ContextReachEnv(), LinearGenerator(), **kwargs)
