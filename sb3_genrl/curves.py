"""Per-episode records and learning curves of a training run (GenRL or a baseline), and the mean +- std over seeds
that ``genrl compare`` draws.

Every run records its episodes with SB3's :class:`~stable_baselines3.common.monitor.Monitor` (``episodes.monitor.csv``:
return, length, time, the :data:`EPISODE_INFO` entries and the CPU seconds so far, written as training goes) and its
training logs with SB3's logger (:func:`training_logger`: ``logs/progress.csv`` and TensorBoard). The learning curve
(:func:`write_learning_curve`) is the mean over consecutive windows of episodes of the Monitor file.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import pathlib
import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.logger import Logger, configure
from stable_baselines3.common.monitor import Monitor

from sb3_genrl.utils import atomic_path, atomic_write_text

EPISODE_INFO = ("table_contacts", "distance")  # what the comparison needs of each finished episode's info
MONITOR_FILE = "episodes.monitor.csv"
LOG_DIR = "logs"
# What a run writes in LOG_DIR (patterns under the run folder): SB3's CSV log and TensorBoard events, and the logs a
# resume sets aside (sb3_genrl.run.folder.keep_episodes). --overwrite removes these and nothing else there.
LOG_FILES = (f"{LOG_DIR}/progress.csv", f"{LOG_DIR}/progress.until_episode_*.csv", f"{LOG_DIR}/events.out.tfevents.*")
_MONITOR_COLUMNS = {"r": "return", "l": "length", "t": "time"}


class _EpisodeInfo(gym.Wrapper):
    """Give a finished episode's ``info`` every key Monitor records (NaN where the task does not report it) and
    ``cpu_seconds``: this process' CPU seconds since the env's first reset (what the run has cost, whatever else
    shares the machine).

    SB3's Monitor raises ``KeyError`` for a missing ``info_keywords`` entry, and a task need not report them all
    (basketball has no table, an unstable simulation reports no distance).
    """

    def __init__(self, env: gym.Env, keys: Sequence[str]) -> None:
        super().__init__(env)
        self.keys = tuple(keys)
        self._cpu_start: float | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        if self._cpu_start is None:
            self._cpu_start = time.process_time()
        return self.env.reset(**kwargs)

    def cpu_seconds(self) -> float:
        """The CPU seconds recorded so far (0 before the first reset)."""
        return 0.0 if self._cpu_start is None else time.process_time() - self._cpu_start

    def continue_from(self, seconds: float) -> None:
        """Count on from ``seconds`` (a resumed run: the CPU seconds recorded before it stopped)."""
        self._cpu_start = time.process_time() - seconds

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            for key in self.keys:
                info.setdefault(key, math.nan)
            info["cpu_seconds"] = time.process_time() - self._cpu_start
        return observation, reward, terminated, truncated, info


def episode_info(env: gym.Env, info_keywords: Sequence[str] = EPISODE_INFO) -> gym.Env:
    """``env`` with every ``info_keywords`` entry and ``cpu_seconds`` in a finished episode's ``info`` (see
    :class:`_EpisodeInfo`): what SB3's ``VecMonitor`` over several such envs records."""
    return _EpisodeInfo(env, info_keywords)


def monitor_episodes(
    env: gym.Env, out_dir: str | os.PathLike, info_keywords: Sequence[str] = EPISODE_INFO, *, append: bool = False
) -> Monitor:
    """Wrap ``env`` in SB3's Monitor writing ``out_dir/episodes.monitor.csv`` (one row per episode, as it ends).

    Each row also holds ``cpu_seconds`` (see :class:`_EpisodeInfo`); the timesteps at an episode's end are the
    cumulative sum of the ``length`` column.

    :param env: the training env (a one-step latent-action env or a step-by-step task env)
    :param out_dir: the run folder
    :param info_keywords: entries of a finished episode's ``info`` to record (NaN where missing)
    :param append: add rows to an existing file (a resumed run) instead of starting a new one
    :return: the monitored env
    """
    return Monitor(
        episode_info(env, info_keywords),
        str(pathlib.Path(out_dir) / MONITOR_FILE),
        info_keywords=(*info_keywords, "cpu_seconds"),
        override_existing=not append,
    )


def training_logger(out_dir: str | os.PathLike, verbose: int = 0) -> Logger:
    """SB3's logger writing ``out_dir/logs/progress.csv`` and TensorBoard events there (and to stdout if ``verbose``).

    :param out_dir: the run folder
    :param verbose: also print the logs
    """
    return configure(str(pathlib.Path(out_dir) / LOG_DIR), ["stdout"] * bool(verbose) + ["csv", "tensorboard"])


def read_monitor(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The columns of a Monitor file: ``return``, ``length``, ``time`` and the recorded info entries (NaN if empty).

    Our own reader rather than SB3's ``load_results``: that one needs pandas, which SB3 does not install.

    :param path: an ``*.monitor.csv`` file
    """
    with pathlib.Path(path).open(newline="") as file:
        header = file.readline()
        if not header.startswith("#") or not isinstance(json.loads(header[1:]), dict):
            raise ValueError(f"{path} is not an SB3 Monitor file (its first line is not a '#{{...}}' JSON header)")
        rows = list(csv.DictReader(file))
    if not rows:
        return {}
    return {
        _MONITOR_COLUMNS.get(key, key): np.array([float(row[key]) if row[key] not in ("", None) else np.nan for row in rows])
        for key in rows[0]
    }


def windowed_curve(values: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean of consecutive windows of ``window`` episodes: returns (episodes at each window's end, means)."""
    values = np.asarray(values, dtype=np.float64)
    n = len(values) // window
    if n == 0:
        return np.array([len(values)]), np.array([np.nanmean(values)]) if len(values) else np.array([np.nan])
    means = np.nanmean(values[: n * window].reshape(n, window), axis=1)
    return np.arange(1, n + 1) * window, means


def write_learning_curve(
    monitor_csv: str | os.PathLike, out_dir: str | os.PathLike, *, window: int = 64, title: str = ""
) -> dict[str, np.ndarray]:
    """Average a Monitor file over windows of ``window`` episodes; write ``learning_curve.csv`` (episodes,
    mean_reward, max_reward, mean_table_contacts) and ``learning_curve.png``.

    :param monitor_csv: the run's ``episodes.monitor.csv``
    :param out_dir: the run folder
    :param window: episodes per point (GenRL: one EM iteration's ``batch_episodes``)
    :param title: the plot's title
    :return: the curve's columns
    """
    columns = read_monitor(monitor_csv)
    if not columns:
        raise ValueError(f"{monitor_csv} holds no finished episode")
    out = pathlib.Path(out_dir)
    returns = columns["return"]
    episodes, mean_reward = windowed_curve(returns, window)
    contacts = columns.get("table_contacts", np.full(len(returns), np.nan))
    windows = [slice(max(0, end - window), end) for end in episodes]
    curve = {
        "episodes": episodes,
        "mean_reward": mean_reward,
        "max_reward": np.array([np.max(returns[w]) for w in windows]),
        "mean_table_contacts": np.array(
            [np.nanmean(contacts[w]) if np.isfinite(contacts[w]).any() else np.nan for w in windows]
        ),
    }
    table = io.StringIO()
    writer = csv.writer(table)
    writer.writerow(curve)
    writer.writerows(zip(*curve.values(), strict=True))
    atomic_write_text(out / "learning_curve.csv", table.getvalue(), newline="")
    plot_curves({title or "run": (episodes, mean_reward, None)}, out / "learning_curve.png", ylabel="mean reward", title=title)
    return curve


def read_curve(csv_path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a ``learning_curve.csv`` (any columns; ``episodes`` and ``mean_reward`` at least)."""
    with pathlib.Path(csv_path).open(newline="") as file:
        rows = list(csv.DictReader(file))
    if not rows or "episodes" not in rows[0] or "mean_reward" not in rows[0]:
        raise ValueError(f"{csv_path} is not a learning curve (needs 'episodes' and 'mean_reward' columns)")
    return {key: np.array([float(row[key]) if row[key] not in ("", None) else np.nan for row in rows]) for key in rows[0]}


def mean_std_over_seeds(
    curves: Sequence[dict[str, np.ndarray]], key: str = "mean_reward", grid: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and std over runs of ``key``, each run linearly interpolated onto a common grid of episodes."""
    if not curves:
        raise ValueError("no curves given")
    if grid is None:
        end = min(curve["episodes"][-1] for curve in curves)
        start = max(curve["episodes"][0] for curve in curves)
        grid = np.linspace(start, end, 50) if end > start else np.array([end])
    values = np.stack([np.interp(grid, curve["episodes"], curve[key]) for curve in curves])
    return grid, values.mean(axis=0), values.std(axis=0)


def plot_curves(
    series: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray | None]],
    path: str | os.PathLike,
    *,
    ylabel: str,
    title: str = "",
    xlabel: str = "episodes",
    log_y: bool = False,
) -> pathlib.Path:
    """One line per series (x, mean, std or None), a shaded band of +- std where given; ``log_y``: a log y-axis."""
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
    if log_y:
        ax.set_yscale("log")
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
