"""What GenRL's policy network can represent on a task, measured in the simulation.

The generator's 2-D latent grid (``--grid`` points per axis, played once and cached as ``benchmarks/reachable.py``
plays it) gives each of 20000 training goals (seed 31415) its best latent action on the landing map (the grid point
whose first candidate point is nearest, as ``genrl_tuning.py`` builds its surrogate). The policy network of
``--genrl-kwargs`` (its ``policy`` and ``policy_kwargs``; GenRL's default otherwise) fits its mean to those actions
by regression, and the deterministic policy is then played in the simulation on the tuning goals (seed 777: choose
an architecture on these) and on the benchmarks' held-out goals (seed 12345). This is what a policy search with
that network could reach at best if it found the answer everywhere: unlike the grid's best it does not shrink as
the grid gets finer, and unlike ``genrl_tuning.py --network-fit`` it is measured on the real task, not on a
surrogate interpolated from a coarser grid.

    python benchmarks/network_fit.py --generator vae.pt --task hockey \\
        --genrl-kwargs '{"policy_kwargs": {"net_arch": {"pi": [64, 64, 64], "vf": [64, 64]}}}' --out fit.json
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch
from genrl_benchmark import FINAL_GOAL_SEED
from genrl_tuning import EXTENT, FIT_GOAL_SEED, TUNING_GOAL_SEED, SurrogateTask, first_points, fit_policy_mean, landing_targets
from reachable import CACHE, held_out_goals, latent_set, nearest, play_candidates, summary
from sb3_genrl.envs import TASKS, get_task

from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED, check_int, option
from sb3_genrl.generative import load
from sb3_genrl.genrl.train import genrl_kwargs_argument
from sb3_genrl.utils import atomic_write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generator", required=True, type=EXISTING, help="a trained generator with a 2-D latent space")
    parser.add_argument("--task", required=True, choices=sorted(TASKS))
    parser.add_argument("--genrl-kwargs", type=genrl_kwargs_argument, default={},
                        help="GenRL arguments as JSON; only policy and policy_kwargs are used")
    parser.add_argument("--grid", type=option(check_int, int, minimum=2), default=201, help="latent grid points per axis")
    parser.add_argument("--epochs", type=COUNT, default=300, help="regression epochs")
    parser.add_argument("--seeds", type=SEED, nargs="+", default=[0, 1], help="one fit per seed")
    parser.add_argument("--goals", type=COUNT, default=300, help="tuning and held-out goals")
    parser.add_argument("--out", type=JSON_OUT, default=None, help="JSON output (default: print only)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    generator = load(args.generator, device="cpu")
    if generator.latent_dim != 2:
        parser.error(f"argument --generator: the fit needs a 2-D latent space, {args.generator} has {generator.latent_dim}")
    latents = latent_set(generator, grid=args.grid, extent=EXTENT)
    candidates = play_candidates(args.task, generator.decode(latents), cache=CACHE)
    train = held_out_goals(args.task, 20000, FIT_GOAL_SEED)
    # The target of a goal is the latent action whose first candidate point (the landing map: where the puck rests,
    # where the ball first comes down through the rim's height) is nearest: a later crossing of the rim's height
    # (a ball coming down a second time) lies on another branch of the map, and a regression onto a target that
    # jumps between branches averages them.
    first = first_points(candidates)
    targets = landing_targets(latents, first, train)
    surrogate = SurrogateTask(args.task, first.reshape(args.grid, args.grid, 2))  # the spaces GenRL's policy is built for
    env = get_task(args.task).make_env()
    goal_sets = {"tuning": held_out_goals(args.task, args.goals, TUNING_GOAL_SEED),
                 "held_out": held_out_goals(args.task, args.goals, FINAL_GOAL_SEED)}
    result = {"task": args.task, "generator": os.path.abspath(args.generator), "grid": args.grid,
              "epochs": args.epochs, "genrl_kwargs": args.genrl_kwargs, "fits": []}
    for name, goals in goal_sets.items():
        result[f"grid_best_{name}_mean_m"] = float(nearest(candidates, goals)[0].mean())
    for seed in args.seeds:
        start = time.perf_counter()
        model = fit_policy_mean(surrogate, train, targets, args.genrl_kwargs, epochs=args.epochs, seed=seed)
        row: dict[str, object] = {"seed": seed}
        for name, goals in goal_sets.items():
            alpha, _ = model.predict(goals, deterministic=True)
            rewards, _ = env.play_trajectories(generator.decode(alpha.astype(np.float32)), goals)
            row[name] = summary(-rewards)
        row["seconds"] = time.perf_counter() - start
        result["fits"].append(row)
        print(f"fit {seed}: mean distance {row['tuning']['mean']:.4f} m on the tuning goals, "
              f"{row['held_out']['mean']:.4f} m on the held-out goals ({row['seconds']:.0f} s)", flush=True)
        for name in goal_sets:
            result[f"{name}_mean_m"] = float(np.mean([fit[name]["mean"] for fit in result["fits"]]))
        if args.out:
            atomic_write_json(args.out, result)
    print(f"{args.task}, {args.genrl_kwargs or 'GenRL default policy'}: {result['tuning_mean_m']:.4f} m on the tuning "
          f"goals (grid best {result['grid_best_tuning_mean_m']:.4f}), {result['held_out_mean_m']:.4f} m on the held-out "
          f"goals (grid best {result['grid_best_held_out_mean_m']:.4f})")


if __name__ == "__main__":
    main()
