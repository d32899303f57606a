"""GenRL on your own Gymnasium task with a hand-written generator (runs in well under a minute on a CPU).

The task: a point mass on a plane, moved by per-step velocity commands, must stop on a goal; the only reward is
the terminal one, ``-distance(position, goal)``. The generator: a family of smooth reaching motions (minimum-jerk
velocity profiles) with a 2-D latent action, the end point of the reach. GenRL learns which motion to pick for each
goal. Nothing here comes from the paper's tasks: any episodic env with per-step actions of shape ``(M,)`` works.

    python examples/custom_env.py
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.generative import TrajectoryGenerator


class PointReachEnv(gym.Env):
    """A point mass with velocity control; goal uniform in the annulus 0.3 <= r <= 1.2 around the start.

    Observation: goal (2), position (2). Action: velocity (2) in [-0.2, 0.2] per step. 30 steps per episode.
    Reward: 0, then ``-||position - goal||`` at the last step.
    """

    metadata = {"render_modes": []}
    horizon = 30

    def __init__(self) -> None:
        self.action_space = spaces.Box(-0.2, 0.2, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Box(-5.0, 5.0, shape=(4,), dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        radius, angle = self.np_random.uniform(0.3, 1.2), self.np_random.uniform(-np.pi, np.pi)
        self.goal = radius * np.array([np.cos(angle), np.sin(angle)])
        self.position, self.t = np.zeros(2), 0
        return self._obs(), {}

    def _obs(self):
        return np.concatenate([self.goal, self.position]).astype(np.float32)

    def step(self, action):
        self.position = self.position + np.clip(action, -0.2, 0.2)
        self.t += 1
        terminated = self.t >= self.horizon
        reward = -float(np.linalg.norm(self.position - self.goal)) if terminated else 0.0
        return self._obs(), reward, terminated, False, {}


class ReachingPrimitives(TrajectoryGenerator):
    """Minimum-jerk straight reaches to the end point ``1.3 * alpha``, ``alpha`` in [-1, 1]^2 (a uniform prior)."""

    def __init__(self, horizon: int = 30) -> None:
        super().__init__(horizon=horizon, action_dim=2, latent_dim=2, prior="uniform")
        s = np.linspace(0.0, 1.0, horizon + 1)
        position = 10 * s**3 - 15 * s**4 + 6 * s**5  # minimum-jerk profile from 0 to 1
        self.profile = np.diff(position)  # per-step displacement fractions, summing to 1

    def decode(self, alpha: np.ndarray) -> np.ndarray:
        alpha = self.check_latent(alpha).astype(np.float64)
        end_point = 1.3 * alpha  # (n, 2)
        return (self.profile[None, :, None] * end_point[:, None, :]).astype(np.float32)  # (n, T, 2)

    def save(self, path: str) -> None:
        raise NotImplementedError("ReachingPrimitives has no weights; pass generator= to GenRL.load")


def evaluate(model: GenRL, env: LatentActionWrapper, n: int = 50) -> float:
    """Mean terminal reward of the deterministic policy on ``n`` fresh goals."""
    rewards = []
    for episode in range(n):
        context, _ = env.reset(seed=10_000 + episode)
        alpha, _ = model.predict(context, deterministic=True)
        rewards.append(env.step(alpha)[1])
    return float(np.mean(rewards))


def main() -> None:
    th.set_num_threads(1)  # small networks: one thread is fastest on a shared CPU
    generator = ReachingPrimitives(horizon=PointReachEnv.horizon)
    # The env has no get_context(): say which part of the reset observation is the task context (the goal).
    goal_space = spaces.Box(-1.2, 1.2, shape=(2,), dtype=np.float32)
    env = LatentActionWrapper(PointReachEnv(), generator, context=lambda obs: obs[:2], context_space=goal_space)
    model = GenRL(env, seed=0)
    print(f"before training: mean reward {evaluate(model, env):.3f}")
    model.learn(total_timesteps=64 * 60)  # 60 EM iterations of 64 episodes
    print(f"after {model.num_timesteps} episodes: mean reward {evaluate(model, env):.3f}")

    with tempfile.TemporaryDirectory() as folder:
        model.save(Path(folder) / "reach_policy.zip")
        loaded = GenRL.load(Path(folder) / "reach_policy.zip", generator=generator)
    goal = np.array([0.6, -0.4], dtype=np.float32)
    trajectory = loaded.predict_trajectory(goal)
    print(f"goal {goal} -> trajectory {trajectory.shape}, end point {trajectory.sum(axis=0).round(3)}")


if __name__ == "__main__":
    main()
