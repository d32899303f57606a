"""The generator scorecard: every measure of each generator in one table, ranked, with untrained models set apart.

The rows are ranked by the prior rollout's median best reward when it was measured (the measure grounded in the
task: higher is better; ties, as a sparse 0/-1 reward gives them, broken by its mean), else by precision. A model
whose precision is below :data:`NOT_CONVERGED_PRECISION` generates almost nothing that looks like a demonstration:
it is marked "not converged" and ranked after the others (the study also keeps such models out of its
correlations), since its other measures then describe an untrained model rather than its family.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from sb3_genrl.markdown import markdown_table

NOT_CONVERGED_PRECISION = 0.15
_COLUMNS = ("precision", "recall", "density", "coverage", "delta_1", "mean_delta")
_PRIOR = ("prior_median", "prior_q25", "prior_q75")


def converged(row: Mapping[str, Any]) -> bool:
    """Whether a model's precision reaches :data:`NOT_CONVERGED_PRECISION` (a non-finite one does not)."""
    precision = float(row["precision"])
    return math.isfinite(precision) and precision >= NOT_CONVERGED_PRECISION


def rank_key(rows: Sequence[Mapping[str, Any]]) -> str:
    """The column the scorecard ranks by: ``prior_median`` when every row has it, else ``precision``."""
    return "prior_median" if rows and all("prior_median" in row for row in rows) else "precision"


def ranked(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """The rows, converged models first, each part by :func:`rank_key` from best to worst (ties in given order)."""
    key = rank_key(rows)

    def descending(value: Any) -> float:
        value = float(value)
        return -value if math.isfinite(value) else math.inf

    def order(row: Mapping[str, Any]) -> tuple[bool, float, float]:
        tie = descending(row["prior_mean"]) if key == "prior_median" and "prior_mean" in row else 0.0
        return not converged(row), descending(row[key]), tie

    return sorted(rows, key=order)


def scorecard_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """The ranked scorecard as a Markdown table (no final newline), with a line saying how it is ranked."""
    key = rank_key(rows)
    prior = key == "prior_median"
    success = prior and all("prior_success" in row for row in rows)  # an env that reports info["is_success"]
    header = ["rank", "model", *_COLUMNS, *(("prior median", "prior quartiles") if prior else ()),
              *(("prior success",) if success else ()), *(("prior cost",) if prior else ()), "status"]
    table = []
    for index, row in enumerate(ranked(rows), start=1):
        cells: list[Any] = [index, row["model"], *(row[column] for column in _COLUMNS)]
        if prior:
            cells += [row["prior_median"], f"{row['prior_q25']:.3f} .. {row['prior_q75']:.3f}",
                      *([row["prior_success"]] if success else []),
                      f"{row['prior_episodes']} episodes, {row['prior_seconds']:.1f} s"]
        table.append([*cells, "ok" if converged(row) else "not converged"])
    by = "the prior rollout: the median over goals of the best reward of the prior draws" if prior else "precision"
    rule = (f"Ranked by {by} (higher is better); a model with precision below {NOT_CONVERGED_PRECISION} is not "
            "converged and ranked last.")
    return rule + "\n\n" + markdown_table(header, table, align="rl" + "r" * (len(header) - 3) + "l")
