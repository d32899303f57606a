"""What a generator allows on a task: a dense set of its latent actions decoded and played, and each goal's best.

Used by the GenRL benchmark (:mod:`benchmarks.genrl`) for the generator's limit; run alone, it writes
one generator's limit on the held-out goals.

A played trajectory's reward for a goal is minus the distance from the goal to the best of the trajectory's
*candidate points*, which do not depend on the goal: hockey has one (where the puck rests), basketball one per
moment the ball comes down through the rim's height (the reward takes the crossing nearest the basket). So playing
a set of latent actions once gives every goal's best reward over that set exactly, with no simulation per goal.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import pathlib
from typing import Any

import numpy as np
from sb3_genrl.baselines.feedback import held_out_goals  # noqa: F401 (the benchmarks' goals, imported from here)
from sb3_genrl.envs import get_task
from sb3_genrl.envs.basketball import BASKET_HEIGHT
from sb3_genrl.envs.control import default_threads
from scipy.spatial import cKDTree

from sb3_genrl.generative import load
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.hyperparams import EVAL_GOAL_SEED
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_path, atomic_write_json

CACHE = pathlib.Path(__file__).resolve().parent / "runs" / "limits"  # the played grids (ignored by git)


def latent_set(
    generator: TrajectoryGenerator, *, grid: int = 201, extent: float = 3.0, samples: int = 10_000, seed: int = 0
) -> np.ndarray:
    """Dense latent actions: a ``grid x grid`` grid over ``[-extent, extent]^2`` for a 2-D latent space (row-major,
    first coordinate slowest), else ``samples`` draws from the prior clipped to the same box."""
    if generator.latent_dim == 2:
        axis = np.linspace(-extent, extent, grid)
        return np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1).reshape(-1, 2).astype(np.float32)
    alpha = generator.sample_prior(samples, rng=np.random.default_rng(seed))
    return np.clip(alpha, -extent, extent).astype(np.float32)


def candidate_points(task: str, rows: np.ndarray) -> np.ndarray:
    """The goal-independent points ``(k, 2)`` among which an episode's reward takes the nearest (see module doc).

    :param task: ``"hockey"`` or ``"basketball"``
    :param rows: the episode's sensor rows (one per physics step), as the env's ``_outcome`` receives them
    """
    position = rows[:, 1:4]
    if task == "hockey":
        return position[-1:, :2].copy()
    height = position[:, 2] - BASKET_HEIGHT
    crossing = np.flatnonzero((height[:-1] >= 0) & (height[1:] < 0))
    fraction = height[crossing] / (height[crossing] - height[crossing + 1])
    return position[crossing, :2] + fraction[:, None] * (position[crossing + 1, :2] - position[crossing, :2])


def play_candidates(
    task: str, trajectories: np.ndarray, *, chunk: int = 2048, cache: str | os.PathLike | None = None
) -> list[np.ndarray]:
    """Play trajectories (on every core) and return each one's candidate points; none for an unstable episode.

    :param cache: a folder where the result is kept, named by a digest of the task and the trajectories (the
        simulation is deterministic, so the same trajectories give the same points): a rerun on the same generator
        reads it instead of playing tens of thousands of trajectories again
    """
    trajectories = np.ascontiguousarray(trajectories, dtype=np.float32)
    path = None
    if cache is not None:
        digest = hashlib.sha256(task.encode() + trajectories.tobytes()).hexdigest()[:16]
        path = pathlib.Path(cache) / f"{task}_candidates_{digest}.npz"
        if path.is_file():
            with np.load(path) as stored:
                return np.split(stored["points"], np.cumsum(stored["counts"])[:-1])
    env = get_task(task).make_env()
    out: list[np.ndarray] = []
    original = env._finish

    def finish(rows: np.ndarray, goal: np.ndarray, clipped_steps: int) -> tuple[float, dict[str, Any]]:
        reward, info = original(rows, goal, clipped_steps)
        out.append(np.zeros((0, 2)) if info.get("unstable") else candidate_points(task, rows))
        return reward, info

    env._finish = finish  # type: ignore[method-assign]
    for start in range(0, len(trajectories), chunk):
        batch = trajectories[start : start + chunk]
        env.play_trajectories(batch, np.zeros((len(batch), 2)), n_threads=default_threads(), allow_outside_region=True)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp, open(tmp, "wb") as file:
            np.savez(file, points=np.concatenate(out), counts=np.array([len(c) for c in out]))
    return out


def nearest(candidates: list[np.ndarray], goals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per goal: the distance to the nearest candidate point of any trajectory and that trajectory's index."""
    points = np.concatenate([c for c in candidates if len(c)])
    owner = np.concatenate([np.full(len(c), i) for i, c in enumerate(candidates) if len(c)])
    distance, index = cKDTree(points).query(np.asarray(goals, dtype=np.float64), k=1)
    return distance, owner[index]


def summary(distances: np.ndarray) -> dict[str, float]:
    """Mean, median, 90th percentile and maximum of distances (m)."""
    return {
        "mean": float(np.mean(distances)),
        "median": float(np.median(distances)),
        "p90": float(np.percentile(distances, 90)),
        "max": float(np.max(distances)),
    }


def generator_limit(
    generator: TrajectoryGenerator,
    task: str,
    goals: np.ndarray,
    *,
    grid: int = 201,
    extent: float = 3.0,
    check: int = 5,
    prior_samples: int = 10_000,
    cache: str | os.PathLike | None = CACHE,
) -> dict[str, Any]:
    """The generator's best reachable distance to each goal over :func:`latent_set`, checked by replaying.

    For a 2-D latent space the result also holds the mean over coarser grids and over ``prior_samples`` draws from
    the prior (the other dense set that issue 12's yardstick allows; ``0``: not measured): the best reachable
    distance shrinks as the set gets denser, so each of them is a yardstick, none a floor.

    :param generator: the trajectory generator
    :param task: ``"hockey"`` or ``"basketball"``
    :param goals: ``(n, 2)`` goals
    :param grid: grid points per axis (2-D latents)
    :param extent: half-width of the latent box (prior stds)
    :param check: goals whose best latent action is replayed with that goal; its reward must be minus the distance
    :param cache: where the played grid's candidate points are kept (see :func:`play_candidates`; ``None``: nowhere)
    :return: ``distances`` (per goal), ``best_latents``, ``latents``, ``candidates`` and a ``summary``
    """
    latents = latent_set(generator, grid=grid, extent=extent)
    trajectories = generator.decode(latents)
    candidates = play_candidates(task, trajectories, cache=cache)
    distances, owner = nearest(candidates, goals)
    _check_by_replaying(task, trajectories[owner[:check]], goals[:check], distances[:check])
    coarser = {}
    if generator.latent_dim == 2:  # the same limit over coarser grids (every 2nd and 5th point of this one)
        index = np.arange(grid * grid).reshape(grid, grid)
        for step in (2, 5):
            if (grid - 1) % step == 0:
                kept = index[::step, ::step].ravel()
                coarse, _ = nearest([candidates[i] for i in kept], goals)
                coarser[f"{(grid - 1) // step + 1}x{(grid - 1) // step + 1}"] = float(coarse.mean())
    prior_mean = None
    if generator.latent_dim == 2 and prior_samples:
        prior_mean = prior_limit(generator, task, goals, samples=prior_samples, extent=extent, cache=cache)["summary"]
    return {
        "distances": distances,
        "best_latents": latents[owner],
        "latents": latents,
        "candidates": candidates,
        "summary": summary(distances),
        "n_latents": len(latents),
        "coarser_grid_means": coarser,
        "prior_samples": prior_samples if prior_mean else 0,
        "prior_samples_mean": prior_mean and prior_mean["mean"],
    }


def prior_limit(
    generator: TrajectoryGenerator,
    task: str,
    goals: np.ndarray,
    *,
    samples: int = 10_000,
    extent: float = 3.0,
    seed: int = 0,
    check: int = 5,
    cache: str | os.PathLike | None = CACHE,
) -> dict[str, Any]:
    """The generator's best reachable distance to each goal over ``samples`` latent actions drawn from its prior
    (clipped to ``[-extent, extent]``, as :func:`latent_set` draws them for latent spaces of more than 2 dimensions)."""
    latents = np.clip(generator.sample_prior(samples, rng=np.random.default_rng(seed)), -extent, extent)
    trajectories = generator.decode(latents.astype(np.float32))
    candidates = play_candidates(task, trajectories, cache=cache)
    distances, owner = nearest(candidates, goals)
    _check_by_replaying(task, trajectories[owner[:check]], goals[:check], distances[:check])
    return {"distances": distances, "summary": summary(distances), "n_latents": samples}


def _check_by_replaying(task: str, trajectories: np.ndarray, goals: np.ndarray, distances: np.ndarray) -> None:
    """Replay each goal's best trajectory with that goal: its reward must be minus the distance found."""
    env = get_task(task).make_env()
    rewards, _ = env.play_trajectories(trajectories, goals)
    if not np.allclose(-rewards, distances, atol=1e-6):
        raise RuntimeError(f"replayed rewards {rewards} differ from minus the distances found {distances}")


def main() -> None:
    """Measure a saved generator's best reachable distance to held-out goals and write it as JSON."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--task", required=True, choices=("hockey", "basketball"))
    parser.add_argument("--generator", required=True, help="a generator file")
    parser.add_argument("--goals", type=int, default=300, help="held-out goals (default 300, as the GenRL benchmarks)")
    parser.add_argument("--goal-seed", type=int, default=EVAL_GOAL_SEED)
    parser.add_argument("--grid", type=int, default=0, help="grid points per axis (2-D latents; default 0: no grid)")
    parser.add_argument("--prior-samples", type=int, default=10_000, help="draws from the prior (0: none)")
    parser.add_argument("--out", required=True, help="JSON file")
    args = parser.parse_args()
    if not os.path.isfile(args.generator):
        parser.error(f"--generator {args.generator} is not a file")
    if args.grid < 0 or args.prior_samples < 0 or args.goals < 1 or not (args.grid or args.prior_samples):
        parser.error("--goals must be positive, --grid and --prior-samples non-negative and not both 0")
    out = pathlib.Path(args.out)
    if not out.parent.is_dir():
        parser.error(f"--out: {out.parent} is not a folder")
    generator = load(args.generator, device="cpu")
    goals = held_out_goals(args.task, args.goals, args.goal_seed)
    result: dict[str, Any] = {
        "task": args.task,
        "generator": os.path.abspath(args.generator),
        "goals": args.goals,
        "goal_seed": args.goal_seed,
    }
    if args.prior_samples:
        result["prior_samples"] = {
            "n": args.prior_samples,
            **prior_limit(generator, args.task, goals, samples=args.prior_samples)["summary"],
        }
    if args.grid:
        limit = generator_limit(generator, args.task, goals, grid=args.grid, prior_samples=0)
        result["grid"] = {"n": args.grid, **limit["summary"], "coarser_grid_means": limit["coarser_grid_means"]}
    atomic_write_json(out, provenance() | result)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
