"""Simulation throughput of the tasks: the fast open-loop path (1 and 2 threads), the step-by-step Gymnasium path,
and the bound (raw ``mj_step`` over the same number of physics steps per episode).

    python -m benchmarks.sim_throughput [--episodes 256] [--out benchmarks/results/sim_throughput.json]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
from sb3_genrl.envs.basketball import BasketballEnv, scripted_throw
from sb3_genrl.envs.hockey import HockeyEnv, scripted_hit

from sb3_genrl.checks import COUNT, JSON_OUT
from sb3_genrl.markdown import markdown_table
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_write_json


def _trajectories(task: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if task == "hockey":
        return np.stack([scripted_hit(strength=s, direction=d) for s, d in rng.uniform([0.7, -0.4], [1.3, 0.4], (n, 2))])
    return np.stack([scripted_throw(strength=s, yaw=y) for s, y in rng.uniform([0.6, -1.2], [1.2, 1.2], (n, 2))])


def scripted_episodes(task: str, env, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` scripted trajectories of the task's expert and ``n`` goals, from seed 0 (what this benchmark plays)."""
    rng = np.random.default_rng(0)
    trajectories = _trajectories(task, n, rng)
    return trajectories, np.array([env.sample_goal(rng) for _ in range(n)])


def open_loop_rate(env, trajectories: np.ndarray, goals: np.ndarray, threads: int, repeats: int) -> float:
    """Episodes per second of the fast path playing all ``trajectories`` in one call on ``threads`` threads (best of
    ``repeats``)."""
    return len(trajectories) / _best_of(repeats, lambda: env.play_trajectories(trajectories, goals, n_threads=threads))


def _best_of(repeats: int, fn) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def measure(task: str, episodes: int, step_episodes: int, repeats: int) -> dict:
    env = HockeyEnv() if task == "hockey" else BasketballEnv()
    trajectories, goals = scripted_episodes(task, env, episodes)
    physics_steps = (env.horizon + env.settle_steps) * env.frame_skip
    # The same commanded joint positions the open-loop path sends, held after the last action.
    commands = env.home_qpos() + np.cumsum(np.clip(trajectories, -env.max_joint_delta, env.max_joint_delta), axis=1)
    commands = np.concatenate([commands, np.repeat(commands[:, -1:], env.settle_steps, axis=1)], axis=1)

    def raw_bound():
        data = mujoco.MjData(env.model)
        for i in range(episodes):
            mujoco.mj_setState(env.model, data, env.initial_state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
            for command in commands[i]:
                data.ctrl[:] = command
                mujoco.mj_step(env.model, data, nstep=env.frame_skip)

    def step_path():
        for i in range(step_episodes):
            env.reset(seed=i, options={"goal": goals[i]})
            for action in trajectories[i]:
                if env.step(action)[2]:
                    break

    results = {"task": task, "episodes": episodes, "physics_steps_per_episode": physics_steps}
    results["raw_mj_step"] = episodes / _best_of(repeats, raw_bound)
    for threads in (1, 2):
        results[f"open_loop_{threads}_thread"] = open_loop_rate(env, trajectories, goals, threads, repeats)
    results["step_by_step"] = step_episodes / _best_of(repeats, step_path)
    results["open_loop_1_thread_vs_bound"] = results["open_loop_1_thread"] / results["raw_mj_step"]
    results["step_by_step_vs_bound"] = results["step_by_step"] / results["raw_mj_step"]
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=COUNT, default=256)
    parser.add_argument("--step-episodes", type=COUNT, default=16)
    parser.add_argument("--repeats", type=COUNT, default=3)
    parser.add_argument("--out", type=JSON_OUT, default="benchmarks/results/sim_throughput.json")
    args = parser.parse_args()
    rows = [measure(task, args.episodes, args.step_episodes, args.repeats) for task in ("hockey", "basketball")]
    print(f"episodes per second (best of {args.repeats} runs, {args.episodes} episodes)")
    header = (
        "task",
        "raw mj_step bound",
        "open loop 1 thread",
        "open loop 2 threads",
        "step by step",
        "1 thread / bound",
        "step by step / bound",
    )
    print(
        markdown_table(
            header,
            [
                [
                    r["task"],
                    *(f"{r[key]:.1f}" for key in ("raw_mj_step", "open_loop_1_thread", "open_loop_2_thread", "step_by_step")),
                    *(f"{r[key]:.2f}" for key in ("open_loop_1_thread_vs_bound", "step_by_step_vs_bound")),
                ]
                for r in rows
            ],
        )
    )
    atomic_write_json(args.out, provenance() | {"rows": rows})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
