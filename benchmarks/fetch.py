"""GenRL on Gymnasium-Robotics' Fetch tasks: the deterministic policy's success rate on held-out initial states.

Makes the task's demonstrations (or reads ``--data``), trains the quickstart's generator for the Fetch tasks (VAE9,
300 epochs; or reads ``--generator``), measures the generator's own limit (the share of ``--limit-states`` held-out
initial states that some of ``--prior-draws`` draws from its prior solves), then trains GenRL with the task's entry in
``hyperparams/genrl.yml`` and several seeds. Every ``--eval-every`` episodes and at the end, each seed's deterministic
policy plays ``--eval-states`` held-out initial states (seeds from :data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`); the
curve is against episodes and environment steps (50 per episode). The JSON is written after every evaluation, so an
interrupted run keeps what it finished (default: ``benchmarks/results/fetch_TASK.json``).

    python benchmarks/fetch.py --task fetch-push                   # 3 seeds x 3000 episodes, 500 held-out states
    python benchmarks/fetch.py --task fetch-reach --seeds 0 --eval-states 100
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numpy as np
import torch
from sb3_genrl.benchmarks.genrl import make_generator
from sb3_genrl.envs import TASKS, get_task
from sb3_genrl.envs.fetch import FETCH_HORIZON
from sb3_genrl.envs.fetch_demonstrations import evaluate_success, play_expert
from stable_baselines3.common.callbacks import BaseCallback

from sb3_genrl import __version__
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED
from sb3_genrl.generative import load
from sb3_genrl.genrl.train import genrl_settings, make_genrl
from sb3_genrl.hyperparams import EVAL_GOAL_SEED
from sb3_genrl.study.quickstart import quickstart_preset, task_settings
from sb3_genrl.utils import atomic_write_json

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
FETCH_TASKS = sorted(name for name in TASKS if name.startswith("fetch-"))


class SuccessCurve(BaseCallback):
    """Every ``every`` episodes: the deterministic policy's success rate on the held-out states, kept and written."""

    def __init__(self, task: str, every: int, states: int, record: dict, write) -> None:
        super().__init__()
        self.task, self.every, self.states, self.record, self.write = task, every, states, record, write
        self.next = every

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.next:
            self.next += self.every
            self.evaluate()
        return True

    def evaluate(self) -> None:
        result = evaluate_success(self.model, self.task, episodes=self.states, seed=EVAL_GOAL_SEED)
        self.record["curve_episodes"].append(int(self.num_timesteps))
        self.record["curve_env_steps"].append(int(self.num_timesteps) * FETCH_HORIZON)
        self.record["curve_success"].append(result["success_rate"])
        self.write()


def generator_limit(task: str, generator_path: str, states: int, draws: int) -> dict[str, object]:
    """The share of held-out initial states that at least one of ``draws`` prior draws solves (open-loop)."""
    generator, env_id = load(generator_path, device="cpu"), get_task(task).env_id
    rng = np.random.default_rng(0)
    solved = []
    for i in range(states):
        trajectories = np.clip(generator.decode(generator.sample_prior(draws, rng)), -1.0, 1.0).astype(np.float32)
        solved.append(any(play_expert(env_id, tau, EVAL_GOAL_SEED + i, None)["is_success"] for tau in trajectories))
    return {"states": states, "prior_draws": draws, "success_rate": float(np.mean(solved))}


def run_seed(task: str, generator_path: str, seed: int, args: argparse.Namespace, row: dict, write) -> None:
    """Train GenRL with one seed, evaluating every ``--eval-every`` episodes and at the end (into ``row``)."""
    import gymnasium as gym

    episodes, batch_episodes, genrl_kwargs = task_settings(task)
    model = make_genrl(gym.make(get_task(task).env_id), load(generator_path, device="cpu"), seed=seed, device="cpu",
                       n_steps=batch_episodes, **genrl_kwargs)
    curve = SuccessCurve(task, args.eval_every, args.eval_states, row, write)
    start = time.perf_counter()
    model.learn(args.episodes or episodes, callback=curve)
    row["seconds"] = time.perf_counter() - start
    if not row["curve_episodes"] or row["curve_episodes"][-1] != model.num_timesteps:
        curve.evaluate()
    row["final_success"] = row["curve_success"][-1]
    write()


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True, choices=FETCH_TASKS, help="a Fetch task")
    parser.add_argument("--data", type=EXISTING, default=None, help="the task's dataset (default: make --demos)")
    parser.add_argument("--generator", type=EXISTING, default=None, help="a trained generator")
    parser.add_argument("--demos", type=COUNT, default=4000, help="demonstrations to make (default 4000)")
    parser.add_argument("--epochs", type=COUNT, default=300, help="generator epochs (default 300)")
    parser.add_argument("--episodes", type=COUNT, default=None, help="GenRL episodes (default: the task's)")
    parser.add_argument("--seeds", type=SEED, nargs="+", default=[0, 1, 2])
    parser.add_argument("--eval-every", type=COUNT, default=500, help="episodes between evaluations (default 500)")
    parser.add_argument("--eval-states", type=COUNT, default=500, help="held-out initial states per evaluation")
    parser.add_argument("--limit-states", type=COUNT, default=20, help="held-out states of the generator's limit")
    parser.add_argument("--prior-draws", type=COUNT, default=1000, help="prior draws per state of the generator's limit")
    parser.add_argument("--threads", type=COUNT, default=2, help="demonstration worker processes")
    parser.add_argument("--out", type=JSON_OUT, default=None, help="JSON output (default: results/fetch_TASK.json)")
    args = parser.parse_args(argv)
    args.out = args.out or os.path.join(RESULTS, f"fetch_{args.task}.json")
    return args


def main(argv: list[str] | None = None) -> None:
    args = arguments(argv)
    torch.set_num_threads(1)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    _, _, genrl_kwargs = task_settings(args.task)
    result: dict[str, object] = {
        "benchmark": f"fetch_{args.task}", "task": args.task, "env_id": get_task(args.task).env_id,
        "sb3_genrl": __version__, "torch": torch.__version__, "machine": platform.machine(), "cpus": os.cpu_count(),
        "episodes": args.episodes or task_settings(args.task)[0], "eval_states": args.eval_states,
        "eval_seed": EVAL_GOAL_SEED, "genrl_kwargs": genrl_kwargs, "genrl_settings": genrl_settings(genrl_kwargs),
        "runs": []}

    def write() -> None:
        finals = [run["final_success"] for run in result["runs"] if "final_success" in run]
        if finals:
            result.update(final_success_mean=float(np.mean(finals)), final_success_std=float(np.std(finals)))
        atomic_write_json(args.out, result)

    with tempfile.TemporaryDirectory() as work:
        generator_path, result["generator"] = make_generator(args.task, quickstart_preset(args.task), args, work,
                                                             threads=args.threads)
        result["generator_limit"] = generator_limit(args.task, generator_path, args.limit_states, args.prior_draws)
        write()
        for seed in args.seeds:
            row = {"seed": seed, "curve_episodes": [], "curve_env_steps": [], "curve_success": []}
            result["runs"].append(row)
            run_seed(args.task, generator_path, seed, args, row, write)
            print(f"seed {seed}: success {row['final_success']:.3f} after {row['curve_episodes'][-1]} episodes "
                  f"({row['seconds']:.0f} s)", flush=True)
    print(f"GenRL on {args.task}: {result.get('final_success_mean', float('nan')):.3f} mean final success; the "
          f"generator's prior draws solve {result['generator_limit']['success_rate']:.3f} of the states; wrote {args.out}")


if __name__ == "__main__":
    main()
