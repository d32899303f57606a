"""Policies for GenRL: ``pi_theta(alpha | s0)``, a Gaussian over the latent action given the task context.

GenRL uses SB3's actor-critic policies: an MLP maps the context ``s0`` to the mean of a diagonal Gaussian over
``alpha`` with a state-independent log standard deviation, and a separate MLP head gives the value ``V(s0)``.
:class:`~sb3_genrl.GenRL` sets ``log_std_init`` from the generator's prior unless the user gives it (see
:func:`default_log_std_init`), so that the initial policy explores about as widely as the prior, and, for a Box
context, the features extractor :class:`BoxScaler`, which maps the context's bounded box onto ``[-1, 1]`` (a goal
region of 0.65 m by 0.8 m would otherwise need large first-layer weights, which trust-region steps grow slowly).
"""

from __future__ import annotations

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy, MultiInputActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from sb3_genrl.generative.base import Prior

MlpPolicy = ActorCriticPolicy
MultiInputPolicy = MultiInputActorCriticPolicy


def default_log_std_init(prior: Prior) -> float:
    """Log of the prior's standard deviation: 0 for N(0, 1), log(1/sqrt(3)) for U(-1, 1)."""
    return 0.0 if prior == "normal" else float(np.log(1.0 / np.sqrt(3.0)))


class BoxScaler(BaseFeaturesExtractor):
    """Flatten a Box observation and map each bounded dimension from ``[low, high]`` onto ``[-1, 1]``.

    Unbounded dimensions pass unchanged.

    :param observation_space: the (Box) observation space
    """

    def __init__(self, observation_space: spaces.Box) -> None:
        super().__init__(observation_space, int(np.prod(observation_space.shape)))
        low = np.asarray(observation_space.low, dtype=np.float64).ravel()
        high = np.asarray(observation_space.high, dtype=np.float64).ravel()
        bounded = np.isfinite(low) & np.isfinite(high) & (high > low)
        centre, half_width = np.zeros_like(low), np.ones_like(low)
        centre[bounded] = (low[bounded] + high[bounded]) / 2  # only bounded entries: inf - inf would warn
        half_width[bounded] = (high[bounded] - low[bounded]) / 2
        self.register_buffer("centre", th.as_tensor(centre, dtype=th.float32))
        self.register_buffer("half_width", th.as_tensor(half_width, dtype=th.float32))

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return (observations.flatten(1) - self.centre) / self.half_width
