"""The paper's MuJoCo tasks (section 6.1.1): ``GenRL/Hockey-v0`` and ``GenRL/Basketball-v0``."""

from gymnasium.envs.registration import register, registry

TASK_IDS = {"hockey": "GenRL/Hockey-v0", "basketball": "GenRL/Basketball-v0"}


def register_envs() -> None:
    """Register the tasks with Gymnasium (idempotent). Called through the ``gymnasium.envs`` entry point."""
    if "GenRL/Hockey-v0" not in registry:
        register(id="GenRL/Hockey-v0", entry_point="sb3_genrl.envs.hockey:HockeyEnv", max_episode_steps=69)
    if "GenRL/Basketball-v0" not in registry:
        register(id="GenRL/Basketball-v0", entry_point="sb3_genrl.envs.basketball:BasketballEnv", max_episode_steps=78)


register_envs()
