"""Train a GenRL policy on a registered task, with logs, a learning curve (CSV + PNG) and the saved model.

Task-level workflow code: tasks are resolved through the registry (:func:`sb3_genrl.envs.get_task`), imported inside
the functions so that the core library (:class:`~sb3_genrl.GenRL`) never imports the tasks.
"""

from __future__ import annotations

import csv
import math
import os
import pathlib
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from sb3_genrl.callbacks import EpisodeRecorder
from sb3_genrl.curves import plot_curves
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl.genrl import EStep, GenRL
from sb3_genrl.utils import atomic_write_json


class LearningCurveCallback(BaseCallback):
    """Record one row per EM iteration (after its update) and append it to a CSV file as training goes.

    Columns: ``episodes`` (episodes played so far), the iteration's ``mean_table_contacts`` (where the task reports
    ``table_contacts``) and its ``train/`` logs (:attr:`FIELDS`): the columns of the baselines' learning curves
    (:func:`sb3_genrl.curves.write_learning_curve`, one iteration = one window of N episodes) plus GenRL's own.

    :param csv_path: the CSV file to write (created, or overwritten, when training starts)
    :param verbose: verbosity of the callback
    """

    FIELDS = ("mean_reward", "max_reward", "kl", "entropy", "value_loss", "policy_objective", "line_search_success")
    COLUMNS = ("episodes", "mean_reward", "max_reward", "mean_table_contacts", *FIELDS[2:])

    def __init__(self, csv_path: str | os.PathLike, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.csv_path = pathlib.Path(csv_path)
        self.rows: list[dict[str, float]] = []
        self._table_contacts: list[float] = []

    def _on_training_start(self) -> None:
        self.rows, self._table_contacts = [], []
        self.csv_path.parent.mkdir(parents=True, exist_ok=True)
        with self.csv_path.open("w", newline="") as file:
            csv.writer(file).writerow(self.COLUMNS)

    def _on_rollout_start(self) -> None:
        self._record()  # the logs of the update that followed the previous rollout

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
            if done and "table_contacts" in info:
                self._table_contacts.append(float(info["table_contacts"]))
        return True

    def _on_training_end(self) -> None:
        self._record()

    def _record(self) -> None:
        logs = self.model.logger.name_to_value
        if "train/mean_reward" not in logs or (self.rows and self.rows[-1]["episodes"] == self.num_timesteps):
            return
        row = {"episodes": float(self.num_timesteps)} | {key: float(logs.get(f"train/{key}", math.nan)) for key in self.FIELDS}
        row["mean_table_contacts"] = float(np.mean(self._table_contacts)) if self._table_contacts else math.nan
        self._table_contacts = []
        self.rows.append(row)
        with self.csv_path.open("a", newline="") as file:
            csv.writer(file).writerow([row[key] for key in self.COLUMNS])


def evaluate_on_goals(model: GenRL, task: str, goals: int = 100, seed: int = 0,
                      ) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Play the policy's deterministic latent actions for ``goals`` random goals through the task's fast path.

    :param model: a trained GenRL model with its generator
    :param task: a task name from :data:`sb3_genrl.envs.TASKS` or its Gymnasium id
    :param goals: number of goals, drawn with ``np.random.default_rng(seed)``
    :param seed: seed of the goals
    :return: the goals ``(goals, 2)``, the rewards (minus the final distance, m) and the episodes' infos
    """
    from sb3_genrl.envs import get_task

    if model.generator is None:
        raise ValueError("this GenRL model has no generator: pass generator= to GenRL.load()")
    env = get_task(task).make_env()
    rng = np.random.default_rng(seed)
    goal_array = np.array([env.sample_goal(rng) for _ in range(goals)], dtype=np.float32)
    latents, _ = model.predict(goal_array, deterministic=True)
    rewards, infos = env.play_trajectories(model.generator.decode(latents), goal_array)
    env.close()
    return goal_array, rewards, infos


def _resolve_env_id(task: str) -> tuple[str, str]:
    """The Gymnasium id and name of a registered task, or of any registered Gymnasium id (a user's own env)."""
    from sb3_genrl.envs import TASKS, get_task

    if task not in TASKS and task in gym.registry:
        return task, task
    spec = get_task(task)  # raises, listing the registered tasks
    return spec.env_id, spec.name


def train_policy(
    task: str,
    generator: TrajectoryGenerator | str,
    *,
    episodes: int,
    seed: int = 0,
    out_dir: str | os.PathLike,
    e_step: EStep = "trpo",
    batch_episodes: int = 64,
    device: str = "auto",
    progress_bar: bool = False,
    verbose: int = 0,
    **genrl_kwargs: Any,
) -> dict[str, Any]:
    """Train a GenRL policy for ``episodes`` episodes on ``task`` and write everything to ``out_dir``.

    Writes ``genrl_policy.zip`` (the model), ``summary.json``, ``learning_curve.csv`` (one row per iteration,
    written as training goes), ``learning_curve.png``, ``episodes.csv`` (one row per episode, as the baselines write it) and
    TensorBoard logs under ``tensorboard/``.

    :param task: a task name from :data:`sb3_genrl.envs.TASKS`, or any registered Gymnasium id
    :param generator: the trajectory generator or the path of a saved one
    :param episodes: total episodes (trajectories played); rounded up to whole iterations
    :param seed: random seed
    :param out_dir: output folder (created)
    :param e_step: ``"trpo"`` or ``"kl_penalty"`` (see :class:`~sb3_genrl.GenRL`)
    :param batch_episodes: episodes per EM iteration, ``N``
    :param device: torch device
    :param progress_bar: show a progress bar
    :param verbose: GenRL verbosity
    :param genrl_kwargs: further :class:`~sb3_genrl.GenRL` arguments
    :return: paths of the outputs and a summary (``episodes``, ``iterations``, ``final_mean_reward``,
        ``best_mean_reward``)
    """
    if int(episodes) != episodes or episodes < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    if int(batch_episodes) != batch_episodes or batch_episodes < 2:
        raise ValueError(f"batch_episodes must be an integer >= 2, got {batch_episodes!r}")
    env_id, task_name = _resolve_env_id(task)
    out = pathlib.Path(out_dir)
    model = GenRL(  # built first: a generator that does not fit the task is refused before anything is written
        gym.make(env_id),
        generator,
        e_step=e_step,
        n_steps=batch_episodes,
        batch_size=min(batch_episodes, genrl_kwargs.pop("batch_size", 64)),
        seed=seed,
        device=device,
        tensorboard_log=str(out / "tensorboard"),
        verbose=verbose,
        **genrl_kwargs,
    )
    out.mkdir(parents=True, exist_ok=True)
    curve = LearningCurveCallback(out / "learning_curve.csv")
    callbacks = [EpisodeRecorder(out / "episodes.csv"), curve]
    model.learn(total_timesteps=int(episodes), callback=callbacks, progress_bar=progress_bar, tb_log_name="GenRL")
    model.save(out / "genrl_policy.zip")
    episodes_played = np.array([row["episodes"] for row in curve.rows])
    mean_rewards = [row["mean_reward"] for row in curve.rows]
    plot_curves({"GenRL": (episodes_played, np.array(mean_rewards), None)}, out / "learning_curve.png",
                ylabel="mean reward per iteration", title=f"GenRL on {env_id} (seed {seed})")
    result = {
        "algorithm": "genrl",
        "task": task_name,
        "seed": seed,
        "model_path": str(out / "genrl_policy.zip"),
        "csv_path": str(curve.csv_path),
        "png_path": str(out / "learning_curve.png"),
        "episodes_csv_path": str(out / "episodes.csv"),
        "tensorboard_dir": str(out / "tensorboard"),
        "episodes": int(model.num_timesteps),
        "iterations": len(curve.rows),
        "final_mean_reward": mean_rewards[-1] if mean_rewards else math.nan,
        "best_mean_reward": max(mean_rewards) if mean_rewards else math.nan,
    }
    atomic_write_json(out / "summary.json", result)
    return result
