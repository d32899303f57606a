"""GenRL as an rl-zoo3 algorithm (the ``zoo`` extra): rl-zoo3's own ``train``, ``enjoy`` and ``record_video``.

    python -m sb3_genrl.zoo train --algo genrl --env GenRL/Hockey-v0 -n 3000
    python -m sb3_genrl.zoo enjoy --algo genrl --env GenRL/Hockey-v0 -f logs --no-render -n 300 --seed 1
    python -m sb3_genrl.zoo record_video --algo genrl --env GenRL/Hockey-v0 -f logs -n 20
    python -m sb3_genrl.zoo train --algo genrl --env GenRL/Hockey-v0 -optimize --n-trials 4 --n-timesteps 600

:func:`register` adds GenRL to rl-zoo3's ``ALGOS`` and its sampler to ``HYPERPARAMS_SAMPLER`` (as SBX registers its
algorithms); the settings are ``hyperparams/genrl.yml`` (the default ``--conf-file`` of ``--algo genrl``), whose
``env_wrapper`` :func:`latent_action` builds the latent-action wrapper with the task's generator.
"""

from sb3_genrl import GenRL
from sb3_genrl.zoo.sampler import convert_genrl_params, sample_genrl_params
from sb3_genrl.zoo.wrapper import latent_action

__all__ = ["latent_action", "register"]


def register() -> None:
    """Make ``genrl`` an rl-zoo3 algorithm, with its optuna sampler and the converter of its trials' parameters
    (idempotent)."""
    from rl_zoo3.hyperparams_opt import HYPERPARAMS_CONVERTER, HYPERPARAMS_SAMPLER
    from rl_zoo3.utils import ALGOS

    ALGOS["genrl"] = GenRL
    HYPERPARAMS_SAMPLER["genrl"] = sample_genrl_params
    HYPERPARAMS_CONVERTER["genrl"] = convert_genrl_params
