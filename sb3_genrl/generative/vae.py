"""beta-VAE generator (paper section 5.1.1, eq. 9; architecture in appendix B)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch import nn

from sb3_genrl.generative.common import STD_FLOOR
from sb3_genrl.generative.networks import GaussianEncoder, make_decoder
from sb3_genrl.generative.torch_generator import TorchTrajectoryGenerator


def gaussian_kl_to_standard_normal(mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """``KL(N(mean, exp(log_std)^2) || N(0, I))`` per row, summed over the latent dimensions."""
    return 0.5 * (mean.pow(2) + torch.exp(2.0 * log_std) - 1.0 - 2.0 * log_std).sum(dim=1)


class BetaVAE(TorchTrajectoryGenerator):
    """beta-VAE over motor trajectories with a standard normal prior ``p(alpha) = N(0, I)``.

    Training minimises the negative of the lower bound of eq. 9, per trajectory and averaged over a minibatch::

        loss = mean_{t, j} (tau_hat[t, j] - tau[t, j])^2 + beta * KL(q(alpha | tau) || N(0, I))

    The reconstruction term is the squared error *averaged* over the ``T * M`` elements of the normalised trajectory
    (a unit-variance Gaussian likelihood divided by ``T * M``), and the KL term is summed over the ``N_alpha`` latent
    dimensions. Relative to a summed Gaussian log-likelihood this ``beta`` therefore equals ``beta_summed / (T * M)``.
    ``alpha`` is drawn with the reparameterisation trick; :meth:`decode` uses the decoder only.

    With ``path_weight > 0`` (not in the paper) the loss also weighs the error of the trajectory's running sum::

        + path_weight * mean_{t, j} (sum_{s <= t} (tau_hat[s, j] - tau[s, j]) / (sigma_j * sqrt(T)))^2

    in raw units, ``sigma_j`` joint ``j``'s normalisation std averaged over time. Where actions are displacements or
    velocity commands (the Fetch tasks' end-effector moves), the running sum is the path the robot takes: a small
    error repeated at every step moves the path's end far, and the per-step error alone hardly sees it.

    :param horizon: number of time steps ``T``
    :param action_dim: number of joints ``M``
    :param latent_dim: ``N_alpha`` (paper: 2, 3 or 6)
    :param beta: weight of the KL term (paper: 0.01, 0.005 or 0.001)
    :param std_floor: floor of each normalisation std, a fraction of the largest (see :class:`TorchTrajectoryGenerator`)
    :param path_weight: weight of the running sum's error (default 0: eq. 9 alone)
    :param device: torch device or ``"auto"``
    """

    decoder_name = "decoder"
    has_encoder = True

    def __init__(
        self,
        horizon: int,
        action_dim: int,
        latent_dim: int,
        *,
        beta: float,
        std_floor: float = STD_FLOOR,
        path_weight: float = 0.0,
        device: torch.device | str = "auto",
    ) -> None:
        if not 0 <= beta < math.inf:
            raise ValueError(f"beta must be non-negative and finite, got {beta}")
        if not 0 <= path_weight < math.inf:
            raise ValueError(f"path_weight must be non-negative and finite, got {path_weight}")
        self.beta, self.path_weight = float(beta), float(path_weight)
        super().__init__(
            horizon=horizon, action_dim=action_dim, latent_dim=latent_dim, prior="normal", std_floor=std_floor, device=device
        )

    def _hyperparameters(self) -> dict[str, Any]:
        # (path_weight only where set: the files of eq. 9's models stay as they were)
        return {"beta": self.beta} | ({"path_weight": self.path_weight} if self.path_weight else {})

    def _build_networks(self) -> nn.ModuleDict:
        trajectory_size = self.horizon * self.action_dim
        return nn.ModuleDict(
            {
                "encoder": GaussianEncoder(trajectory_size, self.latent_dim),
                "decoder": make_decoder(self.latent_dim, trajectory_size),
            }
        )

    def _make_optimizers(self, lr: float) -> list[torch.optim.Optimizer]:
        return [torch.optim.Adam(self.networks.parameters(), lr=lr, foreach=True)]

    def encode(self, trajectories: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and log standard deviation of ``q(alpha | tau)`` for raw ``(n, T, M)`` trajectories, float32 (eval mode)."""
        trajectories = np.asarray(trajectories, dtype=np.float32)
        if trajectories.ndim != 3 or trajectories.shape[1:] != (self.horizon, self.action_dim):
            raise ValueError(f"trajectories must have shape (n, {self.horizon}, {self.action_dim}), got {trajectories.shape}")
        if not np.all(np.isfinite(trajectories)):
            raise ValueError("trajectories contain non-finite values (nan or inf)")
        self.networks.eval()
        with torch.no_grad():
            normalised = self.normalise(torch.as_tensor(trajectories, device=self.device))
            mean, log_std = self.networks["encoder"](normalised)
        return mean.cpu().numpy(), log_std.cpu().numpy()

    def reconstruction_mse(self, trajectories: np.ndarray) -> float:
        """Mean squared error, per element in raw action units, of raw ``(n, T, M)`` trajectories decoded from their
        posterior means (eval mode)."""
        trajectories = np.asarray(trajectories, dtype=np.float32)
        mean, _ = self.encode(trajectories)
        return float(np.mean((self.decode(mean).astype(np.float64) - trajectories) ** 2))

    def _train_step(
        self, batch: torch.Tensor, optimizers: list[torch.optim.Optimizer], generator: torch.Generator
    ) -> dict[str, float]:
        (optimizer,) = optimizers
        # Approximate posterior q(alpha | tau) and a reparameterised sample alpha = mean + std * eps.
        mean, log_std = self.networks["encoder"](batch)
        alpha = mean + torch.exp(log_std) * self._noise("normal", tuple(mean.shape), generator)
        reconstruction = self.networks["decoder"](alpha)
        # Eq. 9: reconstruction error (mean over the T*M elements) + beta * KL to the prior.
        reconstruction_loss = (reconstruction - batch).pow(2).mean(dim=1).mean()
        kl = gaussian_kl_to_standard_normal(mean, log_std).mean()
        loss = reconstruction_loss + self.beta * kl
        path = {}
        if self.path_weight:
            path_loss = self.path_error(reconstruction, batch)
            loss = loss + self.path_weight * path_loss
            path = {"path": path_loss.item()}
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        return {"loss": loss.item(), "reconstruction": reconstruction_loss.item(), "kl": kl.item(), **path}

    def path_error(self, reconstruction: torch.Tensor, batch: torch.Tensor) -> torch.Tensor:
        """The running sum's squared error of normalised, flattened ``(B, T*M)`` trajectories (see the class doc),
        averaged over the batch, the time steps and the joints."""
        std = self.action_std.reshape(self.horizon, self.action_dim)
        error = (reconstruction - batch).view(-1, self.horizon, self.action_dim) * std  # raw units
        return (torch.cumsum(error, dim=1) / (std.mean(dim=0) * self.horizon**0.5)).pow(2).mean()
