"""Callbacks shared by GenRL and the baselines: a per-episode record written as training goes."""

from __future__ import annotations

import csv
import os
import pathlib
import time
from collections.abc import Sequence

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback


class EpisodeRecorder(BaseCallback):
    """Append one CSV row per finished episode: its index, the timesteps so far, the process' CPU seconds since
    training started (what the run has cost, whatever else shares the machine), its return and chosen ``info``
    entries.

    Works for any SB3 algorithm and any number of environments: a one-step GenRL bandit pull is an episode, and
    so is a 69-step PPO episode. The return is the sum of the episode's rewards (the terminal reward for the
    paper's tasks, whose other rewards are 0).

    :param csv_path: the CSV file (created, or overwritten, when training starts; flushed after every episode)
    :param info_keys: numeric ``info`` entries of an episode's last step to record (missing ones are left empty)
    :param verbose: verbosity of the callback
    """

    def __init__(self, csv_path: str | os.PathLike, info_keys: Sequence[str] = ("table_contacts", "distance"),
                 verbose: int = 0) -> None:
        super().__init__(verbose)
        self.csv_path = pathlib.Path(csv_path)
        self.info_keys = tuple(info_keys)
        self.returns: list[float] = []
        self.records: list[dict[str, float]] = []

    def _on_training_start(self) -> None:
        self.csv_path.parent.mkdir(parents=True, exist_ok=True)
        self._running = np.zeros(self.training_env.num_envs)
        self._file = self.csv_path.open("w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(("episode", "timesteps", "cpu_seconds", "return", *self.info_keys))
        self._cpu_start = time.process_time()

    def _on_step(self) -> bool:
        self._running += np.asarray(self.locals["rewards"], dtype=np.float64)
        for index in np.flatnonzero(self.locals["dones"]):
            info = self.locals["infos"][index]
            record = {"episode": len(self.records) + 1, "timesteps": self.num_timesteps,
                      "cpu_seconds": time.process_time() - self._cpu_start, "return": float(self._running[index])}
            record |= {key: float(info[key]) for key in self.info_keys if key in info}
            self.records.append(record)
            self.returns.append(record["return"])
            self._writer.writerow([record["episode"], record["timesteps"], f"{record['cpu_seconds']:.3f}", record["return"],
                                   *(record.get(key, "") for key in self.info_keys)])
            self._running[index] = 0.0
        self._file.flush()
        return True

    def _on_training_end(self) -> None:
        self._file.close()


def read_episodes(csv_path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read an :class:`EpisodeRecorder` CSV into columns (empty cells become NaN)."""
    with pathlib.Path(csv_path).open(newline="") as file:
        rows = list(csv.DictReader(file))
    if not rows:
        return {}
    return {key: np.array([float(row[key]) if row[key] != "" else np.nan for row in rows]) for key in rows[0]}


def windowed_curve(values: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean of consecutive windows of ``window`` episodes: returns (episodes at each window's end, means)."""
    values = np.asarray(values, dtype=np.float64)
    n = len(values) // window
    if n == 0:
        return np.array([len(values)]), np.array([np.nanmean(values)]) if len(values) else np.array([np.nan])
    means = np.nanmean(values[: n * window].reshape(n, window), axis=1)
    return np.arange(1, n + 1) * window, means
