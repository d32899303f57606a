"""Correlation of generator measures with policy performance (paper section 6.4, tables 3-5).

Pearson's R and its two-sided p-value between each evaluation measure (precision, recall, delta_1, mean delta, ...)
and the policy score of each generative model (the best reward of its GenRL policies), per model type and for all
models together; beside it Spearman's rho, and for both a 95% percentile bootstrap interval over the models
(:mod:`sb3_genrl.metrics.bootstrap`).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import os
from collections.abc import Mapping, Sequence

import numpy as np

from sb3_genrl.markdown import markdown_table
from sb3_genrl.metrics.bootstrap import BOOTSTRAP_SEED, DEFAULT_RESAMPLES, bootstrap_correlations, spearman
from sb3_genrl.utils import atomic_write_text

# The five measures of a generator (paper section 5.2): the one list every table, report and correlation uses.
MEASURES = ("precision", "recall", "delta_1", "delta_2", "mean_delta")
ALL_MODELS = "ALL"
_COLUMNS = (
    "group",
    "measure",
    "num_models",
    "pearson_r",
    "p_value",
    "pearson_low",
    "pearson_high",
    "spearman_rho",
    "spearman_p",
    "spearman_low",
    "spearman_high",
    "resamples",
    "note",
)


@dataclasses.dataclass(frozen=True)
class CorrelationRow:
    """Pearson's R between one measure and the score within one group of models.

    :param group: model type (e.g. ``"VAE"``) or ``"ALL"``
    :param measure: name of the measure
    :param num_models: number of models with finite values used
    :param pearson_r: Pearson's correlation coefficient, ``nan`` when undefined (see ``note``)
    :param p_value: two-sided p-value of the null hypothesis of no correlation, ``nan`` when undefined
    :param note: why the value is undefined or which models were left out, empty otherwise
    :param pearson_low: lower end of the 95% bootstrap interval of Pearson's R
    :param pearson_high: its upper end
    :param spearman_rho: Spearman's rank correlation
    :param spearman_p: its two-sided p-value
    :param spearman_low: lower end of the 95% bootstrap interval of Spearman's rho
    :param spearman_high: its upper end
    :param resamples: bootstrap resamples drawn (0: no interval)
    """

    group: str
    measure: str
    num_models: int
    pearson_r: float
    p_value: float
    note: str = ""
    pearson_low: float = math.nan
    pearson_high: float = math.nan
    spearman_rho: float = math.nan
    spearman_p: float = math.nan
    spearman_low: float = math.nan
    spearman_high: float = math.nan
    resamples: int = 0


@dataclasses.dataclass(frozen=True)
class CorrelationTable:
    """Rows of :func:`correlation_table`, one per (group, measure), groups in order then measures in order."""

    rows: tuple[CorrelationRow, ...]

    def get(self, group: str, measure: str) -> CorrelationRow:
        """The row of ``group`` and ``measure``, or a ``KeyError``."""
        for row in self.rows:
            if row.group == group and row.measure == measure:
                return row
        raise KeyError(f"no row for group {group!r} and measure {measure!r}")

    def to_markdown(self, digits: int = 3) -> str:
        """A Markdown table, one line per (group, measure), values rounded to ``digits`` decimals, each coefficient
        with its 95% bootstrap interval."""
        rows = [
            (
                row.group,
                row.measure,
                row.num_models,
                row.pearson_r,
                _interval(row.pearson_low, row.pearson_high),
                row.p_value,
                row.spearman_rho,
                _interval(row.spearman_low, row.spearman_high),
                row.spearman_p,
                row.note,
            )
            for row in self.rows
        ]
        header = (
            "group",
            "measure",
            "models",
            "Pearson's R",
            "95% interval",
            "p-value",
            "Spearman's rho",
            "95% interval",
            "p-value",
            "note",
        )
        return markdown_table(header, rows, digits=digits, align="llrrlrrlrl") + "\n"

    def to_csv(self, path: str | os.PathLike) -> None:
        """Write the rows to ``path`` as CSV with full float precision (``nan`` for undefined values)."""
        table = io.StringIO()
        writer = csv.writer(table)
        writer.writerow(_COLUMNS)
        for row in self.rows:
            writer.writerow(
                [
                    row.group,
                    row.measure,
                    row.num_models,
                    *(repr(getattr(row, name)) for name in _COLUMNS[3:11]),
                    row.resamples,
                    row.note,
                ]
            )
        atomic_write_text(path, table.getvalue(), newline="")


def _interval(low: float, high: float) -> str:
    return "" if math.isnan(low) else f"[{low:.2f}, {high:.2f}]"


def pearson(x: np.ndarray, y: np.ndarray) -> tuple[float, float, str]:
    """Pearson's R and two-sided p-value of paired finite samples, ``(nan, nan, note)`` when undefined."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if len(x) < 3:
        return math.nan, math.nan, f"fewer than 3 models ({len(x)})"
    if np.ptp(x) == 0 or np.ptp(y) == 0:
        return math.nan, math.nan, "constant values"
    from scipy.stats import pearsonr  # scipy.stats costs about 0.5 s; every `genrl` command reaches this module

    result = pearsonr(x, y)
    return float(result.statistic), float(result.pvalue), ""


def _records(
    measures: Sequence[Mapping] | Mapping[str, Mapping[str, float]],
    scores: Mapping[str, float] | None,
    model_types: Mapping[str, str] | None,
    score_key: str,
    type_key: str,
    model_key: str,
) -> list[dict]:
    if isinstance(measures, Mapping):
        if scores is None:
            raise ValueError("scores (model name -> policy score) are required when measures is a mapping")
        records = []
        for model, values in measures.items():
            if model not in scores:
                raise ValueError(f"no score for model {model!r}")
            record = {model_key: model, **values, score_key: scores[model]}
            if model_types is not None:
                record[type_key] = model_types[model]
            records.append(record)
        return records
    records = [dict(record) for record in measures]
    for index, record in enumerate(records):
        if score_key not in record:
            raise ValueError(f"record {index} ({record.get(model_key, '?')}) has no {score_key!r} value")
        if model_types is not None and model_key in record and record[model_key] in model_types:
            record[type_key] = model_types[record[model_key]]
    return records


def correlation_table(
    measures: Sequence[Mapping] | Mapping[str, Mapping[str, float]],
    scores: Mapping[str, float] | None = None,
    model_types: Mapping[str, str] | None = None,
    *,
    measure_names: Sequence[str] | None = None,
    score_key: str = "score",
    type_key: str = "type",
    model_key: str = "model",
    include_all: bool = True,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> CorrelationTable:
    """Pearson's R and p-value of each measure against the policy score, per model type and for all models, with
    Spearman's rho and 95% bootstrap intervals of both.

    Input, either form:

    - a list of records, e.g. ``{"model": "VAE1", "type": "VAE", "precision": 0.9, "recall": 0.4, "score": 12.0}``;
    - a mapping ``model -> {measure: value}`` with ``scores`` (``model -> score``) and optionally ``model_types``
      (``model -> type``).

    Groups are the model types in order of first appearance, then ``"ALL"`` (all models, also the only group when
    no types are given). Models with a non-finite measure or score are left out of that measure's row (named in
    its note). Fewer than 3 models or a constant column give ``nan`` with a note instead of an error.

    :param measures: records or a mapping, as above
    :param scores: model name -> policy score, for the mapping form
    :param model_types: model name -> model type (e.g. ``"VAE"``, ``"GAN"``)
    :param measure_names: measures to correlate; default: those of ``precision, recall, delta_1, delta_2,
        mean_delta`` present in every record
    :param score_key: key of the score in the records
    :param type_key: key of the model type in the records
    :param model_key: key of the model name in the records
    :param include_all: add the ``"ALL"`` group when there are model types
    :param resamples: bootstrap resamples of each interval (0: no intervals)
    :param seed: seed of the resamples (the same for every row, see :mod:`sb3_genrl.metrics.bootstrap`)
    :return: a :class:`CorrelationTable`
    """
    records = _records(measures, scores, model_types, score_key, type_key, model_key)
    if not records:
        raise ValueError("no models given")
    if measure_names is None:
        measure_names = [name for name in MEASURES if all(name in record for record in records)]
        if not measure_names:
            raise ValueError(f"the records hold none of the measures {MEASURES}; pass measure_names")
    for name in measure_names:
        missing = [record.get(model_key, index) for index, record in enumerate(records) if name not in record]
        if missing:
            raise ValueError(f"measure {name!r} is missing for models {missing}")
    types = list(dict.fromkeys(str(record[type_key]) for record in records if type_key in record))
    groups = [(group, [r for r in records if str(r.get(type_key)) == group]) for group in types]
    if include_all or not groups:
        groups.append((ALL_MODELS, records))
    rows = []
    for group, members in groups:
        for name in measure_names:
            x = np.array([float(record[name]) for record in members])
            y = np.array([float(record[score_key]) for record in members])
            finite = np.isfinite(x) & np.isfinite(y)
            r, p, note = pearson(x[finite], y[finite])
            if not finite.all():
                left_out = [str(member.get(model_key, "?")) for member, ok in zip(members, finite, strict=True) if not ok]
                note = "; ".join(filter(None, [note, f"left out (non-finite): {', '.join(left_out)}"]))
            rows.append(_row(group, name, x[finite], y[finite], r, p, note, resamples, seed))
    return CorrelationTable(tuple(rows))


def _row(
    group: str, measure: str, x: np.ndarray, y: np.ndarray, r: float, p: float, note: str, resamples: int, seed: int
) -> CorrelationRow:
    rho, rho_p = spearman(x, y)
    intervals = {}
    if resamples > 0:
        pearson_ci, spearman_ci = bootstrap_correlations(x, y, resamples=resamples, seed=seed)
        intervals = {
            "pearson_low": pearson_ci.low,
            "pearson_high": pearson_ci.high,
            "spearman_low": spearman_ci.low,
            "spearman_high": spearman_ci.high,
        }
    return CorrelationRow(
        group, measure, len(x), r, p, note, spearman_rho=rho, spearman_p=rho_p, resamples=resamples, **intervals
    )
