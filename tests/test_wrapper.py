"""Tests of sb3_genrl.wrappers.LatentActionWrapper on toy reaching tasks with a known optimum (``conftest.py``)."""

from __future__ import annotations

import re
import warnings

import gymnasium as gym
import numpy as np
import pytest
from conftest import ContextReachEnv, FastReachEnv, LinearGenerator, ReachEnv, optimal_latent
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from sb3_genrl import LatentActionWrapper
from sb3_genrl.generative import TrajectoryGenerator


def checked_without_warnings(env: gym.Env, allowed: tuple[str, ...] = ()) -> None:
    """Run Gymnasium's check_env and fail on any warning outside ``allowed`` (as Gymnasium's own tests do)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym_check_env(env, skip_render_check=True)
    unexpected = [str(w.message) for w in caught if not any(re.search(a, str(w.message)) for a in allowed)]
    assert not unexpected, unexpected


NORMALIZED_BOX = "we recommend using a symmetric and normalized space"  # the +-3 sigma box of a normal prior
# Gymnasium's checker notes that it is given a wrapper; LatentActionWrapper is one by design.
IS_A_WRAPPER = "is different from the unwrapped version"


@pytest.mark.parametrize("env_class", [ReachEnv, ContextReachEnv, FastReachEnv])
@pytest.mark.parametrize("prior", ["normal", "uniform"])
def test_check_env(env_class, prior):
    env = LatentActionWrapper(env_class(), LinearGenerator(prior=prior))
    checked_without_warnings(env, allowed=(IS_A_WRAPPER, NORMALIZED_BOX) if prior == "normal" else (IS_A_WRAPPER,))
    with warnings.catch_warnings():
        warnings.simplefilter("error" if prior == "uniform" else "ignore")
        sb3_check_env(env)


def test_spaces_and_context():
    normal = LatentActionWrapper(FastReachEnv(), LinearGenerator(prior="normal"), latent_clip=2.5)
    assert normal.action_space == spaces.Box(-2.5, 2.5, shape=(2,), dtype=np.float32)
    assert normal.observation_space == FastReachEnv.context_space
    obs, _ = normal.reset(seed=0, options={"goal": [0.3, -0.2]})
    np.testing.assert_allclose(obs, [0.3, -0.2], rtol=1e-6)
    uniform = LatentActionWrapper(ReachEnv(), LinearGenerator(prior="uniform"))
    assert uniform.action_space == spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
    assert uniform.reset(seed=0)[0].shape == (4,)  # no context interface: the reset observation
    goal_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
    custom = LatentActionWrapper(ReachEnv(), LinearGenerator(), context=lambda obs: obs[:2], context_space=goal_space)
    obs, _ = custom.reset(seed=0, options={"goal": [0.5, 0.5]})
    np.testing.assert_allclose(obs, [0.5, 0.5])
    with pytest.raises(ValueError, match="context_space"):
        LatentActionWrapper(ReachEnv(), LinearGenerator(), context=lambda o: o[:2])


@pytest.mark.parametrize("env_class", [ReachEnv, FastReachEnv])
def test_optimal_latent_gets_maximal_reward(env_class):
    env = LatentActionWrapper(env_class(), LinearGenerator())
    for goal in ([0.5, -0.3], [-0.7, 0.2]):
        env.reset(seed=1, options={"goal": goal})
        _, reward, terminated, truncated, info = env.step(optimal_latent(goal))
        assert (terminated, truncated) == (True, False)
        assert reward == pytest.approx(0.0, abs=1e-10)
        assert info["fast_path"] == (env_class is FastReachEnv)
        assert info["steps_played"] == 5 and not info["latent_clipped"]
        np.testing.assert_allclose(info["reached"], goal, atol=1e-6)


def test_fast_path_matches_step_by_step():
    alpha = np.array([0.7, -1.3], dtype=np.float32)
    rewards = []
    for use_fast_path in (True, False):
        env = LatentActionWrapper(FastReachEnv(), LinearGenerator(), use_fast_path=use_fast_path)
        env.reset(seed=3)
        rewards.append(env.step(alpha)[1])
    assert rewards[0] == pytest.approx(rewards[1], rel=1e-6)
    env = LatentActionWrapper(FastReachEnv(), LinearGenerator())
    batch_rewards, infos = env.play_batch(np.stack([alpha, alpha]), np.array([[0.0, 0.0], [0.5, 0.5]]))
    assert batch_rewards.shape == (2,) and len(infos) == 2
    reached = LinearGenerator().decode(alpha).sum(axis=1)[0]
    np.testing.assert_allclose(batch_rewards[1], -np.sum((reached - 0.5) ** 2), rtol=1e-5)


def test_shape_mismatch_names_both_shapes():
    with pytest.raises(ValueError, match=r"\(5, 3\).*\(2,\)"):
        LatentActionWrapper(ReachEnv(), _ThreeJointGenerator())


class _ThreeJointGenerator(LinearGenerator):
    def __init__(self) -> None:
        TrajectoryGenerator.__init__(self, horizon=5, action_dim=3, latent_dim=2, prior="normal")


@pytest.mark.parametrize("bad", [[np.nan, 0.0], [0.0, np.inf]])
def test_non_finite_latent_raises(bad):
    env = LatentActionWrapper(FastReachEnv(), LinearGenerator())
    env.reset(seed=0)
    with pytest.raises(ValueError, match="non-finite"):
        env.step(np.array(bad, dtype=np.float32))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3, dtype=np.float32))


def test_latent_clipping_reported():
    env = LatentActionWrapper(FastReachEnv(), LinearGenerator(), latent_clip=3.0)
    env.reset(seed=0)
    *_, info = env.step(np.array([5.0, 0.0], dtype=np.float32))
    assert info["latent_clipped"]
    env.reset(seed=0)
    clipped_reward = env.step(np.array([3.0, 0.0], dtype=np.float32))[1]
    env.reset(seed=0)
    assert env.step(np.array([7.0, 0.0], dtype=np.float32))[1] == pytest.approx(clipped_reward)


def test_reward_sum_vs_last_and_hold():
    goal, alpha = [0.2, 0.1], np.array([0.3, 0.4], dtype=np.float32)
    reached = LinearGenerator().decode(alpha).sum(axis=1)[0]
    hold = np.array([0.1, 0.0], dtype=np.float32)
    last = LatentActionWrapper(ReachEnv(episode_length=8, step_cost=0.5), LinearGenerator(), hold_action=hold)
    total = LatentActionWrapper(ReachEnv(episode_length=8, step_cost=0.5), LinearGenerator(), reward="sum", hold_action=hold)
    results = []
    for env in (last, total):
        env.reset(seed=0, options={"goal": goal})
        results.append(env.step(alpha))
    terminal = -np.sum((reached + [0.3, 0.0] - goal) ** 2)  # 3 hold steps of (0.1, 0)
    assert results[0][1] == pytest.approx(terminal, rel=1e-5)
    assert results[1][1] == pytest.approx(terminal - 7 * 0.5, rel=1e-5)
    assert results[0][4]["hold_steps"] == 3 and results[0][4]["steps_played"] == 5 and results[0][4]["ended"]
    # An episode that does not end is held for max_hold_steps and reported as not ended.
    endless = LatentActionWrapper(ReachEnv(episode_length=100), LinearGenerator(), max_hold_steps=4)
    endless.reset(seed=0)
    *_, info = endless.step(alpha)
    assert info["hold_steps"] == 4 and not info["ended"]
    # An episode shorter than the trajectory stops early.
    short = LatentActionWrapper(ReachEnv(episode_length=3), LinearGenerator())
    short.reset(seed=0)
    assert short.step(alpha)[4]["steps_played"] == 3


def test_seeded_reset_and_step_without_reset():
    env = LatentActionWrapper(FastReachEnv(), LinearGenerator())
    first = env.reset(seed=42)[0]
    np.testing.assert_array_equal(first, env.reset(seed=42)[0])
    env.step(env.action_space.sample())
    with pytest.raises(RuntimeError, match="reset"):
        env.step(env.action_space.sample())


@pytest.mark.parametrize("algo", ["PPO", "SAC", "TRPO"])
def test_sb3_algorithms_train_on_wrapped_env(algo):
    from sb3_contrib import TRPO
    from stable_baselines3 import PPO, SAC

    env = LatentActionWrapper(FastReachEnv(), LinearGenerator())
    if algo == "SAC":
        model = SAC("MlpPolicy", env, learning_starts=50, batch_size=32, seed=0)
    else:
        model = {"PPO": PPO, "TRPO": TRPO}[algo]("MlpPolicy", env, n_steps=64, batch_size=32, seed=0)
    model.learn(200)
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert action.shape == (2,) and np.all(np.isfinite(action))


@pytest.mark.parametrize("task", ["GenRL/Hockey-v0", "GenRL/Basketball-v0"])
def test_on_paper_tasks(task):
    """The wrapper over the paper's tasks (untrained beta-VAE): env checks, and fast path == step-by-step path."""
    from sb3_genrl.generative import make_generator

    horizon = gym.make(task).unwrapped.horizon
    generator = make_generator("VAE1", horizon=horizon, action_dim=7, device="cpu")
    env = LatentActionWrapper(gym.make(task), generator)
    assert env.use_fast_path and env.observation_space == env.env.unwrapped.context_space
    checked_without_warnings(env, allowed=(IS_A_WRAPPER, NORMALIZED_BOX))
    alpha = np.full(generator.latent_dim, 0.5, dtype=np.float32)
    slow = LatentActionWrapper(gym.make(task), generator, use_fast_path=False)
    env.reset(seed=3)
    slow.reset(seed=3)
    fast_result, slow_result = env.step(alpha), slow.step(alpha)
    assert fast_result[1] == slow_result[1]
    assert fast_result[4]["steps_played"] == slow_result[4]["steps_played"] == horizon


def test_fast_path_reward_equals_the_step_path_reward_exactly_through_the_wrapper():
    """The fast path plays the task's own float64 goal, not the float32 context the policy observes."""
    from sb3_genrl.generative import make_generator

    generator = make_generator("VAE1", horizon=69, action_dim=7, device="cpu")
    fast = LatentActionWrapper(gym.make("GenRL/Hockey-v0"), generator)
    slow = LatentActionWrapper(gym.make("GenRL/Hockey-v0"), generator, use_fast_path=False)
    alphas = generator.sample_prior(4, rng=0)
    for seed, alpha in enumerate(alphas):
        goal = fast.reset(seed=seed)[0]
        slow.reset(seed=seed)
        assert fast.unwrapped.goal.astype(np.float32).tolist() == goal.tolist() != fast.unwrapped.goal.tolist()
        fast_reward, slow_reward = fast.step(alpha)[1], slow.step(alpha)[1]
        assert fast_reward == slow_reward, seed


def test_generator_of_another_horizon_is_refused_when_the_wrapper_is_built(tmp_path):
    from sb3_genrl import GenRL
    from sb3_genrl.generative import make_generator
    from sb3_genrl.run import train_policy

    generator = make_generator("VAE1", horizon=68, action_dim=7, device="cpu")
    for use_fast_path in (None, False):
        with pytest.raises(ValueError, match="horizon T = 68 .* HockeyEnv has horizon 69"):
            LatentActionWrapper(gym.make("GenRL/Hockey-v0"), generator, use_fast_path=use_fast_path)
    with pytest.raises(ValueError, match="horizon"):
        GenRL("GenRL/Hockey-v0", generator)
    with pytest.raises(ValueError, match="horizon"):
        train_policy("hockey", generator, episodes=8, out_dir=tmp_path / "run", progress_bar=False)
    assert not (tmp_path / "run").exists()


class SeedOnlyResetEnv(ReachEnv):
    """An env whose ``reset`` takes no ``options`` (older code): the wrapper must not pass ``options=None``."""

    def reset(self, *, seed=None):  # type: ignore[override]
        return super().reset(seed=seed)


def test_wrapper_is_a_gymnasium_wrapper():
    task = FastReachEnv()
    env = LatentActionWrapper(task, LinearGenerator())
    assert isinstance(env, gym.Wrapper) and env.unwrapped is task and env.env is task
    assert env.get_wrapper_attr("episode_length") == 5 and env.metadata is task.metadata
    assert env.reset(seed=0, options={"goal": [0.25, 0.5]})[0].tolist() == [0.25, 0.5]
    plain = LatentActionWrapper(SeedOnlyResetEnv(), LinearGenerator())
    assert plain.reset(seed=0)[0].shape == (4,)
    assert plain.step(np.zeros(2, dtype=np.float32))[2]


def test_the_spec_records_the_generator_itself_and_rebuilds_the_wrapped_env(monkeypatch):
    monkeypatch.setitem(gym.registry, "Test/FastReach-v0", gym.envs.registration.EnvSpec("Test/FastReach-v0", FastReachEnv))
    generator = LinearGenerator()
    env = LatentActionWrapper(gym.make("Test/FastReach-v0"), generator, latent_clip=2.0)
    recorded = env.spec.additional_wrappers[-1]
    # the generator object, not a copy of it per env (a batched VecEnv holds one wrapper per episode of an iteration)
    assert recorded.kwargs["generator"] is generator and recorded.kwargs["latent_clip"] == 2.0
    rebuilt = env.spec.make()
    assert isinstance(rebuilt, LatentActionWrapper) and rebuilt.generator is generator and rebuilt.latent_clip == 2.0
    alpha = np.array([0.3, -0.2], dtype=np.float32)
    goal = {"goal": [0.25, 0.5]}
    rewards = [wrapped.reset(seed=0, options=goal) and wrapped.step(alpha)[1] for wrapped in (env, rebuilt)]
    assert rewards[0] == rewards[1]


def _hockey_with_frames(generator):
    from sb3_genrl.envs.hockey import HockeyEnv

    return LatentActionWrapper(HockeyEnv(render_mode="rgb_array", width=64, height=48), generator)


def test_subproc_vec_env_reaches_the_task_through_the_wrapper():
    from sb3_genrl.envs.arm import FRAME_SKIP
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    from sb3_genrl.generative import make_generator

    generator = make_generator("VAE1", horizon=69, action_dim=7, device="cpu")
    env = make_vec_env(lambda: _hockey_with_frames(generator), n_envs=2, vec_env_cls=SubprocVecEnv)
    try:
        assert env.get_attr("frame_skip") == [FRAME_SKIP, FRAME_SKIP]
        assert env.get_attr("render_mode") == ["rgb_array"] * 2 and env.render_mode == "rgb_array"
        observations = env.reset()
        contexts = env.env_method("get_context")
        np.testing.assert_array_equal(np.stack(contexts), observations)
        frame = env.render()
        assert frame is not None and frame.dtype == np.uint8 and frame.shape == (96, 64, 3) and frame.std() > 5  # 2 x 1 tiles
        _, rewards, dones, infos = env.step(np.zeros((2, generator.latent_dim), dtype=np.float32))
        assert dones.all() and all(info["fast_path"] for info in infos) and np.all(np.isfinite(rewards))
    finally:
        env.close()


class NanRewardEnv(ReachEnv):
    """A reaching task whose terminal reward is NaN on every ``every``-th episode."""

    every = 5

    def reset(self, *, seed=None, options=None):
        self.episodes = getattr(self, "episodes", 0) + 1
        return super().reset(seed=seed, options=options)

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        if terminated and self.episodes % self.every == 0:
            reward = float("nan")
        return obs, reward, terminated, truncated, info


class FastNanRewardEnv(FastReachEnv):
    """The fast-path reaching task with an infinite reward for the third trajectory it plays."""

    def play_trajectories(self, trajectories, goals, *, n_threads=1):
        self.played = getattr(self, "played", 0) + len(trajectories)
        rewards, infos = super().play_trajectories(trajectories, goals, n_threads=n_threads)
        if self.played == 3:
            rewards = np.full_like(rewards, -np.inf)
        return rewards, infos


def test_non_finite_reward_refused_at_the_pull_that_returns_it():
    from sb3_genrl import GenRL

    env = LatentActionWrapper(NanRewardEnv(), LinearGenerator())
    for _ in range(4):
        env.reset(seed=0)
        assert np.isfinite(env.step(np.zeros(2, dtype=np.float32))[1])
    env.reset(seed=0)
    expected = r"NanRewardEnv returned the non-finite reward nan for the latent action \[0.0, 0.0\]"
    with pytest.raises(ValueError, match=expected):
        env.step(np.zeros(2, dtype=np.float32))
    fast = LatentActionWrapper(FastNanRewardEnv(), LinearGenerator())
    for _ in range(2):
        fast.reset(seed=0)
        fast.step(np.zeros(2, dtype=np.float32))
    fast.reset(seed=0)
    with pytest.raises(ValueError, match="FastNanRewardEnv returned the non-finite reward -inf"):
        fast.step(np.zeros(2, dtype=np.float32))
    # GenRL stops at that pull instead of training on it (it used to learn nothing and return normally)
    with pytest.raises(ValueError, match="non-finite reward nan"):
        GenRL(NanRewardEnv(), LinearGenerator(), n_steps=8, seed=0).learn(64)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "3"])
def test_latent_clip_must_be_a_finite_positive_number(bad):
    with pytest.raises(ValueError, match=f"latent_clip must be a finite number > 0, got {re.escape(repr(bad))}"):
        LatentActionWrapper(FastReachEnv(), LinearGenerator(), latent_clip=bad)


def test_a_goal_env_compute_reward_of_the_wrong_shape_is_named_with_the_shape_expected():
    """A compute_reward that returns one reward per coordinate (a missing sum) is named, with the shape it returned and
    the one expected (it used to fail with "can only convert an array of size 1 to a Python scalar")."""
    from test_fetch_goal_api import PointGoalEnv

    class PerCoordinateReward(PointGoalEnv):
        def compute_reward(self, achieved_goal, desired_goal, info):
            return -np.abs(np.asarray(achieved_goal) - desired_goal)

        def step(self, action):  # the step's own reward, summed: only the relabelled pulls see the wrong shape
            self.position, self.t = self.position + np.asarray(action, dtype=np.float64), self.t + 1
            reward = float(self.compute_reward(self.position, self.goal, None).sum())
            return self._obs(), reward, False, self.t >= self.episode_length, {}

    env = LatentActionWrapper(PerCoordinateReward(), LinearGenerator())
    env.reset(seed=0)
    with pytest.raises(
        ValueError,
        match=r"PerCoordinateReward.compute_reward\(achieved_goal, desired_goal, info\) returned shape \(2,\) for one "
        r"achieved goal of shape \(2,\) and one desired goal: expected one reward \(shape \(\) or \(1,\)\)",
    ):
        env.step(np.ones(2, dtype=np.float32))
