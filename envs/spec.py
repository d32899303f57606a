"""The description of a task that the registry (:data:`sb3_genrl.envs.TASKS`) holds: :class:`TaskSpec`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.envs.base import ArmTaskEnv

from sb3_genrl.checks import check_positive_int


@dataclass(frozen=True, eq=False)
class TaskSpec:
    """Everything the package knows about one task, declared once in the task's module.

    The demonstration generator (:func:`sb3_genrl.envs.demonstrations.make_demonstrations`) makes ``env_class()``
    and uses its ``horizon``, ``max_joint_delta``, ``home_qpos()``, ``sample_goal(rng)``, ``observation_space``,
    ``action_space`` and ``play_trajectories(trajectories, goals, n_threads=..., return_joint_states=True)`` (whose
    infos hold the ``reached`` point): a subclass of :class:`~sb3_genrl.envs.base.ArmTaskEnv` has them all. A task
    that is not an ``ArmTaskEnv`` (Gymnasium-Robotics' Fetch tasks, :mod:`sb3_genrl.envs.fetch`) brings its own
    ``demonstrations`` and ``evaluate``, and its env is made by ``env_class`` (a class or a function).

    :param name: the short name (``genrl demos --task NAME``)
    :param env_id: the Gymnasium id, registered by :func:`sb3_genrl.envs.register_task`
    :param env_class: the env class (or a function that makes the env), called with keyword arguments only
    :param horizon: control steps ``T`` of an episode (the trajectories' length)
    :param goal_low: lower corner ``(x, y)`` of the goal region's bounding box (m)
    :param goal_high: upper corner ``(x, y)`` of the goal region's bounding box (m)
    :param in_goal_region: ``points (N, 2) -> (N,) bool``: whether each point lies in the goal region
    :param cell_size: side of the square cells of the coverage report (m)
    :param sample_expert: ``rng -> (horizon, 7)``: one base motion of the scripted expert, drawn with ``rng`` (a
        task with its own ``demonstrations``: the expert those use)
    :param perturbation_scales: ``(action_dim,)`` travel of one perturbation bump per action dimension at level 1
        (rad for the arm's joints)
    :param is_valid: ``info -> bool``: the task's own test of a stable, unclipped episode (e.g. no table contact)
        for it to become a demonstration
    :param region_patch: draws the goal region's outline on the coverage plot (a Matplotlib patch); by default
        the bounding box
    :param figure_size: size (inches) of the coverage plot
    :param goal_env_id: the Gymnasium id of the task's goal-conditioned variant (dict observations and
        ``compute_reward``, for hindsight experience replay; see :mod:`sb3_genrl.envs.goal`), if it has one
    :param goal_env_class: that variant's class
    :param action_dim: the per-step action's size (the arm's 7 joints by default)
    :param demonstrations: the task's own demonstration maker, ``(spec, episodes, seed, n_threads, progress_bar) ->
        (arrays, drawn, spaces)`` (see :func:`sb3_genrl.envs.demonstrations.fetch.make_arrays`), for a task that is
        not an ``ArmTaskEnv``; None: the arm tasks' (perturbed ``sample_expert`` motions through the fast path)
    :param evaluate: ``(model, task, episodes, seed) -> dict`` with the ``success_rate`` of a GenRL policy, for a task
        whose score is a success (``info["is_success"]``); None: the arm tasks' distance to the goal
    :param generator_preset: the generator of paper table 1 that the quickstart trains for this task (None: its
        default); the latent space must be as large as the expert's family of motions
    :param video: whether the quickstart renders the policy (the arm tasks' offscreen renderer)
    :param quickstart_demo_episodes: the demonstrations ``genrl quickstart`` makes for this task (None: its default,
        :data:`sb3_genrl.study.quickstart.DEMO_EPISODES`)
    :param demonstration_recipe: what the task's demonstrations depend on besides their seed and number (e.g. the
        Fetch tasks' ``aim_margin``), recorded in each dataset's info and compared when a stage reuses a dataset
    """

    name: str
    env_id: str
    env_class: type[ArmTaskEnv] | Callable[..., gym.Env]
    horizon: int
    goal_low: np.ndarray
    goal_high: np.ndarray
    in_goal_region: Callable[[np.ndarray], np.ndarray]
    cell_size: float
    sample_expert: Callable[[np.random.Generator], np.ndarray]
    perturbation_scales: np.ndarray
    is_valid: Callable[[dict[str, Any]], bool]
    region_patch: Callable[[], Any] | None = None
    figure_size: tuple[float, float] = (6.0, 6.0)
    goal_env_id: str | None = None
    goal_env_class: type[ArmTaskEnv] | None = None
    action_dim: int = 7
    demonstrations: Callable[..., tuple[dict[str, np.ndarray], int, dict[str, Any]]] | None = None
    evaluate: Callable[..., dict[str, Any]] | None = None
    generator_preset: str | None = None
    video: bool = True
    quickstart_demo_episodes: int | None = None
    demonstration_recipe: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.name or "/" in self.name:
            raise ValueError(f"a task name must be a non-empty string without '/', got {self.name!r}")
        if int(self.horizon) != self.horizon or self.horizon < 1:
            raise ValueError(f"task {self.name!r}: horizon must be a positive integer, got {self.horizon!r}")
        for corner in ("goal_low", "goal_high"):
            if np.shape(getattr(self, corner)) != (2,):
                raise ValueError(f"task {self.name!r}: {corner} must be an (x, y) pair, got {getattr(self, corner)!r}")
        if not np.all(np.asarray(self.goal_low) < np.asarray(self.goal_high)):
            raise ValueError(f"task {self.name!r}: goal_low {self.goal_low} must be below goal_high {self.goal_high}")
        if np.shape(self.perturbation_scales) != (self.action_dim,):
            raise ValueError(
                f"task {self.name!r}: perturbation_scales must have shape ({self.action_dim},), "
                f"got {np.shape(self.perturbation_scales)}"
            )
        if self.quickstart_demo_episodes is not None:
            check_positive_int(self.quickstart_demo_episodes, f"task {self.name!r}: quickstart_demo_episodes")
        if getattr(self.env_class, "horizon", self.horizon) != self.horizon:
            raise ValueError(
                f"task {self.name!r}: horizon {self.horizon} differs from {self.env_class.__name__}.horizon "
                f"{self.env_class.horizon}"
            )
        if (self.goal_env_id is None) != (self.goal_env_class is None):
            raise ValueError(f"task {self.name!r}: give both goal_env_id and goal_env_class, or neither")
        if not self.cell_size > 0:
            raise ValueError(f"task {self.name!r}: cell_size must be positive, got {self.cell_size!r}")

    def make_env(self, **kwargs: Any) -> ArmTaskEnv | gym.Env:
        """The task's env (unwrapped, without Gymnasium's wrappers), made with ``kwargs``."""
        return self.env_class(**kwargs)
