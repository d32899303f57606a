"""The task registry: :data:`TASKS` maps each task's short name to its :class:`~sb3_genrl.envs.spec.TaskSpec`."""

from __future__ import annotations

from typing import Any

import gymnasium
from gymnasium.envs.registration import register, registry
from sb3_genrl.envs.base import ArmTaskEnv
from sb3_genrl.envs.spec import TaskSpec

from sb3_genrl.task_ids import register_task_id

TASKS: dict[str, TaskSpec] = {}


def register_task(spec: TaskSpec) -> TaskSpec:
    """Add a task to :data:`TASKS` and register its Gymnasium id (idempotent for the same spec).

    :param spec: the task's description
    :return: ``spec``
    """
    known = TASKS.get(spec.name)
    if known is not None and known is not spec:
        raise ValueError(f"a different task is already registered as {spec.name!r}")
    clash = [name for name, other in TASKS.items() if other.env_id == spec.env_id and name != spec.name]
    if clash:
        raise ValueError(f"Gymnasium id {spec.env_id!r} already belongs to task {clash[0]!r}")
    for env_id, cls in ((spec.env_id, spec.env_class), (spec.goal_env_id, spec.goal_env_class)):
        if env_id is not None and env_id not in registry:
            # A module-level class is registered by its import path, as Gymnasium's own envs are.
            entry_point = cls if "<locals>" in cls.__qualname__ else f"{cls.__module__}:{cls.__qualname__}"
            register(id=env_id, entry_point=entry_point, max_episode_steps=spec.horizon)
    register_task_id(spec.name, spec.env_id)
    TASKS[spec.name] = spec
    return spec


def get_task(task: str | TaskSpec) -> TaskSpec:
    """The registered task of a short name or a Gymnasium id (a :class:`TaskSpec` is returned as it is).

    :param task: a name in :data:`TASKS` or the Gymnasium id of one
    :return: the task's description
    """
    if isinstance(task, TaskSpec):
        return task
    if task in TASKS:
        return TASKS[task]
    for spec in TASKS.values():
        if spec.env_id == task:
            return spec
    raise ValueError(
        f"unknown task {task!r}; expected one of {sorted(TASKS)} or their Gymnasium ids "
        f"{sorted(spec.env_id for spec in TASKS.values())}"
    )


def arm_tasks() -> tuple[str, ...]:
    """The registered tasks on the package's arm (:class:`~sb3_genrl.envs.base.ArmTaskEnv`): those that the scripted
    motions' showcase, the feedback baselines, the video and the study run on (not, for now, the Fetch tasks)."""
    return tuple(
        name for name, spec in TASKS.items() if isinstance(spec.env_class, type) and issubclass(spec.env_class, ArmTaskEnv)
    )


def make_task(name: str, **kwargs: Any):
    """``gymnasium.make`` of a registered task by its short name or Gymnasium id, with ``kwargs``."""
    return gymnasium.make(get_task(name).env_id, **kwargs)
