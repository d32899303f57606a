"""The horizon ``genrl quickstart`` finds for each of Meta-World's 50 tasks, and what an episode of it costs.

Per task: :func:`~sb3_genrl.envs.demonstrations.expert_horizon` (seed 0, 100 seeded resets; in this process, so that
its CPU time is counted), then the expert played closed loop from 20 other seeded resets (``10**6 + i``) in the env
GenRL plays (ending at the first success, or at the horizon): its mean steps, and the CPU milliseconds of a step and of
an episode of the whole horizon (process time; what a failing GenRL episode costs). The JSON is written after every
task, and a rerun resumes with the tasks not done yet; the table is printed and written beside it (``.md``).

    python -m benchmarks.metaworld_horizons [--tasks push-v3 ...] [--out benchmarks/results/metaworld_horizons.json]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from sb3_genrl.envs import metaworld
from sb3_genrl.envs.demonstrations import expert_horizon
from sb3_genrl.envs.external import make_task_env

from benchmarks.metaworld import closed_loop, known_task
from sb3_genrl.checks import JSON_OUT, option
from sb3_genrl.markdown import markdown_table
from sb3_genrl.provenance import provenance
from sb3_genrl.run.stages import read_settings
from sb3_genrl.utils import atomic_write_json, atomic_write_text

RESULTS = Path(__file__).resolve().parent / "results"
COST_RESETS, COST_SEED = 20, 10**6  # the expert's episodes that measure the cost (not the probe's resets)


def task_row(name: str) -> dict[str, Any]:
    """The horizon of ``name``'s expert, its success there, and the CPU cost of its steps (see the module doc)."""
    began = time.process_time()
    found = expert_horizon(f"metaworld/{name}", seed=0, n_threads=1)
    probe = time.process_time() - began
    env, expert = make_task_env(f"metaworld/{name}", horizon=found["horizon"]), metaworld.metaworld_expert(name)
    began = time.process_time()
    steps = [len(closed_loop(env, expert, COST_SEED + i, found["horizon"])[1]) for i in range(COST_RESETS)]
    step_ms = 1000 * (time.process_time() - began) / sum(steps)
    env.close()
    return {key: value for key, value in found.items() if key != "success_by_step"} | {
        "probe_cpu_seconds": round(probe, 1),
        "expert_mean_steps": float(np.mean(steps)),
        "step_ms": round(step_ms, 3),
        "horizon_episode_ms": round(step_ms * found["horizon"], 1),
    }


def table(result: dict[str, Any]) -> str:
    rows = [
        [
            name,
            row["horizon"],
            "yes" if row["settled"] else "no",
            f"{row['success']:.2f}",
            f"{row['best']:.2f} (step {row['best_step']})",
            f"{row['expert_mean_steps']:.0f}",
            f"{row['step_ms']:.2f}",
            f"{row['horizon_episode_ms']:.0f}",
        ]
        for name, row in result["tasks"].items()
    ]
    header = ["task", "horizon", "settled", "expert's success", "its best", "expert's steps", "ms a step", "ms a horizon"]
    return markdown_table(header, rows, align="lrrrrrrr")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", type=option(known_task), default=list(metaworld.TASK_NAMES))
    parser.add_argument("--out", type=JSON_OUT, default=str(RESULTS / "metaworld_horizons.json"))
    args = parser.parse_args(argv)
    if not metaworld.installed():
        parser.error(metaworld.INSTALL_HINT)
    torch.set_num_threads(1)
    out = Path(args.out)
    result = (read_settings(out) if out.is_file() else None) or {"benchmark": "metaworld_horizons", "tasks": {}}
    for name in args.tasks:
        if name not in result["tasks"]:
            result["tasks"][name] = task_row(name)
            result |= provenance()
            atomic_write_json(out, result)
            print(name, result["tasks"][name], flush=True)
    atomic_write_text(out.with_suffix(".md"), table(result) + "\n")
    print(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
