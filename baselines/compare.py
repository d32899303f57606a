"""Compare GenRL, PPO, SAC and the latent-space baselines over seeds (paper figures 6 and 8).

Each run folder is one written by ``genrl train-policy`` or ``genrl baseline``: ``summary.json`` names the method,
``learning_curve.csv`` holds mean reward against episodes, ``episodes.monitor.csv`` (SB3's Monitor) the per-episode
table contacts.
"""

from __future__ import annotations

import csv
import io
import json
import os
import pathlib
from collections import defaultdict

import numpy as np
from sb3_genrl.baselines import BASELINES

from sb3_genrl.checks import check_output_dir
from sb3_genrl.curves import MONITOR_FILE, mean_std_over_seeds, plot_curves, read_curve, read_monitor
from sb3_genrl.markdown import markdown_table
from sb3_genrl.utils import atomic_path, atomic_write_text

# How the comparison names each method (``genrl`` and :data:`~sb3_genrl.baselines.BASELINES`).
LABELS = {
    "genrl": "GenRL",
    "ppo": "PPO (BC)",
    "sac": "SAC (prefilled)",
    "sac-no-prefill": "SAC (no prefill)",
    "sac-her": "SAC + HER",
    "latent-ppo": "PPO on latent",
    "latent-sac": "SAC on latent",
    "latent-trpo": "TRPO on latent",
}


def compare_runs(run_dirs: list[str | os.PathLike], out_dir: str | os.PathLike, *, task: str | None = None) -> pathlib.Path:
    """Write ``comparison.md`` / ``comparison.csv``, ``reward_vs_episodes.png`` (mean +- std over seeds of each
    method) and ``table_contacts.png`` (average table contacts per episode of each method) to ``out_dir``.

    :param run_dirs: run folders (several seeds per method), all of one task
    :param out_dir: output folder (created)
    :param task: the task the runs must be of (default: the one they share); a run of another task is refused, naming it
    :return: the Markdown table's path
    """
    out = check_output_dir(out_dir)
    runs, task_name = _read_runs(run_dirs, task)
    out.mkdir(parents=True, exist_ok=True)
    # The budget every run reached: methods are compared there (and each also at the end of its own runs).
    budget = int(min(run["curve"]["episodes"][-1] for group in runs.values() for run in group))
    series, rows = {}, []
    for algorithm, group in runs.items():
        curves = [run["curve"] for run in group]
        series[LABELS.get(algorithm, algorithm)] = mean_std_over_seeds(curves)
        rows.append(_method_row(LABELS.get(algorithm, algorithm), curves, [run["contacts"] for run in group], budget))
    plot_curves(
        series,
        out / "reward_vs_episodes.png",
        ylabel="mean reward (-distance, m)",
        title=f"{task_name}: mean +- std over seeds",
    )
    _plot_contacts(rows, out / "table_contacts.png", title=f"{task_name}: table contacts per episode")
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(out / "comparison.csv", text.getvalue(), newline="")
    header = [
        "method",
        "seeds",
        f"reward at {budget} episodes",
        "episodes run",
        "final mean reward",
        "best mean reward",
        "table contacts / episode",
    ]
    table = [
        [
            row["method"],
            row["seeds"],
            f"{row['reward_at_budget']:.3f} +- {row['reward_at_budget_std']:.3f}",
            row["episodes"],
            f"{row['final_mean_reward']:.3f} +- {row['final_std']:.3f}",
            row["best_mean_reward"],
            "n/a"
            if np.isnan(row["table_contacts_per_episode"])
            else f"{row['table_contacts_per_episode']:.2f} +- {row['table_contacts_std']:.2f}",
        ]
        for row in rows
    ]
    lines = [
        f"# {task_name}: GenRL vs baselines",
        "",
        f"Mean reward (minus the distance in m; mean +- std over seeds) at the budget every run reached ({budget} "
        "episodes) and at the end of each method's own runs.",
        "",
        markdown_table(header, table),
        "",
        "![reward vs episodes](reward_vs_episodes.png)",
        "",
        "![table contacts](table_contacts.png)",
        "",
    ]
    path = out / "comparison.md"
    atomic_write_text(path, "\n".join(lines))
    return path


def _read_runs(run_dirs: list[str | os.PathLike], task: str | None) -> tuple[dict[str, list[dict]], str]:
    """The runs grouped by method (each with its curve and mean table contacts per episode) and their task; runs of
    several tasks, or of another task than ``task``, are refused, naming each run's task."""
    summaries = []
    for run_dir in map(pathlib.Path, run_dirs):
        summary_path = run_dir / "summary.json"
        if not summary_path.exists():
            raise ValueError(f"{run_dir} is not a run folder (no summary.json)")
        summaries.append((run_dir, json.loads(summary_path.read_text())))
    if not summaries:
        raise ValueError("no run folders given")
    folders: dict[pathlib.Path, pathlib.Path] = {}
    seeds: dict[tuple[str, int], pathlib.Path] = {}
    for run_dir, summary in summaries:  # a method's runs are averaged as its seeds: each counted once
        first = folders.setdefault(run_dir.resolve(), run_dir)
        if first is not run_dir:
            raise ValueError(f"{run_dir} is given twice ({first}, {run_dir}); give each run once")
        if summary.get("seed") is not None:
            key = (str(summary.get("algorithm")), summary["seed"])
            first = seeds.setdefault(key, run_dir)
            if first is not run_dir:
                raise ValueError(
                    f"{first} and {run_dir} are both {key[0]} with seed {key[1]}: a method's runs are averaged as its "
                    "seeds; leave one out"
                )
    by_task: dict[str, list[str]] = defaultdict(list)
    for run_dir, summary in summaries:
        by_task[str(summary.get("task"))].append(str(run_dir))
    if task is not None and set(by_task) != {task}:
        others = ", ".join(f"{run} ({name})" for name, dirs in by_task.items() if name != task for run in dirs)
        raise ValueError(f"runs of another task than {task!r}: {others}; leave them out (compare each task's runs apart)")
    if len(by_task) > 1:
        tasks = "; ".join(f"{name}: {', '.join(dirs)}" for name, dirs in by_task.items())
        raise ValueError(f"the runs are of several tasks ({tasks}); compare one task's runs at a time")
    runs: dict[str, list[dict]] = defaultdict(list)
    for run_dir, summary in summaries:
        episodes = read_monitor(run_dir / MONITOR_FILE) if (run_dir / MONITOR_FILE).exists() else {}
        contacts = episodes.get("table_contacts", np.array([np.nan]))
        runs[summary["algorithm"]].append(
            {"curve": read_curve(run_dir / "learning_curve.csv"), "summary": summary, "contacts": _nanmean(contacts)}
        )
    # A fixed order (GenRL, then the baselines' order; each method's runs by seed), whatever order the runs came in:
    # the study gives them as its workers finish
    order = ("genrl", *BASELINES)
    ranked = sorted(runs, key=lambda name: (order.index(name) if name in order else len(order), name))
    return {
        name: sorted(runs[name], key=lambda run: (run["summary"].get("seed") is None, run["summary"].get("seed") or 0))
        for name in ranked
    }, next(iter(by_task))


def _method_row(label: str, curves: list[dict[str, np.ndarray]], contacts: list[float], budget: int) -> dict:
    """One method's line of the comparison: rewards at the common budget, at the end and at best, table contacts."""
    finals = np.array([curve["mean_reward"][-1] for curve in curves])
    at_budget = np.array([np.interp(budget, curve["episodes"], curve["mean_reward"]) for curve in curves])
    contacts = np.array(contacts)
    return {
        "method": label,
        "seeds": len(curves),
        "budget": int(budget),
        "reward_at_budget": at_budget.mean(),
        "reward_at_budget_std": at_budget.std(),
        "episodes": int(min(c["episodes"][-1] for c in curves)),
        "final_mean_reward": finals.mean(),
        "final_std": finals.std(),
        "best_mean_reward": max(np.max(curve["mean_reward"]) for curve in curves),
        "table_contacts_per_episode": _nanmean(contacts),
        "table_contacts_std": np.nanstd(contacts) if np.isfinite(contacts).any() else np.nan,
    }


def _nanmean(values: np.ndarray) -> float:
    return float(np.nanmean(values)) if np.isfinite(values).any() else np.nan


def _plot_contacts(rows: list[dict], path: pathlib.Path, *, title: str) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 3.6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    labels = [row["method"] for row in rows]
    means = [0.0 if np.isnan(row["table_contacts_per_episode"]) else row["table_contacts_per_episode"] for row in rows]
    stds = [0.0 if np.isnan(row["table_contacts_std"]) else row["table_contacts_std"] for row in rows]
    ax.bar(labels, means, yerr=stds, capsize=4, color="C3", alpha=0.7)
    ax.set_ylabel("table contacts per episode (control steps)")
    ax.set_title(title)
    ax.tick_params(axis="x", labelrotation=20)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix[1:] or "png")
