"""Tune GenRL's settings in seconds on a surrogate of a task, and never on the goals the benchmarks evaluate on.

The generator's 2-D latent grid (``--grid`` points per axis over the action box ``[-3, 3]^2``) is decoded and played
once; each grid point's first candidate point (hockey: where the puck rests; basketball: the first time the ball
comes down through the rim's height, see ``benchmarks/reachable.py``) gives the task's landing map, interpolated
bilinearly between grid points. The surrogate bandit draws goals as the task does, and its reward is minus the
distance from the interpolated landing point to the goal. GenRL trains on it through an identity generator (the
trajectory is the latent action itself), a hundred times faster than the simulation. Each run reports the
deterministic policy's mean distance to ``--goals`` tuning goals drawn with seed 777 (the benchmarks evaluate on
seed 12345), and the grid's own best over those goals. The surrogate leaves out a basketball throw's second crossing
(after a bounce; 45% of the quickstart VAE's grid has one), so the real task has a second way to reach many baskets
that the surrogate lacks: settings that mix the two (``hindsight_regression`` on basketball, docs/basketball.md) do
better here than in the simulation. ``--network-fit`` adds what GenRL's own policy network
(the policy and policy_kwargs of ``--genrl-kwargs``) reaches when told the answer: its mean fitted by regression to
the grid's best latent action of 20000 other goals (three fits, mean). Unlike the grid's best, this yardstick does
not shrink as the grid gets finer.

    python benchmarks/genrl_tuning.py --generator vae.pt --task basketball --episodes 20000 --seeds 0 1 2 \\
        --genrl-kwargs '{"policy": "ContextStdPolicy", "target_kl": 0.03, "max_log_std_change": 0.03,
                         "value_history": 10, "n_critic_updates": 10, "cg_max_steps": 30, "policy_averaging": 0.97}'

``--genrl-kwargs`` may name the policy (``"policy": "ContextStdPolicy"``).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from reachable import held_out_goals, latent_set, play_candidates
from sb3_genrl.envs import get_task
from scipy.interpolate import RegularGridInterpolator
from scipy.spatial import cKDTree

from sb3_genrl import LatentActionWrapper
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED, check_int, option
from sb3_genrl.generative import load
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl.train import genrl_kwargs_argument, make_genrl
from sb3_genrl.utils import atomic_path, atomic_write_json

HERE = os.path.dirname(os.path.abspath(__file__))
TUNING_GOAL_SEED = 777
FIT_GOAL_SEED = 31415  # the training goals of the network fit (neither tuning nor evaluation goals)
EXTENT = 3.0  # GenRL's latent action box for a normal prior


class IdentityGenerator(TrajectoryGenerator):
    """The 'trajectory' of a latent action is the latent action itself (one step of two values)."""

    def __init__(self) -> None:
        super().__init__(horizon=1, action_dim=2, latent_dim=2, prior="normal")

    def decode(self, alpha: np.ndarray) -> np.ndarray:
        return self.check_latent(alpha)[:, None, :].astype(np.float32)

    def save(self, path: str) -> None:
        raise NotImplementedError("the identity generator of the tuning surrogate is not saved")


class SurrogateTask(gym.Env):
    """A task's contextual bandit with its landing map interpolated from a latent grid (see the module doc)."""

    def __init__(self, task: str, landing: np.ndarray) -> None:
        axis = np.linspace(-EXTENT, EXTENT, landing.shape[0])
        self.landing = RegularGridInterpolator((axis, axis), np.nan_to_num(landing, nan=0.0))  # none: at the robot
        self.reached = RegularGridInterpolator((axis, axis), landing)  # NaN next to a grid point without landing
        self.name, self.task = task, get_task(task).make_env()
        self.observation_space = self.context_space = self.task.context_space
        self.action_space = spaces.Box(-EXTENT, EXTENT, (2,), np.float32)
        self.horizon, self.goal = 1, np.zeros(2)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.goal = self.task.sample_goal(self.np_random)
        return self.get_context(), {}

    def get_context(self) -> np.ndarray:
        return np.asarray(self.goal, dtype=np.float32)

    def distances(self, alpha: np.ndarray, goals: np.ndarray) -> np.ndarray:
        return np.linalg.norm(self.landing(np.clip(alpha, -EXTENT, EXTENT)) - goals, axis=1)

    def play_trajectories(self, trajectories: np.ndarray, goals: np.ndarray, **_: Any) -> tuple[np.ndarray, list]:
        alpha = np.clip(np.asarray(trajectories)[:, 0, :], -EXTENT, EXTENT)
        distances = self.distances(alpha, np.broadcast_to(goals, (len(trajectories), 2)))
        reached = self.reached(alpha)
        return -distances, [{"distance": float(d), "reached": p} for d, p in zip(distances, reached, strict=True)]

    def hindsight(self, info: dict[str, Any]) -> tuple[np.ndarray, float] | None:
        """The landing point and 0, as the task's (GenRL's ``hindsight=True``); ``None`` where the grid has none."""
        reached = np.asarray(info["reached"], dtype=np.float32)
        return (reached, 0.0) if np.isfinite(reached).all() else None

    def step(self, action: np.ndarray) -> tuple:
        raise NotImplementedError("the surrogate is played through play_trajectories")


def landing_map(generator_path: str, task: str, grid: int) -> np.ndarray:
    """``(grid, grid, 2)`` first candidate point of each grid latent (NaN where there is none), cached per file."""
    with open(generator_path, "rb") as file:
        digest = hashlib.sha256(file.read()).hexdigest()[:16]
    cache = os.path.join(HERE, "runs", "tuning", f"{task}_{digest}_grid{grid}.npy")
    if os.path.exists(cache):
        return np.load(cache)
    generator = load(generator_path, device="cpu")
    if generator.latent_dim != 2:
        raise ValueError(f"the tuning surrogate needs a 2-D latent space, {generator_path} has {generator.latent_dim}")
    candidates = play_candidates(task, generator.decode(latent_set(generator, grid=grid, extent=EXTENT)))
    points = first_points(candidates).reshape(grid, grid, 2)
    os.makedirs(os.path.dirname(cache), exist_ok=True)
    with atomic_path(cache) as tmp, open(tmp, "wb") as file:
        np.save(file, points)
    return points


def first_points(candidates: list[np.ndarray]) -> np.ndarray:
    """``(n, 2)``: each played latent action's first candidate point, the landing map (NaN where there is none)."""
    return np.array([c[0] if len(c) else (np.nan, np.nan) for c in candidates]).reshape(-1, 2)


def landing_targets(latents: np.ndarray, points: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """Per goal, the latent action whose landing point (``points``, NaN: none) is nearest: the network fit's target."""
    valid = np.isfinite(points).all(axis=1)
    return latents[valid][cKDTree(points[valid]).query(goals)[1]]


def run(env: SurrogateTask, goals: np.ndarray, seed: int, episodes: int, genrl_kwargs: dict[str, Any]) -> dict:
    start = time.perf_counter()
    model = make_genrl(LatentActionWrapper(env, IdentityGenerator()), seed=seed, device="cpu", **genrl_kwargs)
    model.learn(episodes)
    alpha, _ = model.predict(goals, deterministic=True)
    distances = env.distances(alpha, goals)
    with torch.no_grad():  # the exploring policy's spread at the tuning goals
        std = model.policy.get_distribution(model.policy.obs_to_tensor(goals)[0]).distribution.stddev.mean().item()
    return {"seed": seed, "mean_m": float(distances.mean()), "median_m": float(np.median(distances)),
            "std": std, "seconds": time.perf_counter() - start}


def network_fit(env: SurrogateTask, landing: np.ndarray, goals: np.ndarray, genrl_kwargs: dict[str, Any], *,
                n_goals: int = 20000, epochs: int = 300, seed: int = 0) -> float:
    """The best GenRL's own policy network does when told the answer: its mean fitted by regression to the grid's
    best latent action of ``n_goals`` training goals (seed :data:`FIT_GOAL_SEED`), then the deterministic policy's
    mean distance to ``goals``. A yardstick for the policy search that, unlike the grid's best, does not shrink
    as the grid gets finer."""
    latents = latent_set(IdentityGenerator(), grid=landing.shape[0], extent=EXTENT)  # the grid landing_map played
    train = held_out_goals(env.name, n_goals, FIT_GOAL_SEED)
    targets = landing_targets(latents, landing.reshape(-1, 2), train)
    model = fit_policy_mean(env, train, targets, genrl_kwargs, epochs=epochs, seed=seed)
    alpha, _ = model.predict(goals, deterministic=True)
    return float(env.distances(alpha, goals).mean())


def fit_policy_mean(env: SurrogateTask, contexts: np.ndarray, targets: np.ndarray, genrl_kwargs: dict[str, Any], *,
                    epochs: int = 300, seed: int = 0) -> Any:
    """A GenRL model whose policy (the policy and policy_kwargs of ``genrl_kwargs``) has its mean fitted to
    ``targets`` (latent actions) at ``contexts`` by regression: Adam, learning rate 1e-3 annealed by a cosine over
    ``epochs``, minibatches of 256."""
    architecture = {key: value for key, value in genrl_kwargs.items() if key in ("policy", "policy_kwargs")}
    model = make_genrl(LatentActionWrapper(env, IdentityGenerator()), seed=seed, device="cpu", **architecture)
    policy = model.policy
    optimizer = torch.optim.Adam(policy.parameters(), lr=1e-3)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, epochs)
    inputs = policy.obs_to_tensor(contexts)[0]
    outputs = torch.as_tensor(targets, dtype=torch.float32)
    for _ in range(epochs):
        for batch in torch.randperm(len(inputs)).split(256):
            loss = (policy.get_distribution(inputs[batch]).distribution.mean - outputs[batch]).pow(2).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        schedule.step()
    return model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generator", required=True, type=EXISTING,
                        help="a trained generator with a 2-D latent space")
    parser.add_argument("--task", default="basketball", choices=["hockey", "basketball"])
    parser.add_argument("--episodes", type=COUNT, default=20000)
    parser.add_argument("--seeds", type=SEED, nargs="+", default=[0, 1, 2])
    parser.add_argument("--genrl-kwargs", type=genrl_kwargs_argument, default={}, help="GenRL arguments, as JSON")
    parser.add_argument("--grid", type=option(check_int, int, minimum=2), default=101, help="latent grid points per axis")
    parser.add_argument("--goals", type=COUNT, default=300, help="tuning goals (seed 777)")
    parser.add_argument("--network-fit", action="store_true",
                        help="also fit the policy network to the grid's best latent actions (see network_fit)")
    parser.add_argument("--out", type=JSON_OUT, default=None,
                        help="JSON output (default: print only)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    genrl_kwargs = args.genrl_kwargs
    landing = landing_map(args.generator, args.task, args.grid)
    env = SurrogateTask(args.task, landing)
    goals = held_out_goals(args.task, args.goals, TUNING_GOAL_SEED)
    valid = landing.reshape(-1, 2)[np.isfinite(landing.reshape(-1, 2)).all(axis=1)]
    grid_best = float(cKDTree(valid).query(goals)[0].mean())
    result = {"task": args.task, "generator": os.path.abspath(args.generator), "episodes": args.episodes,
              "genrl_kwargs": genrl_kwargs, "grid": args.grid, "grid_best_mean_m": grid_best, "runs": []}
    if args.network_fit:
        start = time.perf_counter()
        fits = [network_fit(env, landing, goals, genrl_kwargs, seed=seed) for seed in (0, 1, 2)]
        result |= {"network_fit_mean_m": float(np.mean(fits)), "network_fit_per_seed_m": fits}
        print(f"network fit: mean {np.mean(fits):.4f} m over 3 fits ({time.perf_counter() - start:.0f} s)", flush=True)
    for seed in args.seeds:
        result["runs"].append(run(env, goals, seed, args.episodes, genrl_kwargs))
        row = result["runs"][-1]
        print(f"seed {seed}: mean {row['mean_m']:.4f} m, median {row['median_m']:.4f} m, std {row['std']:.4f} "
              f"({row['seconds']:.0f} s)", flush=True)
    means = [row["mean_m"] for row in result["runs"]]
    result["mean_m_over_seeds"] = float(np.mean(means))
    print(f"{args.task}, {args.episodes} episodes, {genrl_kwargs}: mean over seeds {np.mean(means):.4f} m "
          f"(grid best {grid_best:.4f} m" + (f", network fit {result['network_fit_mean_m']:.4f} m, ratio "
                                              f"{np.mean(means) / result['network_fit_mean_m']:.2f})"
                                              if args.network_fit else ")"))
    if args.out:
        atomic_write_json(args.out, result)


if __name__ == "__main__":
    main()
