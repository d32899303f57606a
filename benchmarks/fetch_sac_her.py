"""The package's SAC+HER on a Fetch task (SB3's SAC and ``HerReplayBuffer``), with or without the task's
demonstrations in its buffer: the deterministic policy's success on the Fetch benchmark's held-out initial states.

Settings: ``benchmarks/sac_her_fetch.yml`` (rl-zoo3's SAC FetchReach-v1 entry with 2 x 256 networks, for every task);
budget: GenRL's (the entry's ``n_timesteps``). ``--variant demos`` writes the demonstrations (the Fetch benchmark's
dataset, ``runs/fetch/TASK/demonstrations``, at most 4000) into the buffer before the first step, as transitions
relabelled by HER like SAC's own (:func:`sb3_genrl.baselines.her.fetch_goal_episodes`); ``--variant none`` starts
empty. Both normalise the observation with the demonstrations' fixed statistics. Every ``--eval-every`` episodes and
at the end, the deterministic policy plays ``--eval-states`` initial states (reset seeds from
:data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`). Each seed checkpoints (model and buffer, as one unit) every
``--checkpoint-every`` episodes in ``--work`` and resumes from it; the JSON is written after every evaluation and says
``"complete": true`` once seeds 0, 1 and 2 have finished, whichever runs wrote them.

    python -m benchmarks.fetch_sac_her --task fetch-reach --variant demos
    python -m benchmarks.fetch_sac_her --task fetch-push --variant none --seeds 0
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import time

import gymnasium as gym
import numpy as np
import torch
import yaml
from sb3_genrl.baselines.checkpoint import ReplayBufferCheckpoint, resume_off_policy
from sb3_genrl.baselines.her import add_goal_demonstrations, fetch_goal_episodes, goal_statistics
from sb3_genrl.baselines.normalization import NormalizedCombined
from sb3_genrl.baselines.train import CHECKPOINT_EVERY
from sb3_genrl.envs import get_task
from sb3_genrl.envs.fetch import FETCH_HORIZON
from sb3_genrl.envs.fetch_mujoco import fix_joint_helpers
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.her import HerReplayBuffer

from benchmarks.fetch_results import (
    BENCHMARK_SEEDS,
    UNRECORDED_DEMONSTRATION_RECIPE,
    all_seeds_finished,
    dataset_recipe,
    seed_row,
    write_result,
)
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED
from sb3_genrl.curves import episode_info
from sb3_genrl.data import dataset_info, load_arrays
from sb3_genrl.hyperparams import EVAL_GOAL_SEED, parse_kwargs
from sb3_genrl.provenance import provenance
from sb3_genrl.run.checkpoint import resume_state

HERE = os.path.dirname(os.path.abspath(__file__))
SETTINGS = os.path.join(HERE, "sac_her_fetch.yml")


# what a resumed JSON must share with the run that continues it
RESUME_KEYS = ("benchmark", "settings", "demonstrations", "demonstration_recipe", "eval_states", "eval_seed", "eval_every")
ZOO_ONLY = ("n_timesteps", "policy", "normalize", "replay_buffer_class", "replay_buffer_kwargs", "policy_kwargs")


def entry(env_id: str) -> dict:
    with open(SETTINGS) as file:
        settings = yaml.safe_load(file)[env_id]
    return settings | {key: parse_kwargs(settings[key]) for key in ("replay_buffer_kwargs", "policy_kwargs")}


def success_rate(model: SAC, env_id: str, states: int) -> float:
    """The deterministic policy's success (``info["is_success"]`` at the last step) from ``states`` reset seeds."""
    fix_joint_helpers()
    env = gym.make(env_id)
    successes = []
    for i in range(states):
        obs, _ = env.reset(seed=EVAL_GOAL_SEED + i)
        for _ in range(FETCH_HORIZON):
            obs, _, _, _, info = env.step(model.predict(obs, deterministic=True)[0])
        successes.append(float(info["is_success"]))
    env.close()
    return float(np.mean(successes))


class Curve(BaseCallback):
    """Every ``every`` episodes (at an episode's end), the held-out success into ``row``, then ``write()``."""

    def __init__(self, env_id: str, every: int, states: int, row: dict, write) -> None:
        super().__init__()
        self.env_id, self.every, self.states, self.row, self.write = env_id, every, states, row, write

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:
        episodes = int(self.model.num_timesteps) // FETCH_HORIZON
        if (
            episodes
            and self.model.num_timesteps % FETCH_HORIZON == 0
            and episodes % self.every == 0
            and episodes not in self.row["curve_episodes"]
        ):
            self.evaluate(episodes)

    def evaluate(self, episodes: int) -> None:
        self.row["curve_episodes"].append(episodes)
        self.row["curve_env_steps"].append(episodes * FETCH_HORIZON)
        self.row["curve_success"].append(success_rate(self.model, self.env_id, self.states))
        self.write()
        print(f"  seed {self.row['seed']}, {episodes} episodes: success {self.row['curve_success'][-1]:.3f}", flush=True)


def run_seed(args: argparse.Namespace, episodes_data: dict, seed: int, row: dict, write) -> None:
    env_id = get_task(args.task).env_id
    settings = entry(env_id)
    steps = args.steps or int(settings["n_timesteps"])
    folder = pathlib.Path(args.work) / f"{args.variant}_seed_{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    identity = {
        "task": args.task,
        "variant": args.variant,
        "seed": seed,
        "steps": steps,
        "settings": json.loads(json.dumps(settings, default=str)),
        "demonstrations": int(len(episodes_data["rewards"])),
    }
    state = resume_state(folder, identity)
    env = Monitor(episode_info(gym.make(env_id)))
    plain = {key: value for key, value in settings.items() if key not in ZOO_ONLY}
    policy_kwargs = settings["policy_kwargs"] | {
        "features_extractor_class": NormalizedCombined,
        "features_extractor_kwargs": {"statistics": goal_statistics(episodes_data)},
    }
    n_demos = int(np.prod(episodes_data["rewards"].shape)) if args.variant == "demos" else 0
    if state is None:
        row.update(curve_episodes=[], curve_env_steps=[], curve_success=[])
        model = SAC(
            settings["policy"],
            env,
            replay_buffer_class=HerReplayBuffer,
            device="cpu",
            seed=seed,
            replay_buffer_kwargs=settings["replay_buffer_kwargs"],
            policy_kwargs=policy_kwargs,
            buffer_size=n_demos + steps,
            **plain,
        )
        if args.variant == "demos":
            add_goal_demonstrations(model, episodes_data)
            model.learning_starts = 0  # the demonstrations are the warm-up data
    else:
        model = resume_off_policy(state, env, device="cpu")
        kept = sum(e <= state["episodes"] for e in row["curve_episodes"])
        row.update({key: row[key][:kept] for key in ("curve_episodes", "curve_env_steps", "curve_success")})
    curve = Curve(env_id, args.eval_every, args.eval_states, row, write)
    checkpoint = ReplayBufferCheckpoint(folder, args.checkpoint_every, identity, state, {})
    begin = time.perf_counter()
    model.learn(steps - model.num_timesteps, callback=CallbackList([curve, checkpoint]), reset_num_timesteps=state is None)
    row["seconds"] = row.get("seconds", 0.0) + time.perf_counter() - begin
    episodes = int(model.num_timesteps) // FETCH_HORIZON
    if episodes not in row["curve_episodes"]:
        curve.evaluate(episodes)
    row.update(final_success=row["curve_success"][-1], episodes=episodes, env_steps=int(model.num_timesteps), finished=True)
    write()
    env.close()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True, choices=("fetch-reach", "fetch-push", "fetch-pick-and-place", "fetch-slide"))
    parser.add_argument("--variant", required=True, choices=("demos", "none"), help="demonstrations in the buffer")
    parser.add_argument("--data", type=EXISTING, default=None, help="the dataset (default runs/fetch/TASK/demonstrations)")
    parser.add_argument("--seeds", type=SEED, nargs="+", default=list(BENCHMARK_SEEDS))
    parser.add_argument("--eval-every", type=COUNT, default=None, help="episodes between evaluations (default: a sixth)")
    parser.add_argument("--eval-states", type=COUNT, default=500)
    parser.add_argument(
        "--checkpoint-every",
        type=COUNT,
        default=None,
        help=f"episodes between checkpoints (default: the evaluations', at most {CHECKPOINT_EVERY}, as genrl baseline)",
    )
    parser.add_argument("--steps", type=COUNT, default=None, help="environment steps (default: the entry's n_timesteps)")
    parser.add_argument("--work", default=None, help="run folders (default runs/fetch_sac_her/TASK)")
    parser.add_argument(
        "--out", type=JSON_OUT, default=None, help="JSON (default runs/fetch_sac_her/fetch_sac_her_TASK_VARIANT.json)"
    )
    args = parser.parse_args(argv)
    root = os.path.join(os.path.dirname(HERE), "runs")
    data = args.data or os.path.join(root, "fetch", args.task, "demonstrations")
    if not os.path.isdir(data):
        parser.error(f"no demonstrations at {data}: run python -m benchmarks.fetch --task {args.task} first, or give --data")
    args.work = args.work or os.path.join(root, "fetch_sac_her", args.task)
    args.out = args.out or os.path.join(root, "fetch_sac_her", f"fetch_sac_her_{args.task}_{args.variant}.json")
    episodes = (args.steps or int(entry(get_task(args.task).env_id)["n_timesteps"])) // FETCH_HORIZON
    args.eval_every = args.eval_every or max(32, round(episodes / 6 / 32) * 32)
    # a checkpoint does not change the run (it draws no random numbers); it bounds what a stopped run plays again
    args.checkpoint_every = args.checkpoint_every or min(args.eval_every, CHECKPOINT_EVERY)
    torch.set_num_threads(1)
    episodes_data = fetch_goal_episodes(args.task, load_arrays(data))
    result = {
        **provenance(),
        "benchmark": f"fetch_sac_her_{args.task}_{args.variant}",
        "task": args.task,
        "variant": args.variant,
        "settings_file": "benchmarks/sac_her_fetch.yml",
        "settings": entry(get_task(args.task).env_id),
        "demonstrations": int(len(episodes_data["rewards"])) if args.variant == "demos" else 0,
        # the recipe of the dataset (GenRL's, the same demonstrations), as its info records it
        "demonstration_recipe": None if args.variant == "none" else dataset_recipe(args.task, dataset_info(data)),
        "eval_states": args.eval_states,
        "eval_seed": EVAL_GOAL_SEED,
        "eval_every": args.eval_every,
        "complete": False,
        "runs": [],
    }
    if os.path.exists(args.out):  # resumed: only a run of the same settings
        with open(args.out) as file:
            kept = json.load(file)
        if args.variant == "demos":  # a file of an earlier version, which did not record the recipe
            kept.setdefault("demonstration_recipe", UNRECORDED_DEMONSTRATION_RECIPE)
        kept.setdefault("demonstration_recipe", None)
        differ = sorted(key for key in RESUME_KEYS if kept.get(key) != result[key])
        if differ:
            raise SystemExit(f"{args.out} holds another run (it differs in {', '.join(differ)}): give another --out")
        result = kept | {"complete": False}

    def write() -> None:
        write_result(args.out, result)

    for seed in args.seeds:
        row = seed_row(result, seed)
        if not row["finished"]:
            run_seed(args, episodes_data, seed, row, write)
    result["complete"] = all_seeds_finished(result)
    write()
    print(
        f"SAC+HER ({args.variant}) on {args.task}: {result['final_success_mean']:.3f} over {result['finished_seeds']} "
        f"seeds ({'complete' if result['complete'] else 'partial'}); wrote {args.out}"
    )


if __name__ == "__main__":
    main()
