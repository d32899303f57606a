"""How close GenRL gets on a task, after how many episodes, and next to what its generator allows.

Makes demonstrations (or reads ``--data``), trains a beta-VAE on them (or reads ``--generator``), measures the
generator's own limit (the best reachable distance to each held-out goal over a dense grid of its latent actions,
see :mod:`benchmarks.reachable`), then trains GenRL with the task's settings (its entry in
``hyperparams/genrl.yml``) and several seeds. Every ``--eval-every`` episodes the deterministic policy is evaluated
on ``--eval-goals`` goals (SB3's ``EvalCallback`` on the latent-action env: one episode = one trajectory, reward =
minus the final distance). At the end each seed's deterministic policy plays the ``--final-goals`` held-out goals
(:data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`); the ratio is its mean distance over the generator's best-reachable
mean on the same goals. Prints a table, writes JSON (after every seed) and a plot of distance vs episodes
(default: ``benchmarks/results/genrl_TASK.json`` and ``.png``).

    python -m benchmarks.genrl --task hockey        # 4000 demos, VAE1 300 epochs, 3 seeds x the task's 3000 episodes
    python -m benchmarks.genrl --task basketball    # 3 seeds x the task's 20000 episodes
    python -m benchmarks.genrl --task hockey --generator quickstart/vae.pt --seeds 0 1 2 3 4 --episodes 6000
    python -m benchmarks.genrl --task basketball --generator quickstart/vae.pt
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import torch
from sb3_genrl.envs import get_task
from sb3_genrl.envs.demonstrations import make_demonstrations
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.monitor import Monitor

from benchmarks.reachable import generator_limit, held_out_goals, summary
from sb3_genrl import LatentActionWrapper
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED, check_int, json_object_argument, option
from sb3_genrl.generative import load, train_generator
from sb3_genrl.generative.presets import PRESETS
from sb3_genrl.genrl import check_genrl_settings
from sb3_genrl.genrl.settings import SETTINGS as GENRL_SETTINGS
from sb3_genrl.hyperparams import EVAL_GOAL_SEED, lay_over
from sb3_genrl.provenance import provenance
from sb3_genrl.run import evaluate_on_goals
from sb3_genrl.run.train import effective_genrl_settings, make_genrl
from sb3_genrl.study.quickstart import task_settings
from sb3_genrl.utils import atomic_path, atomic_write_json

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


@dataclass(frozen=True)
class Setting:
    """A task's benchmark defaults: acceptance bound (m), display unit, the quickstart-size pipeline (its GenRL
    episodes and settings are the task's entry in ``hyperparams/genrl.yml``, see
    :func:`~sb3_genrl.study.quickstart.task_settings`)."""

    task: str
    target_m: float
    unit: str  # "cm" or "m", for printing and plotting
    eval_every: int = 256
    demos: int = 4000
    preset: str = "VAE1"
    epochs: int = 300

    @property
    def episodes(self) -> int:
        return task_settings(self.task)[0]

    @property
    def genrl_kwargs(self) -> dict[str, object]:
        """The task's GenRL settings, its episodes per iteration as ``n_steps`` (one env)."""
        _, batch_episodes, genrl_kwargs = task_settings(self.task)
        return {**genrl_kwargs, "n_steps": batch_episodes}

    @property
    def scale(self) -> float:
        return 100.0 if self.unit == "cm" else 1.0


def make_benchmark_demonstrations(task: str, episodes: int, work: str, threads: int | None = 1) -> str:
    """``episodes`` new demonstrations of ``task`` (seed 0, on ``threads`` threads) in ``work/demonstrations``; its
    path."""
    data = os.path.join(work, "demonstrations")
    start = time.perf_counter()
    make_demonstrations(task, episodes, data, seed=0, n_threads=threads, progress_bar=True)
    print(f"{episodes} demonstrations in {time.perf_counter() - start:.0f} s", flush=True)
    return data


def make_generator(
    task: str, preset: str, args: argparse.Namespace, work: str, threads: int | None = 1
) -> tuple[str, dict[str, object]]:
    """The generator to benchmark: ``--generator``, or the ``preset`` trained on ``--data`` or on ``--demos`` new
    demonstrations (made on ``threads`` threads), with its record."""
    if args.generator is not None:
        return args.generator, {"generator": os.path.abspath(args.generator)}
    data = args.data or make_benchmark_demonstrations(task, args.demos, work, threads)
    path = os.path.join(work, "vae.pt")
    start = time.perf_counter()
    vae = train_generator(data, preset=preset, epochs=args.epochs, seed=0, out=path, progress_bar=True)
    seconds = time.perf_counter() - start
    print(f"{preset}: best checkpoint at epoch {vae.best_epoch} of {args.epochs} ({seconds:.0f} s)", flush=True)
    return path, {
        "demonstrations": args.demos if args.data is None else os.path.abspath(args.data),
        "preset": preset,
        "epochs": args.epochs,
        "best_epoch": vae.best_epoch,
    }


def run_seed(setting: Setting, generator_path: str, seed: int, args: argparse.Namespace, work: str) -> dict[str, object]:
    """Train GenRL with one seed, evaluating on the way; the final deterministic distances to the held-out goals."""
    generator = load(generator_path, device="cpu")
    env_id = get_task(setting.task).env_id
    eval_env = LatentActionWrapper(gym.make(env_id), generator)
    eval_env.reset(seed=10_000 + seed)  # the evaluation goals: one fixed stream per seed
    evaluation = EvalCallback(
        Monitor(eval_env),
        n_eval_episodes=args.eval_goals,
        eval_freq=args.eval_every,
        deterministic=True,
        log_path=os.path.join(work, f"eval_{seed}"),
        verbose=0,
    )
    model = make_genrl(gym.make(env_id), generator, seed=seed, device="cpu", **args.genrl_kwargs)
    start = time.perf_counter()
    model.learn(args.episodes, callback=evaluation)
    seconds = time.perf_counter() - start
    _, rewards, infos = evaluate_on_goals(model, setting.task, goals=args.final_goals, seed=EVAL_GOAL_SEED)
    distances = -rewards
    episodes = [int(n) for n in evaluation.evaluations_timesteps]
    curve = [float(-np.mean(r)) for r in evaluation.evaluations_results]
    below = next((n for n, d in zip(episodes, curve, strict=True) if d < setting.target_m), None)
    row = {
        "seed": seed,
        "episodes": int(model.num_timesteps),
        "seconds": seconds,
        **{f"{key}_m": value for key, value in summary(distances).items()},
        "first_episodes_below_target": below,
        "curve_episodes": episodes,
        "curve_mean_m": curve,
    }
    if "table_contacts" in infos[0]:  # tasks that count the tool's contacts with the table
        row["table_contacts"] = int(sum(info["table_contacts"] for info in infos))
    return row


def plot(setting: Setting, result: dict[str, object], path: str) -> None:
    """Mean final distance vs episodes, one line per seed, the acceptance bound and the generator's limit."""
    import matplotlib

    matplotlib.use("Agg")  # files only
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6, 4))
    for row in result["runs"]:
        axis.plot(
            row["curve_episodes"], np.array(row["curve_mean_m"]) * setting.scale, marker=".", label=f"seed {row['seed']}"
        )
    axis.axhline(
        setting.target_m * setting.scale,
        color="grey",
        linestyle="--",
        label=f"{setting.target_m * setting.scale:g} {setting.unit}",
    )
    limit = result["generator_limit"]["mean_m"] * setting.scale
    axis.axhline(limit, color="k", linestyle=":", label=f"generator best reachable {limit:.3g} {setting.unit}")
    axis.set(
        xlabel="episodes (trajectories played)",
        ylabel=f"mean final distance ({setting.unit})",
        ylim=(0, None),
        title=f"GenRL on {setting.task}: deterministic policy, {result['eval_goals']} goals",
    )
    axis.legend()
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=100)


def print_table(setting: Setting, result: dict[str, object]) -> None:
    unit, scale = setting.unit, setting.scale
    print(
        f"\nGenRL on {setting.task}, deterministic policy on {result['final_goals']} held-out goals after "
        f"{result['episodes']} episodes ({unit})"
    )
    print(
        f"{'seed':>4} {'mean':>7} {'median':>7} {'p90':>7} {'max':>7} {'ratio':>6} {'below target after':>19} {'train s':>8}"
    )
    for row in result["runs"]:
        below = row["first_episodes_below_target"]
        print(
            f"{row['seed']:>4} {row['mean_m'] * scale:>7.3f} {row['median_m'] * scale:>7.3f} {row['p90_m'] * scale:>7.3f} "
            f"{row['max_m'] * scale:>7.2f} {row['ratio']:>6.2f} {str(below) + ' ep' if below else 'never':>19} "
            f"{row['seconds']:>8.0f}" + (f"  table contacts {row['table_contacts']}" if "table_contacts" in row else "")
        )
    limit = result["generator_limit"]
    print(
        f"generator best reachable: mean {limit['mean_m'] * scale:.3f} {unit}, p90 {limit['p90_m'] * scale:.3f} {unit} "
        f"({limit['n_latents']} latent actions; coarser grids: "
        + ", ".join(f"{name} {mean * scale:.3f}" for name, mean in limit["coarser_grid_means_m"].items())
        + (
            f"; {limit['prior_samples']} prior samples {limit['prior_samples_mean_m'] * scale:.3f}"
            if limit.get("prior_samples_mean_m")
            else ""
        )
        + ")"
    )
    prior = (
        f", {result['ratio_prior_samples']:.2f} ({limit['prior_samples']} prior samples)"
        if "ratio_prior_samples" in result
        else ""
    )
    print(
        f"over seeds: {result['mean_m_over_seeds'] * scale:.3f} +- {result['std_m_over_seeds'] * scale:.3f} {unit} "
        f"(worst {result['worst_mean_m'] * scale:.3f}); ratio GenRL / generator's best reachable {result['ratio']:.2f} "
        f"(its {limit['n_latents']} latent actions){prior}"
    )


SETTINGS = {
    "hockey": Setting(task="hockey", target_m=0.05, unit="cm"),
    "basketball": Setting(task="basketball", target_m=0.10, unit="m", eval_every=1000),
}


def arguments(argv: list[str] | None = None) -> tuple[Setting, argparse.Namespace]:
    """The task's benchmark setting and the checked arguments (the GenRL settings joined and checked as GenRL will
    take them)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="hockey", choices=sorted(SETTINGS), help="a task (default: hockey)")
    parser.add_argument(
        "--data", type=EXISTING, default=None, help="the task's Minari dataset (default: make --demos demonstrations)"
    )
    parser.add_argument(
        "--generator", type=EXISTING, default=None, help="a trained generator (skips demonstrations and training)"
    )
    parser.add_argument("--demos", type=COUNT, default=None, help="demonstrations to make (default 4000)")
    parser.add_argument("--preset", type=str.upper, choices=tuple(PRESETS), default=None, help="default VAE1")
    parser.add_argument("--epochs", type=COUNT, default=None, help="generator epochs (default 300)")
    parser.add_argument("--episodes", type=COUNT, default=None, help="GenRL episodes (default: the task's)")
    parser.add_argument("--seeds", type=SEED, nargs="+", default=[0, 1, 2])
    parser.add_argument(
        "--eval-every", type=COUNT, default=None, help="episodes between evaluations (default: hockey 256, basketball 1000)"
    )
    parser.add_argument("--eval-goals", type=COUNT, default=100, help="goals per evaluation during training")
    parser.add_argument("--final-goals", type=COUNT, default=300, help="held-out goals of the final evaluation")
    parser.add_argument(
        "--grid",
        type=option(check_int, int, minimum=2),
        default=201,
        help="latent grid points per axis for the generator's limit",
    )
    parser.add_argument("--threads", type=COUNT, default=1, help="torch threads")
    parser.add_argument(
        "--genrl-kwargs",
        type=json_object_argument,
        default={},
        help="GenRL settings as JSON, laid over the task's (e.g. '{\"target_kl\": 0.02}')",
    )
    parser.add_argument(
        "--library-defaults",
        action="store_true",
        help="GenRL's own defaults (64 episodes per iteration, no hindsight) under --genrl-kwargs, "
        "instead of the task's settings",
    )
    parser.add_argument(
        "--out",
        type=JSON_OUT,
        default=None,
        help="JSON output, a PNG beside it (default: benchmarks/results/genrl_TASK.json, the result of "
        "the task's own settings; with --genrl-kwargs or --library-defaults, --out is needed)",
    )
    args = parser.parse_args(argv)
    setting = SETTINGS[args.task]
    for key in ("demos", "preset", "epochs", "episodes", "eval_every"):
        if getattr(args, key) is None:
            setattr(args, key, getattr(setting, key))
    if args.out is None:
        if args.genrl_kwargs or args.library_defaults:
            parser.error(
                f"{'--genrl-kwargs' if args.genrl_kwargs else '--library-defaults'} needs --out: the "
                "default output is the result of the task's own settings"
            )
        args.out = os.path.join(RESULTS, f"genrl_{setting.task}.json")
    # the task's settings (or none: GenRL's defaults), --genrl-kwargs laid over them, checked together
    args.genrl_kwargs = lay_over({} if args.library_defaults else setting.genrl_kwargs, args.genrl_kwargs)
    try:
        check_genrl_settings(args.genrl_kwargs)
    except (TypeError, ValueError) as error:
        parser.error(f"argument --genrl-kwargs: {error}")
    return setting, args


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark from the command line."""
    setting, args = arguments(argv)
    torch.set_num_threads(args.threads)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    result: dict[str, object] = {
        "benchmark": f"genrl_{setting.task}",
        **provenance(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "cpus": os.cpu_count(),
        "threads": args.threads,
        "episodes": args.episodes,
        "final_goals": args.final_goals,
        "final_goal_seed": EVAL_GOAL_SEED,
        "eval_goals": args.eval_goals,
        "target_m": setting.target_m,
        "genrl_kwargs": args.genrl_kwargs,
        # in effect on one env: the minibatch at most the iteration's episodes, as GenRL caps it
        "genrl_settings": effective_genrl_settings(
            args.genrl_kwargs, args.genrl_kwargs.get("n_steps", GENRL_SETTINGS["n_steps"].default), n_envs=1
        ),
        "runs": [],
    }
    with tempfile.TemporaryDirectory() as work:
        generator_path, result["generator"] = make_generator(setting.task, args.preset, args, work)
        start = time.perf_counter()
        goals = held_out_goals(setting.task, args.final_goals, EVAL_GOAL_SEED)
        limit = generator_limit(load(generator_path, device="cpu"), setting.task, goals, grid=args.grid)
        result["generator_limit"] = {
            **{f"{key}_m": value for key, value in limit["summary"].items()},
            "n_latents": limit["n_latents"],
            "coarser_grid_means_m": limit["coarser_grid_means"],
            "prior_samples": limit["prior_samples"],
            "prior_samples_mean_m": limit["prior_samples_mean"],
            "seconds": time.perf_counter() - start,
        }
        print(f"generator best reachable: {limit['summary']['mean'] * setting.scale:.3f} {setting.unit}", flush=True)
        for seed in args.seeds:
            row = run_seed(setting, generator_path, seed, args, work)
            row["ratio"] = row["mean_m"] / result["generator_limit"]["mean_m"]
            result["runs"].append(row)
            means = np.array([r["mean_m"] for r in result["runs"]])
            result.update(
                mean_m_over_seeds=float(means.mean()),
                std_m_over_seeds=float(means.std()),
                worst_mean_m=float(means.max()),
                ratio=float(means.mean() / result["generator_limit"]["mean_m"]),
            )
            if limit["prior_samples_mean"]:  # the same ratio against the prior samples' best reachable distance
                result["ratio_prior_samples"] = float(means.mean() / limit["prior_samples_mean"])
            atomic_write_json(args.out, result)
            plot(setting, result, os.path.splitext(args.out)[0] + ".png")
            print(f"seed {seed}: mean {row['mean_m'] * setting.scale:.3f} {setting.unit}", flush=True)
    print_table(setting, result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
