"""The description of a task that the registry (:data:`sb3_genrl.envs.TASKS`) holds: :class:`TaskSpec`."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sb3_genrl.envs.base import ArmTaskEnv


@dataclass(frozen=True, eq=False)
class TaskSpec:
    """Everything the package knows about one task, declared once in the task's module.

    The demonstration generator (:func:`sb3_genrl.envs.demonstrations.make_demonstrations`) makes ``env_class()``
    and uses its ``horizon``, ``max_joint_delta``, ``home_qpos()``, ``sample_goal(rng)``, ``observation_space``,
    ``action_space`` and ``play_trajectories(trajectories, goals, n_threads=..., return_joint_states=True)`` (whose
    infos hold the ``reached`` point): a subclass of :class:`~sb3_genrl.envs.base.ArmTaskEnv` has them all.

    :param name: the short name (``genrl demos --task NAME``)
    :param env_id: the Gymnasium id, registered by :func:`sb3_genrl.envs.register_task`
    :param env_class: the env class, made with keyword arguments only
    :param horizon: control steps ``T`` of an episode (the trajectories' length)
    :param goal_low: lower corner ``(x, y)`` of the goal region's bounding box (m)
    :param goal_high: upper corner ``(x, y)`` of the goal region's bounding box (m)
    :param in_goal_region: ``points (N, 2) -> (N,) bool``: whether each point lies in the goal region
    :param cell_size: side of the square cells of the coverage report (m)
    :param sample_expert: ``rng -> (horizon, 7)``: one base motion of the scripted expert, drawn with ``rng``
    :param perturbation_scales: ``(7,)`` joint travel (rad) of one perturbation bump per joint at level 1
    :param is_valid: ``info -> bool``: the task's own test of a stable, unclipped episode (e.g. no table contact)
        for it to become a demonstration
    :param region_patch: draws the goal region's outline on the coverage plot (a Matplotlib patch); by default
        the bounding box
    :param figure_size: size (inches) of the coverage plot
    :param goal_env_id: the Gymnasium id of the task's goal-conditioned variant (dict observations and
        ``compute_reward``, for hindsight experience replay; see :mod:`sb3_genrl.envs.goal`), if it has one
    :param goal_env_class: that variant's class
    :param quickstart: the task's GenRL settings, used by ``genrl quickstart``, ``genrl train-policy``, the study
        and the task's benchmark: ``policy_episodes`` (GenRL episodes, default 3000), ``batch_episodes`` (episodes
        per EM iteration, default 64; the study's scales set their own) and ``genrl_kwargs`` (further
        :class:`~sb3_genrl.GenRL` arguments, without ``n_steps``, which ``batch_episodes`` sets); a task needing
        other settings than the defaults says so here
    """

    name: str
    env_id: str
    env_class: type[ArmTaskEnv]
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
    quickstart: Mapping[str, Any] = field(default_factory=dict)

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
        if np.shape(self.perturbation_scales) != (7,):
            raise ValueError(f"task {self.name!r}: perturbation_scales must have shape (7,), "
                             f"got {np.shape(self.perturbation_scales)}")
        if getattr(self.env_class, "horizon", self.horizon) != self.horizon:
            raise ValueError(f"task {self.name!r}: horizon {self.horizon} differs from {self.env_class.__name__}.horizon "
                             f"{self.env_class.horizon}")
        if (self.goal_env_id is None) != (self.goal_env_class is None):
            raise ValueError(f"task {self.name!r}: give both goal_env_id and goal_env_class, or neither")
        self._check_quickstart()
        if not self.cell_size > 0:
            raise ValueError(f"task {self.name!r}: cell_size must be positive, got {self.cell_size!r}")

    def _check_quickstart(self) -> None:
        unknown = set(self.quickstart) - {"policy_episodes", "batch_episodes", "genrl_kwargs"}
        if unknown:
            raise ValueError(f"task {self.name!r}: unknown quickstart settings {sorted(unknown)}; expected "
                             "'policy_episodes', 'batch_episodes' and 'genrl_kwargs'")
        for key, minimum in (("policy_episodes", 1), ("batch_episodes", 2)):
            value = self.quickstart.get(key, minimum)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
                raise ValueError(f"task {self.name!r}: quickstart {key} must be an integer of at least {minimum}, "
                                 f"got {value!r}")
        genrl_kwargs = self.quickstart.get("genrl_kwargs", {})
        if not isinstance(genrl_kwargs, Mapping):
            raise ValueError(f"task {self.name!r}: quickstart genrl_kwargs must be a mapping, got {genrl_kwargs!r}")
        if "n_steps" in genrl_kwargs:
            raise ValueError(f"task {self.name!r}: give the episodes per iteration as quickstart batch_episodes, not "
                             "as genrl_kwargs n_steps")

    def make_env(self, **kwargs: Any) -> ArmTaskEnv:
        """The task's env (unwrapped, without Gymnasium's wrappers), made with ``kwargs``."""
        return self.env_class(**kwargs)
