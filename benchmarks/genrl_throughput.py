"""GenRL's throughput with each task's settings: episodes per wall second against the open-loop bound on the same
cores, and the shares of the run's time in simulation, in decoding and in updates.

Shares are of GenRL's loop (``learn``: collection and updates, without the run's set-up and outputs). For each task,
trains GenRL with its settings (``hyperparams/genrl.yml``) for ``--episodes`` episodes through
:func:`sb3_genrl.run.train_policy`, once per ``--n-envs`` (``2``: the quickstart's; ``N``: all of an iteration's
episodes in one fast-path call), timing the fast path's ``play_trajectories`` calls (simulation), the generator's
``decode`` calls (decoding) and GenRL's ``train`` (updates), and within the updates each of :data:`UPDATE_PARTS`
(their shares of the updates: ``update_parts_share``). In the same run it measures the open-loop bound on all
cores: the episodes GenRL played (a sample of them) and the scripted ones of ``benchmarks/sim_throughput.py``, each
played in one ``play_trajectories`` call on every core (best of ``--repeats``). With ``--cli``, each task also gets
the row "the CLI's default command": ``genrl train-policy --task TASK --generator G --episodes E --out R`` with
nothing else, timed as a whole process (start-up, set-up and outputs included; best of ``--repeats``) against the
scripted open-loop bound.
Writes JSON with the load average.

    python -m benchmarks.genrl_throughput --generator hockey=quickstart/vae.pt --generator basketball=qs_b/vae.pt

With ``--update``, the runs measured replace those of the same task and ``n_envs`` in ``--out`` and the others are
kept, each run with the command and the load average of its own invocation: a benchmark too long for one quiet
window on a shared machine is measured in parts (``--generator basketball=... --n-envs N --update``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import torch
from sb3_genrl.envs import get_task

from benchmarks.sim_throughput import open_loop_rate, scripted_episodes
from sb3_genrl.checks import COUNT, JSON_OUT, check_input_path
from sb3_genrl.generative import load
from sb3_genrl.genrl import GenRL
from sb3_genrl.genrl.hindsight import HindsightRelabelling
from sb3_genrl.markdown import markdown_table
from sb3_genrl.provenance import provenance
from sb3_genrl.run import train_policy
from sb3_genrl.study.quickstart import task_settings
from sb3_genrl.utils import atomic_write_json
from sb3_genrl.vec_env import default_threads

# The parts of GenRL's update timed on their own: the kept relabelled pulls joining the batch, the E-step (the
# conjugate gradient and the line search), the regression of the policy's mean on the kept pulls, the value fit
UPDATE_PARTS = ("relabelled_pulls", "e_step", "regression", "value_fit")
EPISODES = {"hockey": 960, "basketball": 1920}  # 30 and 120 iterations of the tasks' 32 and 16 episodes


@contextlib.contextmanager
def timed(owner: Any, name: str, seconds: dict[str, float], key: str, keep: list | None = None) -> Iterator[None]:
    """While in the block, add the time of every call of ``owner.name`` to ``seconds[key]`` (and keep the first two
    arguments of each call in ``keep``)."""
    original = getattr(owner, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            seconds[key] += time.perf_counter() - start
            if keep is not None:
                keep.append(args[1:3])

    setattr(owner, name, wrapper)
    try:
        yield
    finally:
        setattr(owner, name, original)


def run_genrl(task: str, generator_path: str, episodes: int, n_envs: int, threads: int, work: str) -> dict[str, Any]:
    """One GenRL run with the task's settings; its wall time and the time in each part, and what it played."""
    _, batch_episodes, genrl_kwargs = task_settings(task)
    generator = load(generator_path, device="cpu")
    task_class = type(get_task(task).make_env())
    seconds = {"simulation": 0.0, "decoding": 0.0, "updates": 0.0, "learn": 0.0}
    parts = dict.fromkeys(UPDATE_PARTS, 0.0)  # the parts of the updates (inside GenRL.train)
    played: list[tuple[np.ndarray, np.ndarray]] = []
    with (
        timed(task_class, "play_trajectories", seconds, "simulation", played),
        timed(type(generator), "decode", seconds, "decoding"),
        timed(GenRL, "train", seconds, "updates"),
        timed(GenRL, "learn", seconds, "learn"),
        timed(HindsightRelabelling, "extend_batch", parts, "relabelled_pulls"),
        timed(GenRL, "_e_step", parts, "e_step"),
        timed(HindsightRelabelling, "regress", parts, "regression"),
        timed(GenRL, "_fit_value_function", parts, "value_fit"),
    ):
        start = time.perf_counter()
        summary = train_policy(
            task,
            generator,
            episodes=episodes,
            batch_episodes=batch_episodes,
            n_envs=n_envs,
            n_threads=threads,
            seed=0,
            out_dir=os.path.join(work, f"{task}_{n_envs}"),
            device="cpu",
            checkpoint_every=None,
            **genrl_kwargs,
        )
        wall = time.perf_counter() - start
    learn = seconds.pop("learn")  # GenRL's loop: the run without its set-up and its outputs (model, curve, plot)
    row = {
        "task": task,
        "n_envs": n_envs,
        "batch_episodes": batch_episodes,
        "episodes": summary["episodes"],
        "wall_seconds": wall,
        "learn_seconds": learn,
        "episodes_per_second": summary["episodes"] / learn,
        "episodes_per_second_with_set_up": summary["episodes"] / wall,
        **{f"{key}_seconds": value for key, value in seconds.items()},
        **{f"{key}_share": value / learn for key, value in seconds.items()},
        "final_mean_reward": summary["final_mean_reward"],
        "updates_per_iteration_seconds": seconds["updates"] / summary["iterations"],
        "update_parts_share": {key: value / seconds["updates"] for key, value in parts.items()},
    }
    row["other_share"] = 1.0 - sum(row[f"{key}_share"] for key in seconds)  # policy, SB3's loop, the wrappers
    return row | {"played": played}


def run_cli(task: str, generator_path: str, episodes: int, work: str, repeats: int) -> dict[str, Any]:
    """The CLI's default command on ``task``, timed as a whole process, ``repeats`` times (a new run folder each):
    its episodes per wall second at the fastest, as the bound is the best of its repeats."""
    walls = []
    for repeat in range(repeats):
        out = os.path.join(work, f"{task}_cli_{repeat}")
        argv = ["--task", task, "--generator", generator_path, "--episodes", str(episodes), "--out", out]
        start = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "sb3_genrl.cli", "train-policy", *argv, "--no-progress-bar"],
            capture_output=True,
            text=True,
            check=False,
        )
        walls.append(time.perf_counter() - start)
        if done.returncode:
            raise RuntimeError(f"genrl train-policy failed: {done.stderr.strip().splitlines()[-1:]}")
        with open(os.path.join(out, "summary.json")) as file:
            summary = json.load(file)
    return {
        "task": task,
        "n_envs": f"cli ({summary['n_envs']})",
        "cli_command": "genrl train-policy " + " ".join(argv[:4]) + f" --episodes {episodes} --out R",
        "episodes": summary["episodes"],
        "wall_seconds": min(walls),
        "wall_seconds_each": walls,
        "episodes_per_second": summary["episodes"] / min(walls),
    }


def played_sample(played: list[tuple[np.ndarray, np.ndarray]], n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` of the trajectories and goals a run played (evenly spaced over the run)."""
    trajectories = np.concatenate([np.asarray(t, dtype=np.float64).reshape(-1, *np.shape(t)[-2:]) for t, _ in played])
    goals = np.concatenate([np.asarray(g, dtype=np.float64).reshape(-1, 2) for _, g in played])
    keep = np.linspace(0, len(trajectories) - 1, min(n, len(trajectories))).astype(int)
    return trajectories[keep], goals[keep]


def measure_task(task: str, generator_path: str, args: argparse.Namespace, work: str) -> list[dict[str, Any]]:
    threads, episodes = args.threads, args.episodes or EPISODES[task]
    env = get_task(task).make_env()
    scripted = open_loop_rate(env, *scripted_episodes(task, env, args.bound_episodes), threads, args.repeats)
    rows = []
    for n_envs in args.n_envs:
        n_envs = task_settings(task)[1] if n_envs == "N" else int(n_envs)
        row = run_genrl(task, generator_path, episodes, n_envs, threads, work)
        bound = open_loop_rate(env, *played_sample(row.pop("played"), args.bound_episodes), threads, args.repeats)
        row.update(
            threads=threads,
            open_loop_bound=bound,
            scripted_open_loop_bound=scripted,
            share_of_bound=row["episodes_per_second"] / bound,
            collection_share_of_bound=row["episodes"] / (row["learn_seconds"] - row["updates_seconds"]) / bound,
        )
        print(
            f"{task} n_envs={n_envs}: {row['episodes_per_second']:.1f} episodes/s, {row['share_of_bound']:.2f} of "
            f"the bound ({bound:.1f}); updates {row['updates_share']:.0%} ("
            + ", ".join(f"{key} {share:.0%}" for key, share in row["update_parts_share"].items())
            + ")",
            flush=True,
        )
        rows.append(row)
    if args.cli:
        row = run_cli(task, generator_path, episodes, work, args.repeats)
        row.update(threads=threads, open_loop_bound=scripted, share_of_bound=row["episodes_per_second"] / scripted)
        print(
            f"{task} {row['cli_command']}: {row['episodes_per_second']:.1f} episodes/s, {row['share_of_bound']:.2f} of the "
            f"scripted bound ({scripted:.1f}), whole command",
            flush=True,
        )
        rows.append(row)
    env.close()
    return rows


def run_kind(row: dict[str, Any]) -> str:
    """What a run measured, whatever its task's batch: ``"cli"`` (the CLI's command), ``"N"`` (an iteration's
    episodes as envs) or its number of envs."""
    if "cli_command" in row:
        return "cli"
    return "N" if row["n_envs"] == row["batch_episodes"] else str(row["n_envs"])


def updated_runs(path: str, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``rows``, and the runs in the JSON at ``path`` (if any) of the tasks and kinds (:func:`run_kind`) not among
    them, so that a task whose batch changed replaces its ``N`` and CLI rows; in the order of :data:`EPISODES`' tasks,
    then of ``n_envs`` (numbers first)."""
    measured = {(row["task"], run_kind(row)) for row in rows}
    kept = []
    if os.path.exists(path):
        with open(path) as file:
            kept = [row for row in json.load(file)["runs"] if (row["task"], run_kind(row)) not in measured]

    def order(row: dict[str, Any]) -> tuple[int, bool, int, str]:
        n_envs = row["n_envs"]
        numbered = isinstance(n_envs, int)
        return list(EPISODES).index(row["task"]), not numbered, n_envs if numbered else 0, str(n_envs)

    return sorted(kept + rows, key=order)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--generator",
        action="append",
        required=True,
        metavar="TASK=PATH",
        help="the generator of a task (e.g. a quickstart's vae.pt); the tasks measured are these",
    )
    parser.add_argument("--episodes", type=COUNT, default=None, help=f"GenRL episodes per run (default {EPISODES})")
    parser.add_argument(
        "--n-envs",
        nargs="*",
        default=["2", "N"],
        help="envs per step: numbers, N: an iteration's; none (with --cli): only the CLI's command",
    )
    parser.add_argument("--threads", type=COUNT, default=default_threads(), help="simulation threads (all cores)")
    parser.add_argument("--bound-episodes", type=COUNT, default=256)
    parser.add_argument("--repeats", type=COUNT, default=2, help="the bound's and the CLI's command's, best of")
    parser.add_argument("--out", type=JSON_OUT, default="benchmarks/results/genrl_throughput.json")
    parser.add_argument("--update", action="store_true", help="keep --out's runs of other tasks and n_envs")
    parser.add_argument("--cli", action="store_true", help="also time the CLI's default command, as a whole process")
    args = parser.parse_args()
    if not args.n_envs and not args.cli:
        parser.error("--n-envs with no value measures only the CLI's command, which needs --cli")
    generators = dict(item.split("=", 1) if "=" in item else (item, "") for item in args.generator)
    for task, path in generators.items():
        if task not in EPISODES:
            parser.error(f"--generator {task}=...: the tasks measured are {', '.join(EPISODES)}")
        check_input_path(path, "--generator")
    torch.set_num_threads(1)  # as the quickstart: the models are small, one thread is as fast
    command = (
        "python -m benchmarks.genrl_throughput "
        + " ".join(f"--generator {task}=..." for task in generators)
        + (" --n-envs" + "".join(f" {n_envs}" for n_envs in args.n_envs) + " --update" if args.update else "")
        + (" --cli" if args.cli else "")
        + (f" --repeats {args.repeats}" if args.repeats != 2 else "")
    )
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as work:
        rows = [row for task, path in generators.items() for row in measure_task(task, path, args, work)]
    for row in rows:
        row.update(command=command, load_average_before=load_before, load_average_after=os.getloadavg())
    rows = updated_runs(args.out, rows) if args.update else rows
    header = (
        "task",
        "n_envs",
        "episodes/s",
        "bound",
        "share",
        "simulation",
        "decoding",
        "updates",
        "other",
        "of the updates: " + " / ".join(UPDATE_PARTS),
    )
    print(
        markdown_table(
            header,
            [
                [
                    r["task"],
                    r["n_envs"],
                    f"{r['episodes_per_second']:.1f}",
                    f"{r['open_loop_bound']:.1f}",
                    f"{r['share_of_bound']:.2f}",
                    *(
                        f"{r[f'{k}_share']:.0%}" if f"{k}_share" in r else "-"
                        for k in ("simulation", "decoding", "updates", "other")
                    ),
                    " / ".join(f"{r['update_parts_share'][k]:.0%}" for k in UPDATE_PARTS)
                    if "update_parts_share" in r
                    else "not measured (a whole command)"
                    if "cli_command" in r
                    else "not measured",
                ]
                for r in rows
            ],
        )
    )
    atomic_write_json(
        args.out,
        provenance()
        | {
            "command": command,
            "machine": platform.processor() or platform.machine(),
            "cores": default_threads(),
            "load_average_before": load_before,
            "load_average_after": os.getloadavg(),
            "runs": rows,
        },
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
