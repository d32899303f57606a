"""Compare GenRL, PPO, SAC and the latent-space baselines over seeds (paper figures 6 and 8).

Each run folder is one written by ``genrl train-policy`` or ``genrl baseline``: ``summary.json`` names the method,
``learning_curve.csv`` holds mean reward against episodes, ``episodes.csv`` the per-episode table contacts.
"""

from __future__ import annotations

import csv
import json
import os
import pathlib
from collections import defaultdict

import numpy as np

from sb3_genrl.callbacks import read_episodes
from sb3_genrl.curves import mean_std_over_seeds, plot_curves, read_curve

LABELS = {"genrl": "GenRL", "ppo": "PPO (BC)", "sac": "SAC (prefilled)", "latent-ppo": "PPO on latent",
          "latent-sac": "SAC on latent", "latent-trpo": "TRPO on latent"}


def compare_runs(run_dirs: list[str | os.PathLike], out_dir: str | os.PathLike, *, task: str | None = None) -> pathlib.Path:
    """Write ``comparison.md`` / ``comparison.csv``, ``reward_vs_episodes.png`` (mean +- std over seeds of each
    method) and ``table_contacts.png`` (average table contacts per episode of each method) to ``out_dir``.

    :param run_dirs: run folders (several seeds per method)
    :param out_dir: output folder (created)
    :param task: only runs of this task (default: all given, which must then share one task)
    :return: the Markdown table's path
    """
    runs: dict[str, list[dict]] = defaultdict(list)
    tasks = set()
    for run_dir in map(pathlib.Path, run_dirs):
        summary_path = run_dir / "summary.json"
        if not summary_path.exists():
            raise ValueError(f"{run_dir} is not a run folder (no summary.json)")
        summary = json.loads(summary_path.read_text())
        if task is not None and summary.get("task") != task:
            continue
        tasks.add(summary.get("task"))
        episodes = read_episodes(run_dir / "episodes.csv") if (run_dir / "episodes.csv").exists() else {}
        contacts = episodes.get("table_contacts", np.array([np.nan]))
        runs[summary["algorithm"]].append({"curve": read_curve(run_dir / "learning_curve.csv"), "summary": summary,
                                           "contacts": float(np.nanmean(contacts)) if np.any(np.isfinite(contacts))
                                           else np.nan})
    if not runs:
        raise ValueError(f"no runs of task {task!r} among {len(run_dirs)} folders")
    if len(tasks) > 1:
        raise ValueError(f"runs of several tasks {sorted(tasks)}; pass task=...")
    task_name = task or tasks.pop()
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    # The budget every run reached: methods are compared there (and each also at the end of its own runs).
    budget = int(min(run["curve"]["episodes"][-1] for group in runs.values() for run in group))
    series, rows = {}, []
    for algorithm, group in runs.items():
        label = LABELS.get(algorithm, algorithm)
        curves = [run["curve"] for run in group]
        series[label] = mean_std_over_seeds(curves)
        finals = np.array([curve["mean_reward"][-1] for curve in curves])
        at_budget = np.array([np.interp(budget, curve["episodes"], curve["mean_reward"]) for curve in curves])
        best = np.array([np.max(curve["mean_reward"]) for curve in curves])
        contacts = np.array([run["contacts"] for run in group])
        rows.append({"method": label, "seeds": len(group), "budget": int(budget), "reward_at_budget": at_budget.mean(),
                     "reward_at_budget_std": at_budget.std(), "episodes": int(min(c["episodes"][-1] for c in curves)),
                     "final_mean_reward": finals.mean(), "final_std": finals.std(), "best_mean_reward": best.max(),
                     "table_contacts_per_episode": np.nanmean(contacts) if np.any(np.isfinite(contacts)) else np.nan,
                     "table_contacts_std": np.nanstd(contacts) if np.any(np.isfinite(contacts)) else np.nan})
    plot_curves(series, out / "reward_vs_episodes.png", ylabel="mean reward (-distance, m)",
                title=f"{task_name}: mean +- std over seeds")
    _plot_contacts(rows, out / "table_contacts.png", title=f"{task_name}: table contacts per episode")
    with (out / "comparison.csv").open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    lines = [f"# {task_name}: GenRL vs baselines", "",
             f"Mean reward (minus the distance in m; mean +- std over seeds) at the budget every run reached ({budget} "
             "episodes) and at the end of each method's own runs.", "",
             f"| method | seeds | reward at {budget} episodes | episodes run | final mean reward | best mean reward "
             "| table contacts / episode |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        cells = [row["method"], row["seeds"], f"{row['reward_at_budget']:.3f} +- {row['reward_at_budget_std']:.3f}",
                 row["episodes"], f"{row['final_mean_reward']:.3f} +- {row['final_std']:.3f}",
                 f"{row['best_mean_reward']:.3f}",
                 "n/a" if np.isnan(row["table_contacts_per_episode"])
                 else f"{row['table_contacts_per_episode']:.2f} +- {row['table_contacts_std']:.2f}"]
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    lines += ["", "![reward vs episodes](reward_vs_episodes.png)", "", "![table contacts](table_contacts.png)", ""]
    path = out / "comparison.md"
    path.write_text("\n".join(lines))
    return path


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
    fig.savefig(path, dpi=110)
