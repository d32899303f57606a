"""InfoGAN generator (paper section 5.1.2, eq. 10-11; architecture in appendix B)."""

from __future__ import annotations

import math
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from sb3_genrl.generative.common import STD_FLOOR
from sb3_genrl.generative.networks import DiscriminatorWithQ, make_decoder
from sb3_genrl.generative.torch_generator import TorchTrajectoryGenerator

# Adam momentum of the adversarial updates (DCGAN / InfoGAN practice, which pairs with the paper's lr 2e-4).
GAN_ADAM_BETAS = (0.5, 0.999)


def gaussian_info_loss(q_mean: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """``-log Q(alpha | tau)`` for a unit-variance Gaussian ``Q``, up to its constant, averaged over the batch."""
    return 0.5 * (q_mean - alpha).pow(2).sum(dim=1).mean()


class InfoGAN(TorchTrajectoryGenerator):
    """InfoGAN over motor trajectories with a uniform prior ``p(alpha) = U(-1, 1)^N_alpha``.

    By default (``noise_dim=0``) the whole generator input is the latent code ``alpha`` (``N_alpha`` numbers, as in the
    paper's generator table): there is no extra incompressible noise. With ``noise_dim > 0`` the generator also
    receives ``noise_dim`` U(-1, 1) noise values during training, which :meth:`decode` fixes to 0 (their prior mean),
    so decoding is always a deterministic function of ``alpha``. ``Q(alpha | tau)`` is a Gaussian whose mean is the
    Q head's output and whose standard deviation is fixed to 1, so the information term of eq. 11 is
    ``0.5 * ||alpha - Q_mean(g(alpha))||^2`` up to a constant.

    Each minibatch makes two updates (eq. 11): the discriminator and Q head (with the shared layers) minimise
    ``BCE(D(tau), 1) + BCE(D(g(alpha)), 0) + lambda * info``; the generator minimises the non-saturating
    ``BCE(D(g(alpha)), 1) + lambda * info``. Both use Adam with ``betas=(0.5, 0.999)``.

    :param horizon: number of time steps ``T``
    :param action_dim: number of joints ``M``
    :param latent_dim: ``N_alpha`` (paper: 2, 3 or 6)
    :param info_weight: ``lambda``, weight of the mutual-information term (paper: 0.1, 1.5 or 3.5)
    :param noise_dim: extra incompressible noise inputs of the generator (default 0, as in the paper)
    :param std_floor: floor of each normalisation std, a fraction of the largest (see :class:`TorchTrajectoryGenerator`)
    :param device: torch device or ``"auto"``
    """

    decoder_name = "generator"

    def __init__(
        self,
        horizon: int,
        action_dim: int,
        latent_dim: int,
        *,
        info_weight: float,
        noise_dim: int = 0,
        std_floor: float = STD_FLOOR,
        device: torch.device | str = "auto",
    ) -> None:
        if not 0 <= info_weight < math.inf:
            raise ValueError(f"info_weight must be non-negative and finite, got {info_weight}")
        if int(noise_dim) != noise_dim or noise_dim < 0:
            raise ValueError(f"noise_dim must be a non-negative integer, got {noise_dim!r}")
        self.info_weight = float(info_weight)
        self.noise_dim = int(noise_dim)
        super().__init__(
            horizon=horizon, action_dim=action_dim, latent_dim=latent_dim, prior="uniform", std_floor=std_floor, device=device
        )

    def _hyperparameters(self) -> dict[str, Any]:
        return {"info_weight": self.info_weight, "noise_dim": self.noise_dim}

    def _build_networks(self) -> nn.ModuleDict:
        trajectory_size = self.horizon * self.action_dim
        return nn.ModuleDict(
            {
                "generator": make_decoder(self.latent_dim + self.noise_dim, trajectory_size),
                "discriminator": DiscriminatorWithQ(trajectory_size, self.latent_dim),
            }
        )

    def _make_optimizers(self, lr: float) -> list[torch.optim.Optimizer]:
        return [
            torch.optim.Adam(self.networks["discriminator"].parameters(), lr=lr, betas=GAN_ADAM_BETAS, foreach=True),
            torch.optim.Adam(self.networks["generator"].parameters(), lr=lr, betas=GAN_ADAM_BETAS, foreach=True),
        ]

    def _decoder_input(self, alpha: torch.Tensor) -> torch.Tensor:
        # Decoding fixes the incompressible noise (if any) to its prior mean 0.
        return torch.cat([alpha, alpha.new_zeros(len(alpha), self.noise_dim)], dim=1) if self.noise_dim else alpha

    def _train_step(
        self, batch: torch.Tensor, optimizers: list[torch.optim.Optimizer], generator: torch.Generator
    ) -> dict[str, float]:
        discriminator_optimizer, generator_optimizer = optimizers
        discriminator = self.networks["discriminator"]
        alpha = self._noise("uniform", (len(batch), self.latent_dim), generator)
        noise = self._noise("uniform", (len(batch), self.noise_dim), generator)
        fake = self.networks["generator"](torch.cat([alpha, noise], dim=1))
        ones, zeros = torch.ones(len(batch), device=self.device), torch.zeros(len(batch), device=self.device)

        # Discriminator and Q step: max over D of eq. 10, min over Q of the information term of eq. 11.
        real_logit, _ = discriminator(batch)
        fake_logit, q_mean = discriminator(fake.detach())
        discriminator_loss = F.binary_cross_entropy_with_logits(real_logit, ones) + F.binary_cross_entropy_with_logits(
            fake_logit, zeros
        )
        q_loss = gaussian_info_loss(q_mean, alpha)
        discriminator_optimizer.zero_grad()
        (discriminator_loss + self.info_weight * q_loss).backward()
        discriminator_optimizer.step()

        # Generator step: non-saturating adversarial loss + lambda * information term (eq. 11).
        fake_logit, q_mean = discriminator(fake)
        generator_loss = F.binary_cross_entropy_with_logits(fake_logit, ones)
        info_loss = gaussian_info_loss(q_mean, alpha)
        generator_optimizer.zero_grad()
        (generator_loss + self.info_weight * info_loss).backward()
        generator_optimizer.step()
        return {"discriminator": discriminator_loss.item(), "generator": generator_loss.item(), "info": info_loss.item()}
