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

from sb3_genrl.envs import basketball, fetch, fetch_tasks, hockey, metaworld
from sb3_genrl.envs.fetch_mujoco import fix_on_import
from sb3_genrl.envs.registry import TASKS, arm_tasks, get_task, make_task, register_task
from sb3_genrl.envs.spec import TaskSpec

__all__ = ["DEFAULT_TASK", "TASKS", "TaskSpec", "arm_tasks", "get_task", "make_task", "register_envs", "register_task"]

# Gymnasium-Robotics' Fetch tasks, when its optional extra is installed (``pip install "sb3-genrl[robotics]"``; looked up
# without importing it)
ROBOTICS = importlib.util.find_spec("gymnasium_robotics") is not None
_BUILT_IN = (hockey.TASK, basketball.TASK, *(fetch_tasks.TASKS if ROBOTICS else ()))
DEFAULT_TASK = hockey.TASK.name  # the quickstart's task


def register_envs() -> None:
    """Register the package's tasks (idempotent). Called on import, and through the ``gymnasium.envs`` entry point by
    Gymnasium releases that load plugins."""
    for spec in _BUILT_IN:
        register_task(spec)
    if ROBOTICS:  # Gymnasium-Robotics' joint helpers fixed now if it is imported, else as soon as it is
        fix_on_import(fetch.FETCH_IDS)
    metaworld.register_metaworld_envs()  # GenRL/metaworld-<name>, when Meta-World is installed (not imported here)


register_envs()
