"""The Fetch benchmark's table and curves from its JSON files (``benchmarks/fetch.py``), complete or not.

Reads ``fetch_TASK.json`` for each Fetch task present in ``--results`` and writes there ``fetch.md`` (one row per
task: the demonstrations, the generator's two measures, GenRL's held-out success, the target, and how far the run got)
and ``fetch_curves.png`` (each seed's held-out success against episodes and environment steps). A run that has not
finished every stage is labelled partial, with the episodes its seeds reached; its numbers are never the final ones.
rl-zoo3's published TQC+HER results are the anchor rows (its ``benchmark.md``: mean return of one seed, -1 per step
away from the goal, 50 steps per episode). With ``--tqc``, TQC+HER's progress read from ``benchmarks/tqc_fetch.sh``'s
logs is kept in ``fetch_tqc_progress.json`` beside the JSON files, each run as far as it got in any logs read.

    python -m benchmarks.fetch_results                      # benchmarks/results/fetch_*.json
    python -m benchmarks.fetch_results --results runs/fetch --out runs/fetch
"""

from __future__ import annotations

import argparse
import csv
import glob
import json
import os

import numpy as np
from sb3_genrl.envs import get_task

from benchmarks.fetch_seed import recorded_genrl_settings
from sb3_genrl.generative.presets import resolve_generator_spec
from sb3_genrl.markdown import markdown_table
from sb3_genrl.provenance import provenance
from sb3_genrl.study.quickstart import quickstart_preset
from sb3_genrl.utils import atomic_path, atomic_write_json, atomic_write_text

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
TASKS = ("fetch-reach", "fetch-push", "fetch-pick-and-place", "fetch-slide")
TARGETS = {
    "fetch-reach": (0.99, 500),
    "fetch-push": (0.95, 3000),
    "fetch-pick-and-place": (0.90, 6000),
    "fetch-slide": (0.80, 6000),
}  # the 3-seed mean success and episode budget
BENCHMARK_SEEDS = (0, 1, 2)  # a benchmark's JSON is complete once these seeds have finished
# rl-zoo3's benchmark.md, TQC+HER, one seed: mean return and the environment steps of its run
ZOO_TQC = {
    "fetch-reach": (-1.66, 20_000),
    "fetch-push": (-8.80, 1_000_000),
    "fetch-pick-and-place": (-9.33, 1_000_000),
    "fetch-slide": (-29.2, 3_000_000),
}
# TQC+HER's progress as last read from benchmarks/tqc_fetch.sh's logs (--tqc), kept beside the JSON files
TQC_PROGRESS = "fetch_tqc_progress.json"
TQC_COLUMNS = ["run", "episodes", "env steps", "success, rl-zoo3's last evaluation"]


def seed_row(result: dict, seed: int) -> dict:
    """The row of ``seed`` in a benchmark's ``result["runs"]``, added (empty, unfinished) when it has none."""
    row = next((run for run in result["runs"] if run["seed"] == seed), None)
    if row is None:
        row = {"seed": seed, "finished": False, "curve_episodes": [], "curve_env_steps": [], "curve_success": []}
        result["runs"].append(row)
    return row


def all_seeds_finished(result: dict) -> bool:
    """Whether every seed of :data:`BENCHMARK_SEEDS` has a finished row (a run of fewer seeds is partial)."""
    return {run["seed"] for run in result["runs"] if run.get("finished")} >= set(BENCHMARK_SEEDS)


def write_result(path: str, result: dict) -> None:
    """Write a benchmark's JSON (atomically), with the mean and spread of its finished seeds' final success."""
    finals = [run["final_success"] for run in result["runs"] if run.get("finished")]
    if finals:
        result.update(
            final_success_mean=float(np.mean(finals)), final_success_std=float(np.std(finals)), finished_seeds=len(finals)
        )
    atomic_write_json(path, result)


def read(results: str) -> dict[str, dict]:
    """The JSON of each task present in ``results``."""
    found = {}
    for task in TASKS:
        path = os.path.join(results, f"fetch_{task}.json")
        if os.path.exists(path):
            with open(path) as file:
                found[task] = json.load(file)
    return found


# VAE-FETCH's recipe when the JSON files did not record it yet (they record the preset's name only)
UNRECORDED_RECIPE = {"model": "vae", "latent_dim": 10, "beta": 0.001}
# the demonstrations' recipe when the JSON files did not record it yet (aims over the goal region widened by 2 cm)
UNRECORDED_DEMONSTRATION_RECIPE = {"aim_margin": 0.02}


def dataset_recipe(task: str, info: dict) -> dict:
    """The entries of ``task``'s demonstration recipe that a dataset's ``info`` records (a dataset of an earlier
    version records none: it was made with :data:`UNRECORDED_DEMONSTRATION_RECIPE`)."""
    return {key: info.get(key, UNRECORDED_DEMONSTRATION_RECIPE.get(key)) for key in get_task(task).demonstration_recipe}


def recorded_demonstration_recipe(settings: dict) -> dict | None:
    """The recipe of the demonstrations a benchmark JSON's ``settings`` made (None: a given dataset, ``--data``)."""
    if not isinstance(settings.get("demonstrations"), int):
        return None
    return settings.get("demonstration_recipe", UNRECORDED_DEMONSTRATION_RECIPE)


def former_settings(task: str, result: dict) -> list[str]:
    """The settings in which ``result``'s runs differ from those the benchmark would use now: GenRL's (the task's entry
    in ``hyperparams/genrl.yml``; the episodes per iteration compared as ``batch_episodes``: older JSON files record
    GenRL's default ``n_steps``), the recipe of the generator it trains (``generator recipe``) and of the
    demonstrations it makes (``demonstration recipe``)."""
    settings = result.get("settings", {})
    if "genrl_settings" not in settings:
        return []
    now = recorded_genrl_settings(task)
    batch_episodes = now["n_steps"]
    differ = sorted(
        key
        for key in now.keys() | settings["genrl_settings"].keys()
        if key != "n_steps" and now.get(key) != settings["genrl_settings"].get(key)
    )
    differ += ["batch_episodes"] if settings.get("batch_episodes", batch_episodes) != batch_episodes else []
    preset = quickstart_preset(task)
    if settings.get("generator") == "trained" and settings.get("preset") == preset:
        recorded = settings.get("generator_recipe", UNRECORDED_RECIPE if preset == "VAE-FETCH" else None)
        differ += ["generator recipe"] if recorded is not None and recorded != resolve_generator_spec(preset) else []
    demonstrations = recorded_demonstration_recipe(settings)
    differ += ["demonstration recipe"] if demonstrations not in (None, get_task(task).demonstration_recipe) else []
    return differ


def status(result: dict, task: str | None = None) -> str:
    """``complete``, or ``partial`` with the episodes each seed reached; with ``task``, also whether the runs used
    former settings (:func:`former_settings`)."""
    differ = former_settings(task, result) if task is not None else []
    if differ:
        return f"{status(result)}; former settings ({', '.join(differ)} differ)"
    if result.get("complete"):
        return "complete"
    reached = [
        f"seed {run['seed']}: {run['curve_episodes'][-1] if run['curve_episodes'] else 0}"
        + ("" if run.get("finished") else " (running)")
        for run in result.get("runs", [])
    ]
    return "partial: " + (", ".join(reached) if reached else "no GenRL episodes yet")


def mean_of_seeds(values: list[float], spread: bool) -> str:
    """A table cell: the mean (and standard deviation) over seeds, with how many; ``-`` for none."""
    if not values:
        return "-"
    seeds = f"{len(values)} seed" + ("s" if len(values) > 1 else "")
    return f"{np.mean(values):.3f}" + (f" ± {np.std(values):.3f}" if spread else "") + f" ({seeds})"


def row(task: str, result: dict) -> list:
    generator = result.get("generator", {})
    demos = generator.get("demonstration_info", {}).get("episodes", generator.get("demonstrations"))
    if demos is None:  # a run given --generator: the count its warm start read
        demos = next((run["demo_init"]["demonstrations"] for run in result.get("runs", []) if "demo_init" in run), "")
    recon = result.get("reconstruction", {}).get("success_rate", "not yet measured")
    limit = result.get("generator_limit", {})
    finished = [run["final_success"] for run in result.get("runs", []) if run.get("finished")]
    success = mean_of_seeds(finished, spread=True)
    start = [run["curve_success"][0] for run in result.get("runs", []) if run["curve_episodes"][:1] == [0]]
    start_cell = mean_of_seeds(start, spread=False)
    target, budget = TARGETS[task]
    pending = "not yet measured"
    near = result.get("policy_neighbourhood")
    near_cell = (
        f"{near['deterministic_success']:.3f} / {near['best_of_draws']:.3f} ({near['draws_per_state']})" if near else pending
    )
    return [
        task,
        demos,
        recon,
        limit.get("best_of", {}).get("1", pending),
        limit.get("success_rate", pending),
        near_cell,
        start_cell,
        success,
        result["settings"]["episodes"],
        f">= {target} in {budget}",
        status(result, task),
    ]


def table(found: dict[str, dict], progress: list[list] | None = None, results: str | None = None) -> str:
    header = [
        "task",
        "demonstrations",
        "reconstructions reach their aims",
        "one prior draw solves",
        "best of 100 prior draws",
        "first seed's final policy: its mean / best of its draws",
        "GenRL at episode 0 (mean fitted to the demonstrations)",
        "GenRL held-out success (final, mean ± std)",
        "GenRL episodes",
        "target",
        "run",
    ]
    lines = [markdown_table(header, [row(task, result) for task, result in found.items()])]
    zoo = [[task, f"{ret:.2f}", steps, steps // 50] for task, (ret, steps) in ZOO_TQC.items()]
    lines += [
        "",
        "rl-zoo3's published TQC+HER (benchmark.md, one seed; mean return, -1 per step away from the goal):",
        "",
        markdown_table(["task", "mean return", "env steps", "episodes"], zoo),
    ]
    sac = sac_her_rows(results) if results else []
    if sac:
        lines += [
            "",
            "SAC+HER here (SB3's SAC and HerReplayBuffer, `benchmarks/fetch_sac_her.py`; the same held-out states):",
            "",
            markdown_table(
                ["task", "demonstrations in the buffer", "held-out success (final, mean ± std)", "episodes", "run"], sac
            ),
        ]
    if progress:
        lines += [
            "",
            "TQC+HER here (rl-zoo3's entry point and stock settings, `benchmarks/tqc_fetch.sh`; running, partial):",
            "",
            markdown_table(TQC_COLUMNS, progress),
        ]
    return "\n".join(lines) + "\n"


def sac_her_rows(results: str) -> list[list]:
    """One row per ``fetch_sac_her_TASK_VARIANT.json`` in ``results`` (``benchmarks/fetch_sac_her.py``)."""
    rows = []
    for task in TASKS:
        for variant in ("demos", "none"):
            path = os.path.join(results, f"fetch_sac_her_{task}_{variant}.json")
            if not os.path.exists(path):
                continue
            with open(path) as file:
                result = json.load(file)
            finished = [run["final_success"] for run in result["runs"] if run.get("finished")]
            success = mean_of_seeds(finished, spread=True)
            demos = result.get("demonstrations", "") if variant == "demos" else 0
            episodes = result["settings"]["n_timesteps"] // 50
            rows.append([task, demos, success, episodes, status(result)])
    return rows


def tqc_progress(logs: str) -> list[list]:
    """TQC+HER's runs by ``benchmarks/tqc_fetch.sh`` in ``logs``: per env id, the episodes done and the success of
    rl-zoo3's own evaluation at the last segment's end (its ``evaluations.npz``; rl-zoo3's evaluation episodes, not the
    held-out states)."""
    rows = []
    for listing in sorted(glob.glob(os.path.join(logs, "*_segments.csv"))):
        with open(listing) as file:
            segments = list(csv.DictReader(file))
        if not segments:
            continue
        last = segments[-1]
        evaluations = os.path.join(last["folder"], "evaluations.npz")
        success = float(np.load(evaluations)["successes"][-1].mean()) if os.path.exists(evaluations) else float("nan")
        rows.append(
            [
                os.path.basename(listing).removesuffix("_segments.csv"),
                int(last["env_steps_total"]) // 50,
                int(last["env_steps_total"]),
                success,
            ]
        )
    return rows


def kept_tqc_progress(logs: str | None, results: str) -> list[list]:
    """TQC+HER's progress: read from ``logs`` (:func:`tqc_progress`) and kept in ``results``' ``fetch_tqc_progress.json``.
    Per run the furthest wins: a run the logs do not hold, or hold less far (a machine whose logs were lost, started
    again), keeps its kept row; none anywhere: ``[]``."""
    kept_path = os.path.join(results, TQC_PROGRESS)
    kept: list[list] = []
    if os.path.exists(kept_path):
        with open(kept_path) as file:
            kept = json.load(file)["rows"]
    furthest = {row[0]: row for row in kept}
    for row in tqc_progress(logs) if logs else []:
        if row[0] not in furthest or row[2] >= furthest[row[0]][2]:
            furthest[row[0]] = row
    progress = [furthest[name] for name in sorted(furthest)]
    if progress != kept:
        atomic_write_json(kept_path, provenance() | {"columns": TQC_COLUMNS, "rows": progress})
    return progress


def plot(found: dict[str, dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(found), figsize=(4 * len(found), 6), squeeze=False)
    for column, (task, result) in enumerate(found.items()):
        for line, key in enumerate(("curve_episodes", "curve_env_steps")):
            ax = axes[line][column]
            for run in result.get("runs", []):
                ax.plot(run[key], run["curve_success"], marker="o", label=f"seed {run['seed']}")
            ax.axhline(TARGETS[task][0], color="grey", linestyle="--", linewidth=1)
            ax.set(
                ylim=(0, 1.02),
                xlabel="episodes" if line == 0 else "environment steps",
                ylabel="held-out success",
                title=f"{task} ({'complete' if result.get('complete') else 'partial'})",
            )
            ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as temporary:
        fig.savefig(temporary, format="png", dpi=80)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default=RESULTS, help="folder of the fetch_TASK.json files")
    parser.add_argument("--out", default=None, help="folder of fetch.md and fetch_curves.png (default: --results)")
    parser.add_argument("--tqc", default=None, help="benchmarks/tqc_fetch.sh's log folder (e.g. runs/tqc): its progress")
    args = parser.parse_args(argv)
    found = read(args.results)
    if not found:
        raise SystemExit(f"no fetch_TASK.json in {args.results}")
    out = args.out or args.results
    text = table(found, kept_tqc_progress(args.tqc, args.results), args.results)
    atomic_write_text(os.path.join(out, "fetch.md"), text)
    plot(found, os.path.join(out, "fetch_curves.png"))
    print(text)


if __name__ == "__main__":
    main()
