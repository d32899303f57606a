"""Goal-conditioned envs (Gymnasium-Robotics' GoalEnv convention) through LatentActionWrapper and GenRL, on a small
GoalEnv that the package does not ship: the context, the hindsight derived from compute_reward, the success rate in
the logs, the policy chosen for a Dict context, and GenRL learning from the sparse 0/-1 reward."""

import csv

import gymnasium as gym
import numpy as np
import pytest
from conftest import C, LinearGenerator, R
from gymnasium import spaces
from stable_baselines3.common.logger import configure

from sb3_genrl import GenRL, LatentActionWrapper

THRESHOLD = 0.1


class PointGoalEnv(gym.Env):
    """A point moved by per-step velocities from a random start towards a random goal; the sparse reward of the Fetch
    tasks (``-(distance > 0.1)`` at every step) and ``info["is_success"]``."""

    metadata = {"render_modes": []}

    def __init__(self, episode_length: int = 5) -> None:
        self.episode_length = episode_length
        box = spaces.Box(-3.0, 3.0, shape=(2,), dtype=np.float64)
        self.observation_space = spaces.Dict(
            {"observation": spaces.Box(-3.0, 3.0, shape=(4,), dtype=np.float64), "achieved_goal": box, "desired_goal": box}
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def compute_reward(self, achieved_goal, desired_goal, info):
        return -(np.linalg.norm(np.asarray(achieved_goal) - desired_goal, axis=-1) > THRESHOLD).astype(np.float32)

    def _obs(self):
        return {
            "observation": np.concatenate([self.position, self.start]),
            "achieved_goal": self.position.copy(),
            "desired_goal": self.goal.copy(),
        }

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.start = self.np_random.uniform(-0.5, 0.5, 2)
        self.position, self.goal, self.t = self.start.copy(), self.np_random.uniform(-1.0, 1.0, 2), 0
        return self._obs(), {}

    def step(self, action):
        self.position = self.position + np.asarray(action, dtype=np.float64)
        self.t += 1
        info = {"is_success": float(np.linalg.norm(self.position - self.goal) <= THRESHOLD)}
        reward = float(self.compute_reward(self.position, self.goal, info))
        return self._obs(), reward, False, self.t >= self.episode_length, info


@pytest.mark.parametrize("reward", ["last", "sum"])
def test_context_and_hindsight_come_from_the_goal_env_api(reward):
    env = LatentActionWrapper(PointGoalEnv(), LinearGenerator(), reward=reward)
    assert env.observation_space.shape == (6,)
    rng = np.random.default_rng(0)
    for seed in range(6):
        context, _ = env.reset(seed=seed)
        task = env.unwrapped
        np.testing.assert_allclose(context, np.concatenate([task.goal, task.start, task.start]), rtol=1e-6)
        alpha = rng.normal(size=2).astype(np.float32)
        _, r, terminated, _, info = env.step(alpha)
        # independently: replay the trajectory, then score every step for the last achieved goal
        positions = task.start + np.cumsum(env.trajectory(alpha).astype(np.float64), axis=0)
        np.testing.assert_allclose(task.position, positions[-1])
        scored = task.compute_reward(positions, positions[-1], None)
        relabelled, relabelled_reward = info["hindsight"]
        np.testing.assert_allclose(relabelled, np.concatenate([positions[-1], task.start, task.start]), rtol=1e-6)
        assert relabelled_reward == (scored[-1] if reward == "last" else scored.sum())
        assert reward == "sum" or relabelled_reward == 0.0  # the last achieved goal is always reached
        assert terminated and info["is_success"] == float(np.linalg.norm(positions[-1] - task.goal) <= THRESHOLD)
        own = task.compute_reward(positions, task.goal, None)
        assert r == (own[-1] if reward == "last" else own.sum())


def test_a_pull_that_leaves_the_achieved_goal_where_it_started_is_not_relabelled():
    env = LatentActionWrapper(PointGoalEnv(), LinearGenerator())
    for displacement, relabelled in ((0.0, False), (0.6 * THRESHOLD, False), (3.0 * THRESHOLD, True)):
        context, _ = env.reset(seed=3)
        # the latent action whose trajectory moves the point by `displacement` along x: R alpha + C = (d, 0)
        alpha = np.linalg.solve(R, np.array([displacement, 0.0]) - C).astype(np.float32)
        _, _, _, _, info = env.step(alpha)
        moved = np.linalg.norm(env.unwrapped.position - env.unwrapped.start)
        assert moved == pytest.approx(displacement, abs=1e-5)
        assert (info["hindsight"] is not None) == relabelled, displacement


def test_genrl_picks_multi_input_policy_for_a_dict_context():
    class DictEnv(gym.ObservationWrapper):  # other keys than a goal env's: the context is the Dict reset observation
        def __init__(self, env):
            super().__init__(env)
            self.observation_space = spaces.Dict(
                {"position": env.observation_space["achieved_goal"], "goal": env.observation_space["desired_goal"]}
            )

        def observation(self, observation):
            return {"position": observation["achieved_goal"], "goal": observation["desired_goal"]}

    env = LatentActionWrapper(DictEnv(PointGoalEnv()), LinearGenerator())
    assert isinstance(env.observation_space, spaces.Dict)
    model = GenRL(env, n_steps=4, seed=0, device="cpu")
    assert type(model.policy).__name__ == "MultiInputActorCriticPolicy"
    model.learn(8)


def test_genrl_learns_from_the_sparse_reward_and_logs_the_success_rate(tmp_path):
    env = LatentActionWrapper(PointGoalEnv(), LinearGenerator())
    model = GenRL(
        env, n_steps=16, batch_size=16, seed=0, device="cpu", hindsight_kwargs={"history": 60, "regression_steps": 64}
    )
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(800)
    with open(tmp_path / "progress.csv") as file:
        logged = np.array([float(row["rollout/success_rate"]) for row in csv.DictReader(file)])
    assert len(logged) == 800 // 16 and logged[0] < 0.3
    assert np.all((logged >= 0) & (logged <= 1))
    # the deterministic policy on new starts and goals, against the exact answer R alpha + C = goal - start
    successes = []
    for seed in range(1000, 1100):
        context, _ = env.reset(seed=seed)
        alpha = model.predict(context, deterministic=True)[0]
        successes.append(env.step(alpha)[4]["is_success"])
        assert np.linalg.norm(R @ alpha + C - (env.unwrapped.goal - env.unwrapped.start)) < 1.0
    assert np.mean(successes) >= 0.8


def test_the_prior_rollout_plays_a_goal_env_through_the_step_path_from_each_contexts_reset():
    from sb3_genrl.metrics.prior_rollout import prior_rollout

    generator, seed, contexts, draws = LinearGenerator(), 5, 8, 60
    result = prior_rollout(generator, PointGoalEnv(), contexts=contexts, draws=draws, seed=seed)
    # independently: each context is the reset of seed + g, each draw's end point is start + the sum of its actions
    alphas = np.clip(
        generator.sample_prior(contexts * draws, np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])), -3, 3
    )  # GenRL's action box
    task, best, solved = PointGoalEnv(), [], []
    for g in range(contexts):
        task.reset(seed=seed + g)
        ends = task.start + np.array(
            [generator.decode(alpha[None])[0].astype(np.float64).sum(axis=0) for alpha in alphas[g * draws : (g + 1) * draws]]
        )
        hit = np.linalg.norm(ends - task.goal, axis=1) <= THRESHOLD
        best.append(0.0 if hit.any() else -1.0)
        solved.append(bool(hit.any()))
    assert 0 < sum(solved) < contexts  # both kinds of context, so that the comparison means something
    np.testing.assert_array_equal(result.best, best)
    np.testing.assert_array_equal(result.solved, solved)
    summary = result.summary()
    assert summary["prior_success"] == np.mean(solved) and summary["prior_episodes"] == contexts * draws
    assert summary["prior_mean"] == np.mean(best)
    with pytest.raises(ValueError, match="contexts must be a count"):
        prior_rollout(generator, PointGoalEnv(), contexts=np.zeros((2, 2)), draws=2)
