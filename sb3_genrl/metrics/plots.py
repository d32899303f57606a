"""Labelled scatter plots of generator measures (paper figures: precision vs recall, delta_1 vs mean delta)."""

from __future__ import annotations

import os
from collections.abc import Sequence

from sb3_genrl.utils import atomic_path


def labelled_scatter(
    x: Sequence[float],
    y: Sequence[float],
    labels: Sequence[str],
    path: str | os.PathLike,
    *,
    xlabel: str,
    ylabel: str,
    title: str = "",
) -> None:
    """Save a scatter plot of ``(x, y)`` with each point annotated by its label as a PNG (written atomically).

    Drawn with the Agg canvas directly, so the caller's pyplot backend and state are left alone.

    :param x: horizontal values, one per model
    :param y: vertical values, one per model
    :param labels: model names
    :param path: output path (PNG unless its suffix names another format)
    :param xlabel: horizontal axis label
    :param ylabel: vertical axis label
    :param title: figure title
    """
    if not len(x) == len(y) == len(labels):
        raise ValueError(f"x, y and labels must have the same length, got {len(x)}, {len(y)} and {len(labels)}")
    # matplotlib costs about 0.3 s, and every `genrl` command reaches this module
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(5.0, 4.5))
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    axes.scatter(x, y, s=30)
    for x_value, y_value, label in zip(x, y, labels, strict=True):
        axes.annotate(label, (x_value, y_value), textcoords="offset points", xytext=(4, 4), fontsize=8)
    axes.set_xlabel(xlabel)
    axes.set_ylabel(ylabel)
    if title:
        axes.set_title(title)
    axes.grid(True, alpha=0.3)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=120, format=os.path.splitext(path)[1][1:] or "png")
