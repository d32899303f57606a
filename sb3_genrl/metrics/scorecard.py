"""The generator scorecard: every measure of each generator in one table, ranked, with untrained models set apart.

By default the rows are ranked by recall, the one measure whose correlation with GenRL's result was positive on every
task measured (the study's generators on hockey and basketball, five generators on each Fetch task;
docs/guide/evaluation.md); ``by`` ranks by any other (on hockey the disentanglement predicts best, on FetchReach the
prior rollout). Ranked by the prior rollout's median best reward, its ties (as a sparse 0/-1 reward gives them) are
broken by its mean. A model whose precision is below :data:`NOT_CONVERGED_PRECISION` generates almost nothing that
looks like a demonstration: it is marked "not converged" and ranked after the others (the study also keeps such models
out of its correlations), since its other measures then describe an untrained model rather than its family. The
threshold is ``min_precision``: a VAE with a small KL weight can score low precision from its prior samples and still
serve GenRL well, which starts from posterior means (the Fetch recipe), so such a family is ranked with
``min_precision=0``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from sb3_genrl.checks import check_fraction
from sb3_genrl.markdown import markdown_table

NOT_CONVERGED_PRECISION = 0.15
_COLUMNS = ("precision", "recall", "density", "coverage", "delta_1", "mean_delta")
_PRIOR = ("prior_median", "prior_q25", "prior_q75")


def converged(row: Mapping[str, Any], min_precision: float = NOT_CONVERGED_PRECISION) -> bool:
    """Whether a model's precision reaches ``min_precision`` (a non-finite one does not)."""
    precision = float(row["precision"])
    return math.isfinite(precision) and precision >= min_precision


# prior_success needs no entry: on a 0/-1 reward the median's ties are broken by the mean, i.e. by the share solved
RANK_MEASURES = (*_COLUMNS, "prior_median")
DEFAULT_RANK = "recall"


def rank_key(rows: Sequence[Mapping[str, Any]], by: str | None = None) -> str:
    """The column the scorecard ranks by: ``by`` when given (one of :data:`RANK_MEASURES`, which every row must
    have), else :data:`DEFAULT_RANK`."""
    if by is None:
        return DEFAULT_RANK
    if by not in RANK_MEASURES:
        raise ValueError(f"cannot rank by {by!r}: choose one of {', '.join(RANK_MEASURES)}")
    missing = [str(row.get("model", "?")) for row in rows if by not in row]
    if missing:
        raise ValueError(f"cannot rank by {by!r}: {', '.join(missing)} lack it (the prior rollout runs only with a task)")
    return by


def ranked(
    rows: Sequence[Mapping[str, Any]], by: str | None = None, min_precision: float = NOT_CONVERGED_PRECISION
) -> list[Mapping[str, Any]]:
    """The rows, converged models (:func:`converged` at ``min_precision``) first, each part by :func:`rank_key` from
    best to worst (ties in given order; the prior rollout's ties broken by its mean)."""
    key = rank_key(rows, by)
    min_precision = check_fraction(min_precision, "min_precision")

    def descending(value: Any) -> float:
        value = float(value)
        return -value if math.isfinite(value) else math.inf

    def order(row: Mapping[str, Any]) -> tuple[bool, float, float]:
        tie = descending(row["prior_mean"]) if key == "prior_median" and "prior_mean" in row else 0.0
        return not converged(row, min_precision), descending(row[key]), tie

    return sorted(rows, key=order)


def scorecard_markdown(
    rows: Sequence[Mapping[str, Any]], by: str | None = None, min_precision: float = NOT_CONVERGED_PRECISION
) -> str:
    """The ranked scorecard as a Markdown table (no final newline), with a line saying how it is ranked.

    :param rows: one mapping per generator (``GeneratorEvaluation.row()``)
    :param by: the measure to rank by (:func:`rank_key`)
    :param min_precision: the precision below which a model is marked not converged and ranked last (0: none is)
    """
    key = rank_key(rows, by)
    min_precision = check_fraction(min_precision, "min_precision")
    prior = bool(rows) and all("prior_median" in row for row in rows)
    success = prior and all("prior_success" in row for row in rows)  # an env that reports info["is_success"]
    header = [
        "rank",
        "model",
        *_COLUMNS,
        *(("prior median", "prior quartiles") if prior else ()),
        *(("prior success",) if success else ()),
        *(("prior cost",) if prior else ()),
        "status",
    ]
    table = []
    for index, row in enumerate(ranked(rows, key, min_precision), start=1):
        cells: list[Any] = [index, row["model"], *(row[column] for column in _COLUMNS)]
        if prior:
            cells += [
                row["prior_median"],
                f"{row['prior_q25']:.3f} .. {row['prior_q75']:.3f}",
                *([row["prior_success"]] if success else []),
                f"{row['prior_episodes']} episodes, {row['prior_seconds']:.1f} s",
            ]
        table.append([*cells, "ok" if converged(row, min_precision) else "not converged"])
    by = "the prior rollout: the median over goals of the best reward of the prior draws" if key == "prior_median" else key
    rule = f"Ranked by {by} (higher is better)"
    rule += (
        f"; a model with precision below {min_precision:g} is not converged and ranked last."
        if min_precision > 0
        else "; no precision threshold."
    )
    return rule + "\n\n" + markdown_table(header, table, align="rl" + "r" * (len(header) - 3) + "l")
