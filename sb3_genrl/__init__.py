"""sb3-genrl: policies trained in the latent space of generative models of motor trajectories (GenRL)."""

from importlib.metadata import entry_points

from sb3_genrl.genrl import GenRL
from sb3_genrl.vec_env import BatchedLatentVecEnv, make_latent_vec_env
from sb3_genrl.version import __version__
from sb3_genrl.wrappers import LatentActionWrapper

__all__ = ["BatchedLatentVecEnv", "GenRL", "LatentActionWrapper", "__version__", "make_latent_vec_env"]


def _register_gymnasium_plugins() -> None:
    # Gymnasium >= 1.0 no longer loads the ``gymnasium.envs`` entry point group by itself; load ours so
    # ``gymnasium.make("GenRL/Hockey-v0")`` works once ``sb3_genrl`` is imported. Registration only stores
    # string entry points: no simulator is imported here.
    for entry_point in entry_points(group="gymnasium.envs"):
        if entry_point.dist is not None and entry_point.dist.name == "sb3-genrl":
            entry_point.load()()


_register_gymnasium_plugins()
