"""GenRL on a toy contextual bandit with a known optimum: convergence, logs, constructor forms, seeding, and
the train/eval modes of policies with dropout and batch norm."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from conftest import (
    ContextReachEnv,
    FastReachEnv,
    LinearGenerator,
    ReachEnv,
    optimal_latent,
)
from genrl_test_helpers import GOALS, TOY_ID
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_genrl import GenRL, LatentActionWrapper


@pytest.mark.parametrize("e_step", ["trpo", "kl_penalty"])
def test_converges_to_known_optimum(e_step):
    model = GenRL(FastReachEnv(), LinearGenerator(), e_step=e_step, seed=0)
    before = np.array([model.predict(goal, deterministic=True)[0] for goal in GOALS])
    model.learn(4800)  # 75 EM iterations of N = 64 episodes (the KL-penalty E-step is 0.06-0.17 off after 50)
    after = np.array([model.predict(goal, deterministic=True)[0] for goal in GOALS])
    optimum = np.array([optimal_latent(goal) for goal in GOALS])
    assert np.abs(before - optimum).max() > 0.5
    np.testing.assert_allclose(after, optimum, atol=0.15)
    assert model.logger.name_to_value["train/mean_reward"] > -0.25  # about -1.7 for the initial policy


def test_train_logs_and_kl_bound():
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, target_kl=0.02)
    model.learn(128)
    logs = model.logger.name_to_value
    for key in (
        "mean_reward",
        "max_reward",
        "kl",
        "entropy",
        "value_loss",
        "policy_objective",
        "line_search_success",
        "step_size",
        "accepted_fraction",
    ):
        assert np.isfinite(logs[f"train/{key}"]), key
    assert 0 < logs["train/kl"] < 0.02
    assert logs["train/max_reward"] >= logs["train/mean_reward"]


def test_constructor_forms_and_defaults():
    generator = LinearGenerator()
    for model in (
        GenRL(FastReachEnv(), generator),
        GenRL("MlpPolicy", FastReachEnv(), generator=generator),
        GenRL("MlpPolicy", FastReachEnv(), generator),
        GenRL(env=FastReachEnv(), generator=generator),
        GenRL(LatentActionWrapper(FastReachEnv(), generator)),
        GenRL(DummyVecEnv([lambda: LatentActionWrapper(FastReachEnv(), generator)] * 2)),
    ):
        assert model.generator is generator
        assert model.n_steps == 64 and model.e_step == "trpo"
        assert th.exp(model.policy.log_std).detach().cpu().numpy() == pytest.approx([1.0, 1.0])  # the prior's std
    uniform = GenRL(ContextReachEnv(), LinearGenerator(prior="uniform"))
    assert th.exp(uniform.policy.log_std).detach().cpu().numpy() == pytest.approx([3**-0.5] * 2, rel=1e-5)
    assert uniform.action_space.high.tolist() == [1.0, 1.0]
    gym.register(TOY_ID, entry_point=FastReachEnv) if TOY_ID not in gym.registry else None
    vec_env = GenRL(TOY_ID, generator).env
    assert vec_env.get_attr("generator") == [generator] and isinstance(vec_env.envs[0].unwrapped, FastReachEnv)


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="generator is needed"):
        GenRL(FastReachEnv())
    with pytest.raises(ValueError, match="LatentActionWrapper"):
        GenRL(DummyVecEnv([FastReachEnv]), LinearGenerator())
    with pytest.raises(ValueError, match="e_step"):
        GenRL(FastReachEnv(), LinearGenerator(), e_step="adam")
    with pytest.raises(TypeError, match="twice"):
        GenRL(FastReachEnv(), LinearGenerator(), generator=LinearGenerator())
    with pytest.raises(ValueError, match=r"\(2, 5, 2\).*\(2, 7, 2\)"):
        GenRL(LatentActionWrapper(FastReachEnv(episode_length=7), LinearGenerator(horizon=7)), LinearGenerator())


def test_works_with_step_by_step_env_and_n_envs():
    env = DummyVecEnv(
        [
            lambda: LatentActionWrapper(
                ReachEnv(), LinearGenerator(), context=lambda obs: obs[:2], context_space=ContextReachEnv.context_space
            )
        ]
        * 2
    )
    model = GenRL(env, e_step="kl_penalty", n_steps=16, seed=1).learn(64)
    assert model.num_timesteps == 64 and model.rollout_buffer.buffer_size * model.n_envs == 32


@pytest.mark.parametrize("n_envs", [1, 2])
def test_batch_episodes_is_n_steps_times_n_envs(n_envs, tmp_path):
    generator = LinearGenerator()
    model = GenRL(DummyVecEnv([lambda: LatentActionWrapper(FastReachEnv(), generator)] * n_envs), n_steps=8, seed=0)
    assert model.batch_episodes == 8 * n_envs
    model.learn(model.batch_episodes)  # one iteration plays batch_episodes episodes
    assert model.num_timesteps == model.batch_episodes and model._n_updates == 1
    with pytest.raises(AttributeError):
        model.batch_episodes = 3  # read-only: n_steps and the env set it
    model.save(tmp_path / "model.zip")
    assert GenRL.load(tmp_path / "model.zip", generator=generator).batch_episodes == 8 * n_envs


def test_same_seed_same_run():
    runs = []
    for _ in range(2):
        model = GenRL(FastReachEnv(), LinearGenerator(), seed=7).learn(192)
        runs.append(
            (th.nn.utils.parameters_to_vector(model.policy.parameters()).detach(), model.rollout_buffer.actions.copy())
        )
    th.testing.assert_close(runs[0][0], runs[1][0], rtol=0, atol=0)
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    other = GenRL(FastReachEnv(), LinearGenerator(), seed=8).learn(192)
    assert not np.array_equal(other.rollout_buffer.actions, runs[0][1])


class FlattenBatchNormDropoutExtractor(BaseFeaturesExtractor):
    """Stable-Baselines3's test extractor (tests/test_train_eval_mode.py): batch norm, then dropout."""

    def __init__(self, observation_space: gym.Space) -> None:
        super().__init__(observation_space, get_flattened_obs_dim(observation_space))
        self.flatten = th.nn.Flatten()
        self.batch_norm = th.nn.BatchNorm1d(self._features_dim)
        self.dropout = th.nn.Dropout(0.5)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.dropout(self.batch_norm(self.flatten(observations)))


BATCH_NORM_DROPOUT = {"net_arch": [16, 16], "features_extractor_class": FlattenBatchNormDropoutExtractor}


def batch_norm_stats(model: GenRL) -> tuple[th.Tensor, th.Tensor]:
    batch_norm = model.policy.features_extractor.batch_norm
    return batch_norm.bias.detach().clone(), batch_norm.running_mean.clone()


def mean_reward_on_goals(model: GenRL) -> float:
    latents, _ = model.predict(GOALS, deterministic=True)
    rewards, _ = FastReachEnv().play_trajectories(LinearGenerator().decode(latents), GOALS)
    return float(np.mean(rewards))


@pytest.mark.parametrize("e_step", ["trpo", "kl_penalty"])
@pytest.mark.parametrize("seed", range(5))
def test_train_with_dropout_and_batch_norm(e_step, seed):
    """SB3's train/eval-mode test for GenRL: the E-step sees the policy in evaluation mode, training works."""
    model = GenRL(FastReachEnv(), LinearGenerator(), e_step=e_step, policy_kwargs=BATCH_NORM_DROPOUT, seed=seed)
    bias_before, running_mean_before = batch_norm_stats(model)
    before = mean_reward_on_goals(model)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no float() of a tensor that requires grad, no invalid distribution
        model.learn(1280)
    bias_after, running_mean_after = batch_norm_stats(model)
    assert not th.isclose(bias_before, bias_after).all() and not th.isclose(running_mean_before, running_mean_after).all()
    assert all(bool(th.isfinite(p).all()) for p in model.policy.parameters())
    assert before < -0.35 and mean_reward_on_goals(model) > -0.1  # the optimum is 0
    if e_step == "trpo":
        assert model.logger.name_to_value["train/kl"] < model.target_kl


def test_collect_rollouts_and_predict_leave_batch_norm_alone_and_predict_is_deterministic():
    model = GenRL(FastReachEnv(), LinearGenerator(), policy_kwargs=BATCH_NORM_DROPOUT, n_steps=64, seed=1)
    stats_before = batch_norm_stats(model)
    _, callback = model._setup_learn(total_timesteps=128)
    for _ in range(2):
        model.collect_rollouts(model.get_env(), callback, model.rollout_buffer, n_rollout_steps=model.n_steps)
    first, _ = model.predict(GOALS, deterministic=True)
    for _ in range(5):
        np.testing.assert_array_equal(model.predict(GOALS, deterministic=True)[0], first)
    for before, after in zip(stats_before, batch_norm_stats(model), strict=True):
        th.testing.assert_close(before, after, rtol=0, atol=0)
