"""The task registry: :data:`TASKS` maps each task's short name to its :class:`TaskSpec`.

The paper's MuJoCo tasks (section 6.1.1) are ``hockey`` (``GenRL/Hockey-v0``) and ``basketball``
(``GenRL/Basketball-v0``). Each lives in one module (:mod:`sb3_genrl.envs.hockey`, :mod:`sb3_genrl.envs.basketball`)
that declares its :class:`TaskSpec`; a new task is one more such module and one :func:`register_task` call (for the
package's own tasks, one more entry in :data:`_BUILT_IN`). A task may also declare a goal-conditioned variant for
hindsight experience replay (``GenRL/HockeyGoal-v0``, ``GenRL/BasketballGoal-v0``: ``get_task(name).goal_env_id``).
With the optional extra ``robotics``, Gymnasium-Robotics' Fetch tasks join them (:mod:`sb3_genrl.envs.fetch`:
``fetch-reach``, ``fetch-push``, ``fetch-slide``, ``fetch-pick-and-place``, under Gymnasium-Robotics' own ids).
Meta-World's 50 tasks, when ``metaworld`` is installed, are Gymnasium ids only (``GenRL/metaworld-push-v3``, ...;
:mod:`sb3_genrl.envs.metaworld`), not entries of :data:`TASKS`.
"""

from __future__ import annotations

import importlib.util
from typing import Any

from gymnasium.envs.registration import register, registry
from sb3_genrl.envs import basketball, fetch, hockey, metaworld
from sb3_genrl.envs.spec import TaskSpec

from sb3_genrl.task_ids import register_task_id

__all__ = ["DEFAULT_TASK", "TASKS", "TaskSpec", "arm_tasks", "get_task", "make_task", "register_envs", "register_task"]

TASKS: dict[str, TaskSpec] = {}
# Gymnasium-Robotics' Fetch tasks, when its optional extra is installed (``pip install "sb3-genrl[robotics]"``; looked up
# without importing it)
ROBOTICS = importlib.util.find_spec("gymnasium_robotics") is not None
_BUILT_IN = (hockey.TASK, basketball.TASK, *(fetch.TASKS if ROBOTICS else ()))
DEFAULT_TASK = hockey.TASK.name  # the quickstart's task


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
    from sb3_genrl.envs.base import ArmTaskEnv

    return tuple(
        name for name, spec in TASKS.items() if isinstance(spec.env_class, type) and issubclass(spec.env_class, ArmTaskEnv)
    )


def make_task(name: str, **kwargs: Any):
    """``gymnasium.make`` of a registered task by its short name or Gymnasium id, with ``kwargs``."""
    import gymnasium

    return gymnasium.make(get_task(name).env_id, **kwargs)


def register_envs() -> None:
    """Register the package's tasks (idempotent). Called on import, and through the ``gymnasium.envs`` entry point by
    Gymnasium releases that load plugins."""
    for spec in _BUILT_IN:
        register_task(spec)
    if ROBOTICS:  # Gymnasium-Robotics' joint helpers fixed now if it is imported, else as soon as it is
        from sb3_genrl.envs.fetch_mujoco import fix_on_import

        fix_on_import(fetch.FETCH_IDS)
    metaworld.register_metaworld_envs()  # GenRL/metaworld-<name>, when Meta-World is installed (not imported here)


register_envs()
