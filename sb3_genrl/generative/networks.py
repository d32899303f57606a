"""Network architectures of paper appendix B (tables 7 and 8: the generator, the discriminator and Q-network)."""

from __future__ import annotations

import torch
from torch import nn

# Hidden sizes of the decoder / generator (paper appendix B, table "Architecture of the generator neural network").
DECODER_HIDDEN_SIZES = (128, 256, 512)
# Shared discriminator layers and Q head (paper appendix B, table "Architecture of the discriminator and Qnet").
DISCRIMINATOR_HIDDEN_SIZES = (256, 128)
Q_HIDDEN_SIZE = 64


def _linear_bn_relu(in_features: int, out_features: int) -> list[nn.Module]:
    return [nn.Linear(in_features, out_features), nn.BatchNorm1d(out_features), nn.ReLU()]


def make_decoder(latent_dim: int, output_dim: int) -> nn.Sequential:
    """Decoder / generator: Lin(Na,128)+BN+ReLU, Lin(128,256)+BN+ReLU, Lin(256,512)+BN+ReLU, Lin(512,T*M).

    :param latent_dim: ``N_alpha``
    :param output_dim: ``T * M``, the flattened trajectory size
    """
    layers: list[nn.Module] = []
    sizes = (latent_dim, *DECODER_HIDDEN_SIZES)
    for in_features, out_features in zip(sizes[:-1], sizes[1:], strict=True):
        layers += _linear_bn_relu(in_features, out_features)
    layers.append(nn.Linear(sizes[-1], output_dim))
    return nn.Sequential(*layers)


class GaussianEncoder(nn.Module):
    """VAE encoder, symmetric to the decoder: Lin(T*M,512)+BN+ReLU, Lin(512,256)+BN+ReLU, Lin(256,128)+BN+ReLU,
    then two Lin(128,Na) heads for the mean and the log standard deviation of ``q(alpha | tau)``.

    :param input_dim: ``T * M``
    :param latent_dim: ``N_alpha``
    """

    def __init__(self, input_dim: int, latent_dim: int) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        sizes = (input_dim, *reversed(DECODER_HIDDEN_SIZES))
        for in_features, out_features in zip(sizes[:-1], sizes[1:], strict=True):
            layers += _linear_bn_relu(in_features, out_features)
        self.trunk = nn.Sequential(*layers)
        self.mean = nn.Linear(sizes[-1], latent_dim)
        self.log_std = nn.Linear(sizes[-1], latent_dim)

    def forward(self, trajectories: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        features = self.trunk(trajectories)
        # The clamp only guards exp() against overflow early in training.
        return self.mean(features), self.log_std(features).clamp(-10.0, 5.0)


class DiscriminatorWithQ(nn.Module):
    """InfoGAN discriminator with the Q network sharing its first layers.

    Shared: Lin(T*M,256)+ReLU, Lin(256,128)+ReLU. Discriminator head: Lin(128,1) (+ Sigmoid, applied inside the
    binary cross-entropy for numerical stability, so :meth:`forward` returns a logit). Q head: Lin(128,64),
    Lin(64,Na), the mean of a unit-variance Gaussian ``Q(alpha | tau)``; as in the paper's table there is no
    non-linearity between the two Q layers.

    :param input_dim: ``T * M``
    :param latent_dim: ``N_alpha``
    """

    def __init__(self, input_dim: int, latent_dim: int) -> None:
        super().__init__()
        first, second = DISCRIMINATOR_HIDDEN_SIZES
        self.shared = nn.Sequential(nn.Linear(input_dim, first), nn.ReLU(), nn.Linear(first, second), nn.ReLU())
        self.discriminator = nn.Linear(second, 1)
        self.q_mean = nn.Sequential(nn.Linear(second, Q_HIDDEN_SIZE), nn.Linear(Q_HIDDEN_SIZE, latent_dim))

    def forward(self, trajectories: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Return ``(logit of D(tau), mean of Q(alpha | tau))``."""
        features = self.shared(trajectories)
        return self.discriminator(features).squeeze(-1), self.q_mean(features)
