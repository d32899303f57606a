"""The study's tables (paper tables 1-5) and plots, and its ``report.md``."""

from __future__ import annotations

import csv
import io
import json
import pathlib
from typing import Any

from sb3_genrl.curves import mean_std_over_seeds, plot_curves, read_curve
from sb3_genrl.markdown import markdown_table
from sb3_genrl.metrics import MEASURES, correlation_table, labelled_scatter
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
            plot_curves(series, plots / f"learning_curves_{kind.lower()}.png", ylabel="mean reward per iteration",
                        title=f"{task}: GenRL with each {kind} (mean +- std over seeds)")
    names = [r["model"] for r in rows]
    labelled_scatter([r["precision"] for r in rows], [r["recall"] for r in rows], names, plots / "precision_recall.png",
                     xlabel="precision", ylabel="recall", title=f"{task}: precision and recall")
    labelled_scatter([r["delta_1"] for r in rows], [r["mean_delta"] for r in rows], names,
                     plots / "disentanglement.png", xlabel="delta_1", ylabel="mean delta (delta tilde)",
                     title=f"{task}: disentanglement (DwPR)")
    labelled_scatter([r["recall"] for r in rows], [r["score"] for r in rows], names, plots / "recall_vs_reward.png",
                     xlabel="recall", ylabel="best GenRL reward", title=f"{task}: recall against policy reward")


def write_task_report(task: str, rows: list[dict[str, Any]], task_dir: str | pathlib.Path, *,
                      scale: dict[str, Any], comparison: pathlib.Path | None = None) -> pathlib.Path:
    """Tables 1-5 for one task (Markdown and CSV), the plots, and ``report.md`` linking them."""
    root = pathlib.Path(task_dir)
    tables, plots = root / "tables", root / "plots"
    tables.mkdir(parents=True, exist_ok=True)
    plots.mkdir(parents=True, exist_ok=True)
    rows = sorted(rows, key=lambda r: (r["type"] != "VAE", int(r["model"][3:])))

    # Table 1: the models and the best reward GenRL reached with each (max over seeds of the best iteration mean).
    header1 = ["model", "N_alpha", "beta / lambda", "best reward", "reward per seed"]
    table1 = [[r["model"], r["latent_dim"], r["beta"] if r["type"] == "VAE" else r["info_weight"], r["score"],
               " / ".join(f"{x:.3f}" for x in r["rewards"])] for r in rows]
    _write_csv(tables / "table1_models.csv", header1, table1)

    # Tables 4-5: precision, recall and disentanglement of each model.
    header_m = ["model", *MEASURES]
    table_m = [[r["model"], *(r[m] for m in MEASURES)] for r in rows]
    _write_csv(tables / "measures.csv", header_m, table_m)

    # Tables 2-3: Pearson R and p-value of each measure against the best reward, per model type and for all.
    correlations = correlation_table(rows, measure_names=list(MEASURES), score_key="score")
    correlations.to_csv(tables / "correlation.csv")

    _write_plots(task, rows, root, plots)

    best = max(rows, key=lambda r: r["score"])
    lines = [f"# GenRL study: {task}", "",
             f"Settings (as recorded with each stage): `{json.dumps(scale)}`", "",
             f"Best generator: **{best['model']}** (best reward {best['score']:.3f}, i.e. {-best['score'] * 100:.1f} cm).",
             "", "## Table 1: generators and GenRL reward", "",
             "Best reward = the highest mean reward of a GenRL iteration, over all seeds (paper section 6.1.3).", "",
             markdown_table(header1, table1), "",
             "## Tables 4-5: precision, recall and disentanglement", "", markdown_table(header_m, table_m), "",
             "## Tables 2-3: correlation of each measure with the best reward", "", correlations.to_markdown(), "",
             "## Plots", "",
             "![VAE learning curves](plots/learning_curves_vae.png)", "",
             "![GAN learning curves](plots/learning_curves_gan.png)", "",
             "![precision and recall](plots/precision_recall.png) ![disentanglement](plots/disentanglement.png)", "",
             "![recall vs reward](plots/recall_vs_reward.png)", ""]
    if comparison is not None:
        lines += ["## GenRL vs PPO vs SAC", "", comparison.read_text().split("\n", 2)[2].replace(
            "](", f"]({comparison.parent.relative_to(root)}/"), ""]
    markdown = {"table1_models.md": markdown_table(header1, table1), "measures.md": markdown_table(header_m, table_m),
                "correlation.md": correlations.to_markdown()}
    for name, text in markdown.items():
        atomic_write_text(tables / name, text + "\n")
    report = root / "report.md"
    atomic_write_text(report, "\n".join(lines))
    return report
