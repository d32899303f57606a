"""The one Markdown-table writer of the package (evaluation results, the study's tables, comparisons, benchmarks)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Sequence
from typing import Any


def format_cell(value: Any, digits: int = 3) -> str:
    """A table cell: floats rounded to ``digits`` decimals (``nan`` for NaN), anything else as ``str``.

    :param value: the cell's value
    :param digits: decimals of a float
    """
    if isinstance(value, numbers.Real) and not isinstance(value, numbers.Integral):
        return "nan" if math.isnan(value) else f"{value:.{digits}f}"
    return str(value)


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[Any]], *, digits: int = 3, align: str = "") -> str:
    """A GitHub Markdown table, one line per row, without a final newline.

    :param header: the column names
    :param rows: the rows, each with one value per column (formatted by :func:`format_cell`)
    :param digits: decimals of float cells
    :param align: one letter per column, ``l`` (left, the default) or ``r`` (right); empty: all left
    :return: the table
    """
    align = align or "l" * len(header)
    if len(align) != len(header) or set(align) - {"l", "r"}:
        raise ValueError(f"align must give 'l' or 'r' for each of the {len(header)} columns, got {align!r}")
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---:" if a == "r" else "---" for a in align) + "|"]
    for row in rows:
        if len(row) != len(header):
            raise ValueError(f"a row has {len(row)} cells for {len(header)} columns: {list(row)!r}")
        lines.append("| " + " | ".join(format_cell(value, digits) for value in row) + " |")
    return "\n".join(lines)
