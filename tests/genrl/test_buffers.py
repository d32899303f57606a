"""GenRL's rollout buffers (sb3_genrl/genrl/buffers.py): a non-finite reward is refused where it enters GenRL, whatever
wrapper or VecEnv wrapper made it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from conftest import FastReachEnv, LinearGenerator, ReachEnv
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.genrl.buffers import FiniteRewardDictRolloutBuffer, FiniteRewardRolloutBuffer


class _NanOnThirdPull(gym.Wrapper):
    """A reward transform outside the latent-action wrapper that makes the third pull's reward NaN."""

    pulls = 0

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.pulls += 1
        return obs, float("nan") if self.pulls == 3 else reward, terminated, truncated, info


class _InfOnSecondStep(VecEnvWrapper):
    """A VecEnv wrapper that makes the second env's reward -inf at the second step."""

    steps = 0

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        self.steps += 1
        if self.steps == 2:
            rewards = rewards.copy()
            rewards[1] = -np.inf
        return obs, rewards, dones, infos


def test_a_nan_reward_from_a_wrapper_outside_the_latent_action_wrapper_is_refused_by_learn():
    """LatentActionWrapper refuses the task's own NaN; one added above it used to be taken in by learn(), which then
    learnt nothing and returned normally."""
    model = GenRL(_NanOnThirdPull(LatentActionWrapper(FastReachEnv(), LinearGenerator())), n_steps=16, seed=0)
    assert isinstance(model.rollout_buffer, FiniteRewardRolloutBuffer)
    with pytest.raises(ValueError, match=r"the env returned the non-finite reward nan \(env 0 of 1\) for the latent action"):
        model.learn(32)
    assert model.num_timesteps == 3  # refused at the pull that returned it


def test_a_non_finite_reward_from_a_vec_env_wrapper_is_refused_naming_its_env():
    generator = LinearGenerator()
    venv = _InfOnSecondStep(DummyVecEnv([lambda: LatentActionWrapper(FastReachEnv(), generator)] * 2))
    with pytest.raises(ValueError, match=r"the env returned the non-finite reward -inf \(env 1 of 2\)"):
        GenRL(venv, n_steps=8, seed=0).learn(32)


def test_a_dict_context_gets_the_checking_dict_buffer():
    dict_env = LatentActionWrapper(
        ReachEnv(),
        LinearGenerator(),
        context=lambda obs: {"goal": obs[:2]},
        context_space=gym.spaces.Dict({"goal": gym.spaces.Box(-1, 1, (2,))}),
    )
    model = GenRL(_NanOnThirdPull(dict_env), n_steps=8, seed=0)
    assert isinstance(model.rollout_buffer, FiniteRewardDictRolloutBuffer)
    with pytest.raises(ValueError, match=r"non-finite reward nan \(env 0 of 1\)"):
        model.learn(16)
