"""Policies for GenRL: ``pi_theta(alpha | s0)``, a Gaussian over the latent action given the task context.

GenRL uses SB3's actor-critic policies unchanged: an MLP maps the context ``s0`` to the mean of a diagonal
Gaussian over ``alpha`` with a state-independent log standard deviation, and a separate MLP head gives the value
``V(s0)``. :class:`~sb3_genrl.GenRL` sets ``log_std_init`` from the generator's prior unless the user gives it
(see :func:`default_log_std_init`), so that the initial policy explores about as widely as the prior.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.policies import ActorCriticPolicy, MultiInputActorCriticPolicy

from sb3_genrl.generative.base import Prior

MlpPolicy = ActorCriticPolicy
MultiInputPolicy = MultiInputActorCriticPolicy


def default_log_std_init(prior: Prior) -> float:
    """Log of the prior's standard deviation: 0 for N(0, 1), log(1/sqrt(3)) for U(-1, 1)."""
    return 0.0 if prior == "normal" else float(np.log(1.0 / np.sqrt(3.0)))
