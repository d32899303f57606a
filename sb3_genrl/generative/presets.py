"""The paper's model grid (VAE1-9, GAN1-9, paper table 1) and the task recipes, by name, and the generators they build."""

from __future__ import annotations

from itertools import product
from typing import Any

import torch

from sb3_genrl.generative.defaults import BETAS, INFO_WEIGHTS, LATENT_DIMS, MODEL_KINDS
from sb3_genrl.generative.infogan import InfoGAN
from sb3_genrl.generative.torch_generator import TorchTrajectoryGenerator
from sb3_genrl.generative.vae import BetaVAE


def _grid() -> dict[str, dict[str, Any]]:
    # Table 1 lists the grid with N_alpha as the outer and beta / lambda as the inner loop.
    presets: dict[str, dict[str, Any]] = {}
    for index, (latent_dim, beta) in enumerate(product(LATENT_DIMS, BETAS), start=1):
        presets[f"VAE{index}"] = {"model": "vae", "latent_dim": latent_dim, "beta": beta}
    for index, (latent_dim, info_weight) in enumerate(product(LATENT_DIMS, INFO_WEIGHTS), start=1):
        presets[f"GAN{index}"] = {"model": "gan", "latent_dim": latent_dim, "info_weight": info_weight}
    return presets


PRESETS: dict[str, dict[str, Any]] = _grid()
# Recipes beyond the paper's grid, for a task family (TaskSpec.generator_preset), accepted wherever a preset name is.
# VAE-FETCH, Gymnasium-Robotics' Fetch tasks: VAE9's beta with 10 latent dimensions; a Fetch trajectory depends on
# the object's start, the aim and the demonstration's smooth bumps, and 10 dimensions reproduce demonstrations it was
# not trained on more closely than VAE9's 6, and the error of the end-effector's path (the running sum of its moves,
# BetaVAE's path_weight) weighed with the per-step error lets its reconstructions reach their aims far more often;
# its weight is the one whose mean fitted to the demonstrations solves the most tuning states over the four tasks
# (all measured in docs/guide/tasks.md).
# The class of each model kind.
GENERATOR_KINDS: dict[str, type[TorchTrajectoryGenerator]] = {"vae": BetaVAE, "gan": InfoGAN}
TASK_PRESETS: dict[str, dict[str, Any]] = {"VAE-FETCH": {"model": "vae", "latent_dim": 10, "beta": 0.001, "path_weight": 1.0}}


def resolve_generator_spec(
    preset_or_kind: str, *, latent_dim: int | None = None, beta: float | None = None, info_weight: float | None = None
) -> dict[str, Any]:
    """Model kind and hyperparameters from a preset name (``"VAE1"``..``"GAN9"``, or one of :data:`TASK_PRESETS`) or a
    kind (``"vae"``, ``"gan"``).

    Explicit values must agree with a preset's; for a kind, ``latent_dim`` and ``beta`` (VAE) or ``info_weight``
    (GAN) are required.
    """
    explicit = {"latent_dim": latent_dim, "beta": beta, "info_weight": info_weight}
    presets = PRESETS | TASK_PRESETS
    if preset_or_kind.upper() in presets:
        spec = dict(presets[preset_or_kind.upper()])
        for name, value in explicit.items():
            if value is not None and spec.get(name, value) != value:
                raise ValueError(f"preset {preset_or_kind.upper()} has {name}={spec[name]}, got {name}={value}")
            if value is not None and name not in spec:
                raise ValueError(f"preset {preset_or_kind.upper()} is a {spec['model']} model, which takes no {name}")
        return spec
    kind = preset_or_kind.lower()
    if kind not in MODEL_KINDS:
        raise ValueError(f"unknown generator {preset_or_kind!r}; expected one of {MODEL_KINDS} or a preset {list(PRESETS)}")
    weight_name, unused_name = ("beta", "info_weight") if kind == "vae" else ("info_weight", "beta")
    if explicit[unused_name] is not None:
        raise ValueError(f"a {kind} model takes no {unused_name}")
    for name in ("latent_dim", weight_name):
        if explicit[name] is None:
            raise ValueError(f"a {kind} model needs {name} (or use a preset such as {'VAE1' if kind == 'vae' else 'GAN1'})")
    return {"model": kind, "latent_dim": latent_dim, weight_name: explicit[weight_name]}


def make_generator(
    preset_or_kind: str,
    *,
    horizon: int,
    action_dim: int,
    latent_dim: int | None = None,
    beta: float | None = None,
    info_weight: float | None = None,
    std_floor: float | None = None,
    device: torch.device | str = "auto",
) -> TorchTrajectoryGenerator:
    """Build an untrained generator from a preset of paper table 1 or a model kind.

    :param preset_or_kind: ``"VAE1"``..``"VAE9"``, ``"GAN1"``..``"GAN9"``, ``"vae"`` or ``"gan"``
    :param horizon: number of time steps ``T`` (the task's horizon; paper: 69 for hockey, 78 for basketball)
    :param action_dim: number of joints ``M`` (paper: 7)
    :param latent_dim: ``N_alpha``; required for a kind, must match a preset
    :param beta: KL weight of a VAE; required for ``"vae"``, must match a preset
    :param info_weight: ``lambda`` of an InfoGAN; required for ``"gan"``, must match a preset
    :param std_floor: floor of each normalisation std as a fraction of the largest (``None``: the model's default)
    :param device: torch device or ``"auto"``
    """
    spec = resolve_generator_spec(preset_or_kind, latent_dim=latent_dim, beta=beta, info_weight=info_weight)
    extra = {} if std_floor is None else {"std_floor": std_floor}
    if spec["model"] == "vae":
        extra |= {"path_weight": spec["path_weight"]} if "path_weight" in spec else {}
        return BetaVAE(horizon, action_dim, spec["latent_dim"], beta=spec["beta"], device=device, **extra)
    return InfoGAN(horizon, action_dim, spec["latent_dim"], info_weight=spec["info_weight"], device=device, **extra)
