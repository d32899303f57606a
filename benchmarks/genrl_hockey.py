"""How close GenRL gets on hockey, and after how many episodes: mean final distance of the deterministic policy.

Makes hockey demonstrations (or reads ``--data``), trains a beta-VAE on them (or reads ``--generator``), then trains
GenRL with several seeds. Every ``--eval-every`` episodes the deterministic policy is evaluated on
``--eval-goals`` fixed goals (SB3's ``EvalCallback`` on the latent-action env: one episode = one trajectory, reward =
minus the puck's final distance to the goal). Prints a table, writes JSON and a plot of distance vs episodes.

    python benchmarks/genrl_hockey.py                                  # 4000 demos, VAE1 300 epochs, 3 seeds x 3000 episodes
    python benchmarks/genrl_hockey.py --generator quickstart/vae.pt --seeds 0 1 2 3 4 --episodes 6000
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time

import gymnasium as gym
import matplotlib
import numpy as np
import torch
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.monitor import Monitor

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from sb3_genrl import GenRL, LatentActionWrapper, __version__  # noqa: E402
from sb3_genrl.generative import load, train_generator  # noqa: E402
from sb3_genrl.genrl import evaluate_on_goals  # noqa: E402

DEFAULT_OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "genrl_hockey.json")
TARGET_CM = 5.0  # the acceptance bound on the mean final distance


def make_generator(args: argparse.Namespace, work: str) -> tuple[str, dict[str, object]]:
    if args.generator is not None:
        return args.generator, {"generator": os.path.abspath(args.generator)}
    data = args.data
    if data is None:
        from sb3_genrl.envs.demonstrations import make_demonstrations

        data = os.path.join(work, "demonstrations")
        start = time.perf_counter()
        make_demonstrations("hockey", args.demos, data, seed=0, progress_bar=True)
        print(f"{args.demos} demonstrations in {time.perf_counter() - start:.0f} s")
    path = os.path.join(work, "vae.pt")
    start = time.perf_counter()
    vae = train_generator(data, preset=args.preset, epochs=args.epochs, seed=0, out=path, progress_bar=True)
    seconds = time.perf_counter() - start
    print(f"{args.preset}: best checkpoint at epoch {vae.best_epoch} of {args.epochs} ({seconds:.0f} s)")
    return path, {"demonstrations": args.demos if args.data is None else os.path.abspath(args.data),
                  "preset": args.preset, "epochs": args.epochs, "best_epoch": vae.best_epoch}


def run_seed(generator_path: str, seed: int, args: argparse.Namespace, work: str) -> dict[str, object]:
    generator = load(generator_path)
    eval_env = LatentActionWrapper(gym.make("GenRL/Hockey-v0"), generator)
    eval_env.reset(seed=10_000 + seed)  # the evaluation goals: one fixed stream per seed
    evaluation = EvalCallback(Monitor(eval_env), n_eval_episodes=args.eval_goals, eval_freq=args.eval_every,
                              deterministic=True, log_path=os.path.join(work, f"eval_{seed}"), verbose=0)
    model = GenRL(gym.make("GenRL/Hockey-v0"), generator, seed=seed)
    start = time.perf_counter()
    model.learn(args.episodes, callback=evaluation, progress_bar=True)
    seconds = time.perf_counter() - start
    # Final: the deterministic policy on the same held-out goals for every seed (fast path).
    _, rewards, infos = evaluate_on_goals(model, "hockey", goals=args.final_goals, seed=12345)
    distances = -rewards * 100
    episodes = [int(n) for n in evaluation.evaluations_timesteps]
    curve_cm = [float(-np.mean(r) * 100) for r in evaluation.evaluations_results]
    below = next((n for n, d in zip(episodes, curve_cm, strict=True) if d < TARGET_CM), None)
    return {"seed": seed, "episodes": int(model.num_timesteps), "seconds": seconds,
            "mean_cm": float(distances.mean()), "median_cm": float(np.median(distances)),
            "p90_cm": float(np.percentile(distances, 90)), "max_cm": float(distances.max()),
            "table_contacts": int(sum(info["table_contacts"] for info in infos)),
            "first_episodes_below_target": below, "curve_episodes": episodes, "curve_mean_cm": curve_cm}


def plot(result: dict[str, object], path: str) -> None:
    """Mean final distance vs episodes, one line per seed, and the 5 cm bound."""
    figure, axis = plt.subplots(figsize=(6, 4))
    for row in result["runs"]:
        axis.plot(row["curve_episodes"], row["curve_mean_cm"], marker=".", label=f"seed {row['seed']}")
    axis.axhline(TARGET_CM, color="grey", linestyle="--", label=f"{TARGET_CM:g} cm")
    axis.set(xlabel="episodes (trajectories played)", ylabel="mean final distance (cm)", ylim=(0, None),
             title=f"GenRL on hockey: deterministic policy, {result['eval_goals']} goals")
    axis.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="hockey Minari dataset (default: make --demos demonstrations)")
    parser.add_argument("--generator", default=None, help="a trained generator (skips demonstrations and training)")
    parser.add_argument("--demos", type=int, default=4000)
    parser.add_argument("--preset", default="VAE1")
    parser.add_argument("--epochs", type=int, default=300)
    parser.add_argument("--episodes", type=int, default=3000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--eval-every", type=int, default=256, help="episodes between evaluations")
    parser.add_argument("--eval-goals", type=int, default=100, help="goals per evaluation during training")
    parser.add_argument("--final-goals", type=int, default=300, help="held-out goals of the final evaluation")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--out", default=DEFAULT_OUT, help="JSON output (a PNG is written beside it)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    with tempfile.TemporaryDirectory() as work:
        generator_path, generator_info = make_generator(args, work)
        rows = []
        for seed in args.seeds:
            rows.append(run_seed(generator_path, seed, args, work))
            print(f"seed {seed}: mean {rows[-1]['mean_cm']:.2f} cm", flush=True)

    print(f"\nGenRL on hockey, deterministic policy on {args.final_goals} held-out goals after {args.episodes} episodes")
    print(f"{'seed':>4} {'mean cm':>8} {'median':>7} {'p90':>6} {'max':>6} {'contacts':>8} "
          f"{'< 5 cm after':>13} {'train s':>8}")
    for row in rows:
        below = row["first_episodes_below_target"]
        print(f"{row['seed']:>4} {row['mean_cm']:>8.2f} {row['median_cm']:>7.2f} {row['p90_cm']:>6.2f} "
              f"{row['max_cm']:>6.1f} {row['table_contacts']:>8} {str(below) + ' ep' if below else 'never':>13} "
              f"{row['seconds']:>8.0f}")
    means = np.array([row["mean_cm"] for row in rows])
    print(f"over seeds: {means.mean():.2f} +- {means.std():.2f} cm (worst {means.max():.2f} cm)")

    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    result = {"benchmark": "genrl_hockey", "sb3_genrl": __version__, "torch": torch.__version__,
              "machine": platform.machine(), "processor": platform.processor(), "cpus": os.cpu_count(),
              "threads": args.threads, "generator": generator_info, "episodes": args.episodes,
              "final_goals": args.final_goals, "eval_goals": args.eval_goals, "runs": rows,
              "mean_cm_over_seeds": float(means.mean()), "worst_mean_cm": float(means.max())}
    with open(args.out, "w") as file:
        json.dump(result, file, indent=2)
    plot(result, os.path.splitext(args.out)[0] + ".png")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
