"""Short task names and the Gymnasium ids they stand for (the hockey task's name and ``GenRL/Hockey-v0``).

The tasks register their names here (:func:`sb3_genrl.envs.register_task` does), so that the library can take a task
by its short name without importing the tasks: a name resolves to an id, and the id to an env through Gymnasium's
registry.
"""

from __future__ import annotations

_IDS: dict[str, str] = {}


def register_task_id(name: str, env_id: str) -> None:
    """Let ``name`` stand for the Gymnasium id ``env_id`` (idempotent for the same pair).

    :raises ValueError: when ``name`` already stands for another id
    """
    known = _IDS.get(name)
    if known is not None and known != env_id:
        raise ValueError(f"task name {name!r} already stands for {known!r}, not {env_id!r}")
    _IDS[name] = env_id


def task_env_id(task: str) -> str:
    """The Gymnasium id of a registered task's short name, or of its Gymnasium id.

    :raises ValueError: naming the registered tasks, when ``task`` is neither
    """
    if task in _IDS:
        return _IDS[task]
    if task in _IDS.values():
        return task
    raise ValueError(f"unknown task {task!r}; expected one of {sorted(_IDS)} or their Gymnasium ids {sorted(_IDS.values())}")
