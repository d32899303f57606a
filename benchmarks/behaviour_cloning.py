"""What behaviour cloning's policies reach, and where their gap to the demonstrations comes from (issue: the README's
behaviour-cloning table), from the cloned policies a ``benchmarks/baselines.py`` run saved (``ppo/seedS/bc_policy.zip``).

For each seed's cloned policy, played deterministically:

- on the benchmark's 100 held-out goals: closed loop (its ``bc`` record, which the run measured), and the arm holding
  still on the same goals;
- on the demonstrations the cloning held out (whole episodes, the split of its early stopping): the cloned actions
  along each demonstration's own states, played open loop (its per-step errors without compounding), and the cloned
  policy closed loop on those demonstrations' goals (with compounding).

Usage::

    python -m benchmarks.behaviour_cloning --task hockey
    python -m benchmarks.behaviour_cloning --task basketball   # benchmarks/results/behaviour_cloning_basketball.json
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from typing import Any

import numpy as np
from sb3_genrl.baselines.bc import split_episodes
from sb3_genrl.baselines.evaluation import EVAL_GOALS
from sb3_genrl.baselines.feedback import add_time_feature, evaluate_feedback_policy, open_loop_rewards
from sb3_genrl.envs import arm_tasks, get_task
from stable_baselines3 import PPO

from sb3_genrl.checks import EXISTING, JSON_OUT, SEED
from sb3_genrl.data import load_transitions
from sb3_genrl.hyperparams import EVAL_GOAL_SEED
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_write_json

HERE = pathlib.Path(__file__).resolve().parent


class HoldStill:
    """A policy that never moves the arm."""

    def predict(self, observations: np.ndarray, deterministic: bool = True) -> tuple[np.ndarray, None]:
        return np.zeros((len(observations), 7), dtype=np.float32), None


def seed_result(run: pathlib.Path, task: str, transitions: dict[str, np.ndarray], seed: int) -> dict[str, Any]:
    """One seed's cloned policy on the held-out goals and on the demonstrations it held out."""
    summary = json.loads((run / "summary.json").read_text())
    policy = PPO.load(run / "bc_policy.zip", device="cpu")
    # the split the cloning's early stopping held out: its recorded share, drawn with the run's seed
    _, heldout = split_episodes(transitions["dones"], summary["settings"]["behaviour_cloning"]["holdout"], seed)
    observations = transitions["observations"][heldout]
    horizon = int(np.flatnonzero(transitions["dones"])[0]) + 1
    observations = observations.reshape(-1, horizon, observations.shape[-1])
    goals = observations[:, 0, :2]  # the observation starts with the goal's (x, y)
    if len(goals) != summary["bc"]["heldout_episodes"]:
        raise ValueError(
            f"{run}: {len(goals)} held-out demonstrations, but its cloning held out "
            f"{summary['bc']['heldout_episodes']}; were these its demonstrations?"
        )
    actions, _ = policy.predict(observations.reshape(-1, observations.shape[-1]), deterministic=True)
    closed = evaluate_feedback_policy(policy, task, goals=goals, allow_outside_region=True)["rewards"]
    open_loop = -open_loop_rewards(task, actions.reshape(len(goals), horizon, -1), goals, allow_outside_region=True)
    return {
        "seed": seed,
        "held_out_goals": {
            "deterministic": summary["bc"]["deterministic_distance"],
            "sampled": summary["bc"]["sampled_distance"],
        },
        "first_batch": summary.get("first_batch"),
        "held_out_demonstrations": len(goals),
        "open_loop_on_held_out_demonstrations": float(open_loop.mean()),
        "closed_loop_on_held_out_demonstrations": float(-closed.mean()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="hockey", choices=arm_tasks())
    parser.add_argument(
        "--work", type=EXISTING, help="the baselines benchmark's work folder (default: benchmarks/runs/baselines_TASK)"
    )
    parser.add_argument("--seeds", type=SEED, nargs="+", default=[0, 1, 2])
    parser.add_argument("--out", type=JSON_OUT, help="JSON (default: benchmarks/results/behaviour_cloning_TASK.json)")
    args = parser.parse_args(argv)
    spec = get_task(args.task)
    work = args.work or HERE / "runs" / f"baselines_{spec.name}"
    out = args.out or HERE / "results" / f"behaviour_cloning_{spec.name}.json"
    runs = [work / "ppo" / f"seed{seed}" for seed in args.seeds]
    missing = [str(run) for run in runs if not (run / "bc_policy.zip").exists() or not (run / "summary.json").exists()]
    if missing:
        parser.error(f"no finished PPO (BC) run in {missing}; run python -m benchmarks.baselines --methods ppo first")
    transitions = add_time_feature(load_transitions(work / "demonstrations", task=spec.name), spec.horizon)
    still = evaluate_feedback_policy(HoldStill(), spec.name, goals=EVAL_GOALS, seed=EVAL_GOAL_SEED)
    result = {
        "task": spec.name,
        "goals": EVAL_GOALS,
        "goal_seed": EVAL_GOAL_SEED,
        "work": str(work),
        "arm_holding_still": float(-still["rewards"].mean()),
        "seeds": [],
    }
    for seed, run in zip(args.seeds, runs, strict=True):
        result["seeds"].append(seed_result(run, spec.name, transitions, seed))
        print(json.dumps(result["seeds"][-1]), flush=True)
    atomic_write_json(out, provenance() | result)
    print(f"arm holding still: {result['arm_holding_still']:.3f} m -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
