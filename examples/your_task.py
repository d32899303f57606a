"""Your own task, from an expert to a GenRL policy, with nothing added to the package (docs: "Your own task").

The task: a point mass on a plane must end within 5 cm of a goal drawn from the reset seed; it reports
``info["is_success"]``. The expert: a controller that closes half the distance at each step (closed loop). The path:
record perturbed expert demonstrations (kept only when their actions, replayed open loop from their seeded reset,
still succeed), train a beta-VAE on their actions, train GenRL over its latent space, and measure the success on
held-out resets.

    python examples/your_task.py --out your_task
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces
from sb3_genrl.envs.demonstrations import record_demonstrations
from sb3_genrl.envs.external import make_task_env

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.data import dataset_info
from sb3_genrl.generative import train_generator
from sb3_genrl.genrl.demonstrations import DemonstrationCallback

TASK = "YourTask/PointGoal-v0"
STEP = 0.1  # metres moved per unit of action and step


class PointGoalEnv(gym.Env):
    """A point mass with velocity control; the goal is uniform in [-0.8, 0.8]^2, drawn from ``np_random``.

    Observation: goal (2), position (2). Action: velocity (2) in [-1, 1], 0.1 m a unit. Reward: minus the distance to
    the goal. ``info["is_success"]``: within 5 cm of it. Episodes last 20 steps (``max_episode_steps`` below).
    """

    metadata = {"render_modes": []}

    def __init__(self) -> None:
        self.observation_space = spaces.Box(-2.0, 2.0, shape=(4,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)  # seeds self.np_random: the same seed gives the same goal, as the recorder checks
        self.goal = self.np_random.uniform(-0.8, 0.8, size=2)
        self.position = np.zeros(2)
        return self._obs(), {}

    def _obs(self):
        return np.concatenate([self.goal, self.position]).astype(np.float32)

    def step(self, action):
        self.position = self.position + STEP * np.clip(action, -1.0, 1.0)
        distance = float(np.linalg.norm(self.position - self.goal))
        return self._obs(), -distance, False, False, {"is_success": distance < 0.05}


def expert(observation: np.ndarray) -> np.ndarray:
    """Closes half the distance to the goal at each step (observation -> action)."""
    return np.clip(0.5 * (observation[:2] - observation[2:]) / STEP, -1.0, 1.0)


def success_rate(model: GenRL, env: LatentActionWrapper, resets: int = 100) -> float:
    """The deterministic policy's success on ``resets`` held-out seeded resets (seeds 10000, 10001, ...)."""
    successes = []
    for i in range(resets):
        context, _ = env.reset(seed=10_000 + i)
        _, _, _, _, info = env.step(model.predict(context, deterministic=True)[0])
        successes.append(info["is_success"])
    return float(np.mean(successes))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True, help="output folder (must not hold an earlier run)")
    parser.add_argument("--demos", type=int, default=1000, help="demonstrations to keep (default 1000)")
    parser.add_argument("--epochs", type=int, default=200, help="beta-VAE training epochs (default 200)")
    parser.add_argument("--episodes", type=int, default=3200, help="GenRL episodes (default 3200)")
    args = parser.parse_args()
    th.set_num_threads(1)  # small networks: one thread is fastest on a shared CPU

    # 1. The task: any registered Gymnasium id (or a callable that makes the env) with a max_episode_steps.
    gym.register(TASK, entry_point=PointGoalEnv, max_episode_steps=20)

    # 2. Demonstrations: the expert closed loop with smooth random perturbations, kept when the open-loop replay of
    #    their actions from the same seeded reset succeeds too.
    demos = record_demonstrations(TASK, expert, args.demos, args.out / "demonstrations", seed=0)
    info = dataset_info(demos)
    print(
        f"demonstrations: {info['episodes']} kept of {info['tried']} tried ({info['failed_closed_loop']} failed closed "
        f"loop, {info['failed_open_loop']} failed open loop) -> {demos}"
    )

    # 3. A generator of the demonstrations' action sequences (T = 20 steps, M = 2 action dimensions).
    generator = train_generator(demos, preset="VAE1", epochs=args.epochs, seed=0, out=args.out / "vae.pt")
    print(f"generator: T={generator.horizon}, M={generator.action_dim}, N_alpha={generator.latent_dim} -> {args.out}/vae.pt")

    # 4. GenRL: the context is the reset observation (the goal and the start); one episode is one latent action. It
    #    starts from the demonstrations: the policy's mean fitted to their latent codes before the first iteration.
    env = LatentActionWrapper(make_task_env(TASK), generator)
    model = GenRL(env, seed=0)
    print(f"success before training: {success_rate(model, env):.2f} of 100 held-out resets")
    model.learn(total_timesteps=args.episodes, callback=DemonstrationCallback(demos, keep=False))
    print(f"success after {model.num_timesteps} episodes: {success_rate(model, env):.2f} of 100 held-out resets")
    model.save(args.out / "genrl_policy.zip")
    print(f"policy -> {args.out}/genrl_policy.zip")


if __name__ == "__main__":
    main()
