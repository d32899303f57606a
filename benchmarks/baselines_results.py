"""The baselines benchmark's results (:mod:`benchmarks.baselines`): each method's distances, table contacts
and timings over its seeds, the merge of results made at different times, the JSON, Markdown table and plots, and
the cost of the whole benchmark."""

from __future__ import annotations

import json
import pathlib
from typing import Any

import numpy as np
from sb3_genrl.baselines.compare import LABELS
from sb3_genrl.baselines.evaluation import UNMOVED, training_health
from sb3_genrl.baselines.hyperparameters import baseline_settings

from sb3_genrl.curves import MONITOR_FILE, plot_curves, read_monitor, windowed_curve
from sb3_genrl.markdown import markdown_table
from sb3_genrl.utils import atomic_write_json, atomic_write_text

METHODS = ("genrl", "ppo", "sac", "sac-no-prefill", "sac-her", "latent-ppo", "latent-sac", "latent-trpo")
MILESTONES = (100, 300, 1000, 3000)  # episodes at which the table reports the mean distance
WINDOW = 64  # episodes averaged per point (GenRL's batch)


def method_result(runs: list[pathlib.Path], horizon: int, finals: list[dict[str, Any]], worst_reward: float) -> dict[str, Any]:
    """Distances, table contacts and timings of one method's runs (one per seed); ``finals``: their
    :func:`final_evaluation`; ``worst_reward``: the task's (the reward's floor)."""
    per_seed = [read_monitor(run / MONITOR_FILE) for run in runs]
    records = [json.loads((run / "run.json").read_text()) for run in runs]
    n = min(len(columns["return"]) for columns in per_seed)
    distances = np.stack([-columns["return"][:n] for columns in per_seed])
    contacts = np.stack([columns.get("table_contacts", np.full(n, np.nan))[:n] for columns in per_seed])
    grid, _ = windowed_curve(distances[0], WINDOW)
    curves = np.stack([windowed_curve(d, WINDOW)[1] for d in distances])
    has_contacts = bool(np.isfinite(contacts).any())  # a task without a table (basketball) reports none
    contact_curves = np.stack([windowed_curve(c, WINDOW)[1] for c in contacts]) if has_contacts else None
    milestones = {}
    for episodes in MILESTONES:
        if n >= episodes:
            values = distances[:, episodes - min(WINDOW, episodes) : episodes].mean(axis=1)
            milestones[str(episodes)] = {"mean": float(values.mean()), "std": float(values.std()), "per_seed": values.tolist()}
    # Steady-state cost: CPU seconds per episode over the second half of each run (the process' own CPU time, so
    # what else runs on the machine does not count).
    half = n // 2
    cpu_rates = [
        (n - half) / (columns["cpu_seconds"][n - 1] - (columns["cpu_seconds"][half - 1] if half else 0.0))
        for columns in per_seed
    ]
    final_distances = np.array([final["mean_distance"] for final in finals])
    final_contacts = [final["table_contacts"] for final in finals]
    final = {
        "goals": finals[0]["goals"],
        "goal_seed": finals[0]["goal_seed"],
        "mean": float(final_distances.mean()),
        "std": float(final_distances.std()),
        "per_seed": final_distances.tolist(),
        "median_per_seed": [f["median_distance"] for f in finals],
        "p90_per_seed": [f["p90_distance"] for f in finals],
        "table_contacts": None if None in final_contacts else float(np.mean(final_contacts)),
        "unstable_per_seed": [f["unstable"] for f in finals],
        "object_unmoved_per_seed": [f["object_unmoved"] for f in finals],
    }
    return {
        "seeds": len(runs),
        "episodes": int(n),
        "env_steps_per_episode": horizon,
        "milestones": milestones,
        "final_deterministic": final,
        "training_health": [training_health(run) for run in runs],
        "curve": {
            "episodes": grid.tolist(),
            "mean_distance": curves.mean(0).tolist(),
            "std_distance": curves.std(0).tolist(),
            "table_contacts": np.nanmean(contact_curves, 0).tolist() if has_contacts else None,
        },
        "table_contacts_per_episode": float(np.nanmean(contacts)) if has_contacts else None,
        # training episodes at the task's worst reward, the reward's floor: that far from the goal or further,
        # a ball that never came down through the rim's height (basketball), or an unstable simulation
        "worst_reward_share": float(np.isclose(-distances, worst_reward).mean()),
        "setup_seconds": float(np.mean([r["setup_seconds"] for r in records])),
        "setup_cpu_seconds": float(np.mean([r["setup_cpu_seconds"] for r in records])),
        "episodes_per_second": float(np.mean([r["episodes_played"] / r["learn_seconds"] for r in records])),
        "episodes_per_cpu_second": float(np.mean(cpu_rates)),
        "bc": [r["bc"] for r in records if r.get("bc")],
        "first_batch": [r["first_batch"] for r in records if r.get("first_batch")],
    }


# what must agree between a result and the methods merged into it (see ``merge_results``)
MERGE_KEYS = (
    "benchmark",
    "task",
    "horizon",
    "episodes",
    "seeds",
    "window",
    "sb3_genrl",
    "worst_reward",
    "demos",
    "demo_dataset",
    "generator_sha256",
)


def merge_results(previous: dict[str, Any], current: dict[str, Any]) -> dict[str, Any]:
    """``current`` with the methods of ``previous`` that it did not run, in the benchmark's order of methods.

    Raises ``ValueError`` naming what differs when the two are not results of the same benchmark settings; a key that
    ``previous`` does not hold (a result written before it was recorded) is not compared, except ``demos``, the
    dataset's path, which every result holds; one that only ``previous`` holds (the generator's digest, when
    ``current`` ran no method that uses it) is kept. ``merged_methods`` lists the methods taken from ``previous``."""
    differ = [
        key
        for key in MERGE_KEYS
        if (key in previous or key == "demos") and key in current and previous.get(key) != current[key]
    ]
    if differ:
        shown = "; ".join(f"{key}: {previous.get(key)!r} there, {current[key]!r} now" for key in differ)
        raise ValueError(f"the result to merge into was made with other settings ({shown})")
    kept = [method for method in previous["methods"] if method not in current["methods"]]
    methods = previous["methods"] | current["methods"]
    order = [m for m in METHODS if m in methods] + [m for m in methods if m not in METHODS]
    carried = {key: previous[key] for key in MERGE_KEYS if key in previous and key not in current}
    return carried | current | {"methods": {method: methods[method] for method in order}, "merged_methods": kept}


def write_outputs(result: dict[str, Any], out: pathlib.Path) -> None:
    """The JSON, the Markdown table and the three plots."""
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out, result)
    stem, task = out.with_suffix(""), result["task"]
    series = {}
    for method, row in result["methods"].items():
        curve = row["curve"]
        series[LABELS.get(method, method)] = (
            np.array(curve["episodes"]),
            -np.array(curve["mean_distance"]),
            np.array(curve["std_distance"]),
        )
    plot_curves(series, f"{stem}_episodes.png", ylabel="mean reward (-distance, m)", title=f"{task}: mean +- std over seeds")
    steps = {label: (x * result["horizon"], y, s) for label, (x, y, s) in series.items()}
    plot_curves(
        steps,
        f"{stem}_env_steps.png",
        ylabel="mean reward (-distance, m)",
        xlabel="environment steps",
        title=f"{task}: mean +- std over seeds",
    )
    contacts = {
        LABELS.get(m, m): (np.array(r["curve"]["episodes"]), np.array(r["curve"]["table_contacts"]), None)
        for m, r in result["methods"].items()
        if r["curve"]["table_contacts"] is not None
    }
    if contacts:
        plot_curves(
            contacts,
            f"{stem}_contacts.png",
            ylabel="table contacts per episode (control steps)",
            title=f"{task}: table contacts",
        )
    goals = next(iter(result["methods"].values()))["final_deterministic"]["goals"]
    header = [
        "method",
        "seeds",
        *(f"{m} episodes" for m in MILESTONES),
        "final policy, deterministic",
        f"final policy: goals of {goals} with the object not moved, per seed",
        "table contacts / episode",
        "episodes at the worst reward",
        "setup (CPU s)",
        "episodes / CPU s",
    ]
    rows = []
    for method, row in result["methods"].items():
        cells = [
            f"{row['milestones'][str(m)]['mean']:.3f} +- {row['milestones'][str(m)]['std']:.3f}"
            if str(m) in row["milestones"]
            else "n/a"
            for m in MILESTONES
        ]
        contacts_cell = "n/a" if row["table_contacts_per_episode"] is None else f"{row['table_contacts_per_episode']:.2f}"
        final = row["final_deterministic"]
        rows.append(
            [
                LABELS.get(method, method),
                row["seeds"],
                *cells,
                f"{final['mean']:.3f} +- {final['std']:.3f}",
                " / ".join(str(n) for n in final["object_unmoved_per_seed"]),
                contacts_cell,
                f"{100 * row['worst_reward_share']:.1f}%",
                f"{row['setup_cpu_seconds']:.0f}",
                f"{row['episodes_per_cpu_second']:.2f}",
            ]
        )
    lines = [
        f"# {task}: mean distance to the goal (m), mean +- std over seeds",
        "",
        f"Mean over the {WINDOW} episodes before each budget (training episodes, as played), and the final "
        f"policy's deterministic mean distance to {goals} held-out goals (the same goals for every method). "
        f"Episodes at the worst reward ({result['worst_reward']:g} m), the reward's floor, are training episodes "
        "that ended that far from the goal or further (hockey: a puck sent off the table), whose ball never came "
        "down through the rim's height (basketball), or whose simulation went unstable. An object not moved ends within "
        f"{UNMOVED * 100:g} cm of where it rests at the start: the final policy never hit the puck (or threw the "
        "ball), and scores what the arm holding still does.",
        "",
        markdown_table(header, rows),
    ]
    warned = [
        f"- {LABELS.get(method, method)}, seed {seed}: {warning}"
        for method, row in result["methods"].items()
        for seed, health in zip(result["seeds"], row["training_health"], strict=True)
        for warning in health["warnings"]
    ]
    if warned:
        lines += ["", "Training that did not stay stable (SB3's logs, `training_health`):", "", *warned]
    lines += ["", f"![episodes]({stem.name}_episodes.png)", "", f"![environment steps]({stem.name}_env_steps.png)", ""]
    if contacts:
        lines += [f"![table contacts]({stem.name}_contacts.png)", ""]
    atomic_write_text(out.with_suffix(".md"), "\n".join(lines))


def core_hours(result: dict[str, Any], episodes: int, seeds: int) -> float:
    """Single-core hours of the whole benchmark at ``episodes`` x ``seeds``, from the measured CPU costs (setup and
    steady-state episodes). SAC without prefill plays random actions until ``learning_starts``; a run too short to
    pass it is charged SAC (prefilled)'s rate, its cost once learning, beyond that point."""
    methods, seconds = result["methods"], 0.0
    warm_up = baseline_settings("sac-no-prefill", result["task"])[0]["learning_starts"] / result["horizon"]
    for method, row in methods.items():
        rate = row["episodes_per_cpu_second"]
        if method == "sac-no-prefill" and row["episodes"] <= warm_up and "sac" in methods:
            learning = max(episodes - warm_up, 0)
            cost = (episodes - learning) / rate + learning / methods["sac"]["episodes_per_cpu_second"]
        else:
            cost = episodes / rate
        seconds += seeds * (row["setup_cpu_seconds"] + cost)
    return seconds / 3600
