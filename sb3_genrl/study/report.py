"""The study's tables (paper tables 1-5, with bootstrap intervals), the ranking's stability, every generator's
selection curve, the scorecard's predictions, the plots, and its ``report.md``."""

from __future__ import annotations

import csv
import io
import json
import pathlib
from typing import Any

from sb3_genrl.curves import mean_std_over_seeds, plot_curves, read_curve
from sb3_genrl.markdown import markdown_table
from sb3_genrl.metrics import labelled_scatter
from sb3_genrl.metrics.scorecard import converged
from sb3_genrl.study.report_tables import (
    SCORECARD_MEASURES,  # noqa: F401 (the job's row holds these measures)
    all_tasks_correlations,
    correlations,
    cpu_line,
    excluded_line,
    measures_table,
    predictions,
    selection_table,
    stability,
    stability_line,
    table1,
)
from sb3_genrl.utils import atomic_write_text


def _write_csv(path: pathlib.Path, header: list[str], rows: list[list[Any]]) -> None:
    text = io.StringIO(newline="")
    writer = csv.writer(text)
    writer.writerow(header)
    writer.writerows(rows)
    atomic_write_text(path, text.getvalue(), newline="")


def _write_plots(task: str, rows: list[dict[str, Any]], root: pathlib.Path, plots: pathlib.Path) -> None:
    """Write one task's plots into ``plots`` (learning curves, precision/recall, disentanglement, recall vs reward)."""
    for kind in ("VAE", "GAN"):
        series = {}
        for r in rows:
            if r["type"] != kind:
                continue
            runs = sorted((root / "policies" / r["model"]).glob("seed*/learning_curve.csv"))
            if runs:
                series[r["model"]] = mean_std_over_seeds([read_curve(p) for p in runs])
        if series:
            plot_curves(
                series,
                plots / f"learning_curves_{kind.lower()}.png",
                ylabel="mean reward per iteration",
                title=f"{task}: GenRL with each {kind} (mean +- std over seeds)",
            )
    for kind in ("VAE", "GAN"):
        series = {
            r["model"]: ([e for e, _ in r["selection"]], [m for _, m in r["selection"]], None)
            for r in rows
            if r["type"] == kind and r["selection"]
        }
        if series:
            plot_curves(
                series,
                plots / f"selection_{kind.lower()}.png",
                xlabel="epoch",
                ylabel="model-selection MSE (held-out)",
                title=f"{task}: each {kind}'s training",
                log_y=True,
            )
    names = [r["model"] for r in rows]
    labelled_scatter(
        [r["precision"] for r in rows],
        [r["recall"] for r in rows],
        names,
        plots / "precision_recall.png",
        xlabel="precision",
        ylabel="recall",
        title=f"{task}: precision and recall",
    )
    labelled_scatter(
        [r["delta_1"] for r in rows],
        [r["mean_delta"] for r in rows],
        names,
        plots / "disentanglement.png",
        xlabel="delta_1",
        ylabel="mean delta (delta tilde)",
        title=f"{task}: disentanglement (DwPR)",
    )
    labelled_scatter(
        [r["recall"] for r in rows],
        [r["score"] for r in rows],
        names,
        plots / "recall_vs_reward.png",
        xlabel="recall",
        ylabel="best GenRL reward",
        title=f"{task}: recall against policy reward",
    )


def write_task_report(
    task: str,
    rows: list[dict[str, Any]],
    task_dir: str | pathlib.Path,
    *,
    scale: dict[str, Any],
    comparison: pathlib.Path | None = None,
) -> pathlib.Path:
    """Tables 1-5 for one task (Markdown and CSV), the stability, the selection curves, the plots, and ``report.md``
    linking them."""
    root = pathlib.Path(task_dir)
    tables, plots = root / "tables", root / "plots"
    tables.mkdir(parents=True, exist_ok=True)
    plots.mkdir(parents=True, exist_ok=True)
    rows = sorted(rows, key=lambda r: (r["type"] != "VAE", int(r["model"][3:])))
    parts = {"table1_models": table1(rows), "measures": measures_table(rows), "selection": selection_table(rows)}
    for name, (header, table) in parts.items():
        _write_csv(tables / f"{name}.csv", header, table)
    markdown = {name: markdown_table(header, table) for name, (header, table) in parts.items()}
    markdown["selection"] = markdown_table(*_significant(*parts["selection"], "selection MSE"))
    tables23, by_best, by_final = correlations(rows), predictions(rows, "score"), predictions(rows, "final")
    for name, table in (("correlation", tables23), ("prediction_best", by_best), ("prediction_final", by_final)):
        table.to_csv(tables / f"{name}.csv")
        markdown[name] = table.to_markdown().rstrip("\n")
    steady = stability(rows)
    atomic_write_text(tables / "stability.json", json.dumps(steady, indent=2) + "\n")
    _write_plots(task, rows, root, plots)
    for name, text in markdown.items():
        atomic_write_text(tables / f"{name}.md", text.rstrip("\n") + "\n")
    report = root / "report.md"
    atomic_write_text(report, "\n".join(_report_lines(task, rows, scale, markdown, steady, comparison, root)))
    return report


def write_all_tasks_report(rows_by_task: dict[str, list[dict[str, Any]]], out_dir: str | pathlib.Path) -> pathlib.Path:
    """Paper table 6 (:func:`~sb3_genrl.study.report_tables.all_tasks_correlations`) as ``all_tasks.csv`` and
    ``all_tasks.md`` in ``out_dir``; returns the Markdown file."""
    out = pathlib.Path(out_dir)
    table = all_tasks_correlations(rows_by_task)
    table.to_csv(out / "all_tasks.csv")
    counts = ", ".join(f"{task} {sum(converged(r) for r in rows)}" for task, rows in rows_by_task.items())
    path = out / "all_tasks.md"
    atomic_write_text(
        path,
        "\n".join(
            [
                "# GenRL study: all tasks (paper table 6)",
                "",
                f"Each measure against GenRL's best reward over the converged generators of every task together ({counts}), "
                "pooled as the paper pools them: each task's own rewards, so a difference between the tasks' rewards and "
                "measures is part of each coefficient. Each coefficient has its 95% percentile bootstrap interval over the "
                "models.",
                "",
                table.to_markdown().rstrip("\n"),
                "",
            ]
        ),
    )
    return path


def _significant(header: list[str], table: list[list[Any]], prefix: str) -> tuple[list[str], list[list[Any]]]:
    """The table with the float cells of the columns named ``prefix...`` given to 3 significant digits: errors
    far below 0.001 would otherwise all read 0.000."""
    columns = {i for i, name in enumerate(header) if name.startswith(prefix)}
    return header, [[f"{v:.3g}" if i in columns and isinstance(v, float) else v for i, v in enumerate(row)] for row in table]


def _report_lines(
    task: str,
    rows: list[dict[str, Any]],
    scale: dict[str, Any],
    markdown: dict[str, str],
    steady: dict[str, Any],
    comparison: pathlib.Path | None,
    root: pathlib.Path,
) -> list[str]:
    best = max(rows, key=lambda r: r["score"])
    intervals = (
        "Each coefficient has its 95% percentile bootstrap interval over the models (resampled with "
        "replacement, seed 0, the number of resamples in the CSV)."
    )
    lines = [
        f"# GenRL study: {task}",
        "",
        f"Settings (as recorded with each stage): `{json.dumps(scale)}`",
        "",
        f"Best generator: **{best['model']}** (best reward {best['score']:.3f}, i.e. {-best['score'] * 100:.1f} cm).",
        "",
        excluded_line(rows),
        "",
        cpu_line(rows),
        "",
        "## Table 1: generators and GenRL reward",
        "",
        "Best reward = the highest mean reward of a GenRL iteration, over all seeds (paper section 6.1.3); at "
        "half budget: the same within the first half of the episodes; final: the last iteration's, mean over "
        "seeds.",
        "",
        markdown["table1_models"],
        "",
        "## The ranking's stability",
        "",
        stability_line(steady),
        "",
        "## Tables 4-5: precision, recall and disentanglement",
        "",
        "With density and coverage (Naeem et al., 2020) and the prior rollout (the best reward of "
        f"{scale.get('prior_draws')} prior draws for each of {scale.get('prior_contexts')} held-out goals: "
        "median and quartiles over the goals).",
        "",
        markdown["measures"],
        "",
        "## Tables 2-3: correlation of each measure with the best reward",
        "",
        intervals,
        "",
        markdown["correlation"],
        "",
        "## Which measure predicts GenRL's reward",
        "",
        "Every measure against the best reward and against the final reward, over all converged generators.",
        "",
        "Against the best reward:",
        "",
        markdown["prediction_best"],
        "",
        "Against the final reward:",
        "",
        markdown["prediction_final"],
        "",
        "## Generator training",
        "",
        "The model-selection error (paper appendix B: 100 generated against held-out trajectories) at each "
        "evaluation of each generator's training; the epoch kept is the one of the smallest.",
        "",
        markdown["selection"],
        "",
        "![VAE training](plots/selection_vae.png) ![GAN training](plots/selection_gan.png)",
        "",
        "## Plots",
        "",
        "![VAE learning curves](plots/learning_curves_vae.png)",
        "",
        "![GAN learning curves](plots/learning_curves_gan.png)",
        "",
        "![precision and recall](plots/precision_recall.png) ![disentanglement](plots/disentanglement.png)",
        "",
        "![recall vs reward](plots/recall_vs_reward.png)",
        "",
    ]
    if comparison is not None:
        lines += [
            "## GenRL vs PPO vs SAC",
            "",
            comparison.read_text().split("\n", 2)[2].replace("](", f"]({comparison.parent.relative_to(root)}/"),
            "",
        ]
    return lines
