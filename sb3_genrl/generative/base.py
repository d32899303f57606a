"""The interface every trajectory generator implements (paper section 3).

A generator ``g`` maps a latent action ``alpha`` (``latent_dim`` numbers) to a whole open-loop motor
trajectory ``tau = g(alpha)`` of ``horizon`` time steps and ``action_dim`` joints, in raw action units.
The GenRL policy, the :class:`~sb3_genrl.LatentActionWrapper` and the metrics only rely on this interface,
so any object implementing it (a neural decoder, a linear map, a motion primitive library) can be used.
"""

from __future__ import annotations

import abc
from typing import Literal

import numpy as np

Prior = Literal["normal", "uniform"]


class TrajectoryGenerator(abc.ABC):
    """A map from latent actions to motor trajectories.

    :param horizon: number of time steps ``T`` of a generated trajectory
    :param action_dim: number of action dimensions ``M`` per time step (joints)
    :param latent_dim: dimension ``N_alpha`` of the latent action
    :param prior: ``"normal"`` (standard normal, beta-VAE) or ``"uniform"`` (U(-1, 1), InfoGAN)
    """

    def __init__(self, *, horizon: int, action_dim: int, latent_dim: int, prior: Prior) -> None:
        for name, value in (("horizon", horizon), ("action_dim", action_dim), ("latent_dim", latent_dim)):
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if prior not in ("normal", "uniform"):
            raise ValueError(f"prior must be 'normal' or 'uniform', got {prior!r}")
        self.horizon = int(horizon)
        self.action_dim = int(action_dim)
        self.latent_dim = int(latent_dim)
        self.prior: Prior = prior

    @property
    def latent_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Bounds of the prior's support: ``(-1, 1)`` per dimension for a uniform prior, ``None`` when unbounded."""
        if self.prior == "uniform":
            return -np.ones(self.latent_dim), np.ones(self.latent_dim)
        return None

    def sample_prior(self, n: int, rng: np.random.Generator | int | None = None) -> np.ndarray:
        """Draw ``n`` latent actions from the prior, as a ``(n, latent_dim)`` float32 array."""
        rng = np.random.default_rng(rng)
        if self.prior == "normal":
            return rng.standard_normal((n, self.latent_dim)).astype(np.float32)
        return rng.uniform(-1.0, 1.0, size=(n, self.latent_dim)).astype(np.float32)

    def check_latent(self, alpha: np.ndarray) -> np.ndarray:
        """Return ``alpha`` as a finite ``(n, latent_dim)`` float32 array or raise a ``ValueError`` naming the problem."""
        alpha = np.asarray(alpha, dtype=np.float32)
        if alpha.ndim == 1:
            alpha = alpha[None]
        if alpha.ndim != 2 or alpha.shape[1] != self.latent_dim:
            raise ValueError(f"latent actions must have shape (n, {self.latent_dim}), got {alpha.shape}")
        if not np.all(np.isfinite(alpha)):
            raise ValueError("latent actions contain non-finite values (nan or inf)")
        return alpha

    @abc.abstractmethod
    def decode(self, alpha: np.ndarray) -> np.ndarray:
        """Map latent actions ``(n, latent_dim)`` to trajectories ``(n, horizon, action_dim)`` in raw action units."""

    @abc.abstractmethod
    def save(self, path: str) -> None:
        """Write the generator (weights, configuration, normalisation, package version) to one file."""
