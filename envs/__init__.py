"""The paper's MuJoCo tasks (section 6.1.1): ``GenRL/Hockey-v0`` and ``GenRL/Basketball-v0``."""

import os

from gymnasium.envs.registration import register, registry

# Offscreen rendering on machines without a display.
if "DISPLAY" not in os.environ:
    os.environ.setdefault("MUJOCO_GL", "egl")

TASK_IDS = {"hockey": "GenRL/Hockey-v0", "basketball": "GenRL/Basketball-v0"}


def register_envs() -> None:
    """Register the tasks with Gymnasium (idempotent). Called through the ``gymnasium.envs`` entry point."""
    if "GenRL/Hockey-v0" not in registry:
        register(id="GenRL/Hockey-v0", entry_point="sb3_genrl.envs.hockey:HockeyEnv", max_episode_steps=69)
    if "GenRL/Basketball-v0" not in registry:
        register(id="GenRL/Basketball-v0", entry_point="sb3_genrl.envs.basketball:BasketballEnv", max_episode_steps=78)


register_envs()


def make_task(name: str, **kwargs):
    """Make a task by its short name (``"hockey"`` or ``"basketball"``) or its Gymnasium id."""
    import gymnasium

    env_id = TASK_IDS.get(name, name)
    if env_id not in TASK_IDS.values():
        raise ValueError(f"unknown task {name!r}; expected one of {sorted(TASK_IDS)} or {sorted(TASK_IDS.values())}")
    return gymnasium.make(env_id, **kwargs)
