"""Generative models of motor trajectories (paper section 5.1, appendix B)."""

from sb3_genrl.generative.base import Prior, TrajectoryGenerator
from sb3_genrl.generative.infogan import InfoGAN
from sb3_genrl.generative.presets import PRESETS, make_generator
from sb3_genrl.generative.serialization import load
from sb3_genrl.generative.torch_generator import TorchTrajectoryGenerator
from sb3_genrl.generative.training import load_trajectories, train_generator
from sb3_genrl.generative.vae import BetaVAE

__all__ = [
    "PRESETS",
    "BetaVAE",
    "InfoGAN",
    "Prior",
    "TorchTrajectoryGenerator",
    "TrajectoryGenerator",
    "load",
    "load_trajectories",
    "make_generator",
    "train_generator",
]
