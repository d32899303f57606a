"""Observation normalisation inside the policy, with statistics fixed from the demonstrations.

The baselines normalise observations as SB3's ``VecNormalize`` does (subtract the mean, divide by the standard
deviation, clip at 10), but inside the policy's features extractor and with statistics taken once from the
demonstrations: they are then saved in the model's zip with the weights, applied alike to the env's observations,
to SAC's replay samples and to HER's relabelled goals, and they do not drift under a behaviour-cloned actor as
running statistics would.
"""

from __future__ import annotations

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

CLIP = 10.0  # VecNormalize's default clip_obs
# Floor of each standard deviation, in the features' units (m, rad, rad/s): the demonstrations barely move some
# joints (0.003 rad of spread), and dividing by that spread would turn the small deviations of a closed-loop
# rollout into large inputs (the floor was chosen on tuning goals, not the evaluation goals).
STD_FLOOR = 0.05


def observation_statistics(observations: np.ndarray, *, std_floor: float = STD_FLOOR) -> dict[str, np.ndarray]:
    """Mean and standard deviation of each observation feature.

    :param observations: ``(N, D)`` observations
    :param std_floor: smallest standard deviation kept
    :return: ``{"mean": (D,), "std": (D,)}`` float32 arrays
    """
    observations = np.asarray(observations, dtype=np.float64)
    if observations.ndim != 2 or len(observations) < 2:
        raise ValueError(f"observations must have shape (N >= 2, D), got {observations.shape}")
    if not std_floor > 0:
        raise ValueError(f"std_floor must be positive, got {std_floor}")
    std = np.maximum(observations.std(axis=0), std_floor)
    return {"mean": observations.mean(axis=0).astype(np.float32), "std": std.astype(np.float32)}


class NormalizedFlatten(BaseFeaturesExtractor):
    """Flatten a Box observation and normalise it with fixed statistics: ``clip((obs - mean) / std, -clip, clip)``.

    :param observation_space: a flat Box observation space
    :param mean: ``(D,)`` mean of each feature
    :param std: ``(D,)`` standard deviation of each feature (positive)
    :param clip: bound of the normalised features
    """

    def __init__(self, observation_space: spaces.Box, mean: np.ndarray, std: np.ndarray, clip: float = CLIP) -> None:
        dim = int(np.prod(observation_space.shape))
        super().__init__(observation_space, features_dim=dim)
        self.clip = float(clip)
        self.register_buffer("mean", _vector(mean, dim, "mean"))
        self.register_buffer("std", _vector(std, dim, "std", positive=True))

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return th.clamp((observations.flatten(1) - self.mean) / self.std, -self.clip, self.clip)


class NormalizedCombined(BaseFeaturesExtractor):
    """Normalise each entry of a Dict observation with its own fixed statistics and concatenate them (in the
    space's key order, as SB3's ``CombinedExtractor`` does).

    :param observation_space: a Dict of flat Box spaces (a goal-conditioned env's)
    :param statistics: per key, ``{"mean": ..., "std": ...}``; keys without statistics pass unnormalised
    :param clip: bound of the normalised features
    """

    def __init__(
        self, observation_space: spaces.Dict, statistics: dict[str, dict[str, np.ndarray]], clip: float = CLIP
    ) -> None:
        unknown = sorted(set(statistics) - set(observation_space.spaces))
        if unknown:
            raise ValueError(
                f"statistics for keys {unknown} that the observation space lacks ({sorted(observation_space.spaces)})"
            )
        dims = {key: int(np.prod(space.shape)) for key, space in observation_space.spaces.items()}
        super().__init__(observation_space, features_dim=sum(dims.values()))
        self.clip = float(clip)
        self.keys = list(observation_space.spaces)
        for key, dim in dims.items():
            stats = statistics.get(key, {"mean": np.zeros(dim), "std": np.ones(dim)})
            self.register_buffer(f"mean_{key}", _vector(stats["mean"], dim, f"{key} mean"))
            self.register_buffer(f"std_{key}", _vector(stats["std"], dim, f"{key} std", positive=True))

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        parts = [
            (observations[key].flatten(1) - getattr(self, f"mean_{key}")) / getattr(self, f"std_{key}") for key in self.keys
        ]
        return th.clamp(th.cat(parts, dim=1), -self.clip, self.clip)


def _vector(values: np.ndarray, dim: int, name: str, *, positive: bool = False) -> th.Tensor:
    values = np.asarray(values, dtype=np.float32)
    if values.shape != (dim,) or not np.all(np.isfinite(values)):
        raise ValueError(f"{name} must be a finite ({dim},) array, got shape {values.shape}")
    if positive and not np.all(values > 0):
        raise ValueError(f"{name} must be positive, got {values}")
    return th.as_tensor(values)
