"""Learning curves from per-episode records: CSV and PNG, and the mean +- std over seeds used by ``genrl compare``."""

from __future__ import annotations

import csv
import io
import os
import pathlib
from collections.abc import Sequence

import numpy as np

from sb3_genrl.callbacks import read_episodes, windowed_curve
from sb3_genrl.utils import atomic_path, atomic_write_text


def write_learning_curve(episodes_csv: str | os.PathLike, out_dir: str | os.PathLike, *, window: int = 64,
                         title: str = "") -> dict[str, np.ndarray]:
    """Average an :class:`~sb3_genrl.callbacks.EpisodeRecorder` CSV over windows of ``window`` episodes; write
    ``learning_curve.csv`` (episodes, mean_reward, max_reward, mean_table_contacts) and ``learning_curve.png``."""
    columns = read_episodes(episodes_csv)
    if not columns:
        raise ValueError(f"{episodes_csv} holds no finished episode")
    out = pathlib.Path(out_dir)
    episodes, mean_reward = windowed_curve(columns["return"], window)
    n = len(episodes)
    returns = columns["return"]
    max_reward = np.array([np.max(returns[max(0, e - window):e]) for e in episodes])
    contacts = columns.get("table_contacts", np.full(len(returns), np.nan))
    mean_contacts = np.array([np.nanmean(contacts[max(0, e - window):e]) if np.any(np.isfinite(contacts[max(0, e - window):e]))
                              else np.nan for e in episodes])
    curve = {"episodes": episodes, "mean_reward": mean_reward, "max_reward": max_reward,
             "mean_table_contacts": mean_contacts}
    table = io.StringIO()
    writer = csv.writer(table)
    writer.writerow(curve)
    for i in range(n):
        writer.writerow([curve[key][i] for key in curve])
    atomic_write_text(out / "learning_curve.csv", table.getvalue(), newline="")
    plot_curves({title or "run": (episodes, mean_reward, None)}, out / "learning_curve.png", ylabel="mean reward",
                title=title)
    return curve


def read_curve(csv_path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a ``learning_curve.csv`` (any columns; ``episodes`` and ``mean_reward`` at least)."""
    with pathlib.Path(csv_path).open(newline="") as file:
        rows = list(csv.DictReader(file))
    if not rows or "episodes" not in rows[0] or "mean_reward" not in rows[0]:
        raise ValueError(f"{csv_path} is not a learning curve (needs 'episodes' and 'mean_reward' columns)")
    return {key: np.array([float(row[key]) if row[key] not in ("", None) else np.nan for row in rows]) for key in rows[0]}


def mean_std_over_seeds(curves: Sequence[dict[str, np.ndarray]], key: str = "mean_reward",
                        grid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and std over runs of ``key``, each run linearly interpolated onto a common grid of episodes."""
    if not curves:
        raise ValueError("no curves given")
    if grid is None:
        end = min(curve["episodes"][-1] for curve in curves)
        start = max(curve["episodes"][0] for curve in curves)
        grid = np.linspace(start, end, 50) if end > start else np.array([end])
    values = np.stack([np.interp(grid, curve["episodes"], curve[key]) for curve in curves])
    return grid, values.mean(axis=0), values.std(axis=0)


def plot_curves(series: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray | None]], path: str | os.PathLike, *,
                ylabel: str, title: str = "", xlabel: str = "episodes") -> pathlib.Path:
    """One line per series (x, mean, std or None), a shaded band of +- std where given."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.0))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for label, (x, mean, std) in series.items():
        (line,) = ax.plot(x, mean, label=label)
        if std is not None:
            ax.fill_between(x, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if len(series) > 1:
        ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = pathlib.Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix[1:] or "png")
    return path
