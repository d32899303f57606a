"""Train a generator from an array or a demonstration dataset (what ``genrl train-generator`` calls)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch

from sb3_genrl.checks import (
    check_device,
    check_int,
    check_not_in_input,
    check_output_file,
    check_positive_float,
    check_positive_int,
    check_seed,
)
from sb3_genrl.data import load_trajectories
from sb3_genrl.generative.defaults import BATCH_SIZE, EPOCHS, LEARNING_RATE, SELECTION_SAMPLES
from sb3_genrl.generative.presets import GENERATOR_KINDS, PRESETS, TASK_PRESETS, make_generator
from sb3_genrl.generative.torch_generator import TorchTrajectoryGenerator, check_selection


def train_generator(
    data: np.ndarray | str | os.PathLike[str],
    *,
    model: str | None = None,
    preset: str | None = None,
    latent_dim: int | None = None,
    beta: float | None = None,
    info_weight: float | None = None,
    std_floor: float | None = None,
    epochs: int = EPOCHS,
    batch_size: int = BATCH_SIZE,
    lr: float = LEARNING_RATE,
    seed: int | None = 0,
    validation_fraction: float = 0.1,
    eval_every: int = 10,
    selection_samples: int = SELECTION_SAMPLES,
    selection: str = "prior",
    min_steps: int = 0,
    even_batches: bool = False,
    out: str | os.PathLike[str] | None = None,
    tensorboard_log: str | None = None,
    progress_bar: bool = False,
    device: torch.device | str = "auto",
) -> TorchTrajectoryGenerator:
    """Build a generator (by preset or kind), fit it on trajectories and optionally save it.

    The horizon and number of joints are read from the data.

    :param data: ``(N, T, M)`` array, ``.npy`` / ``.npz`` file, or Minari dataset directory
    :param model: ``"vae"`` or ``"gan"`` (default ``"vae"`` when no preset is given)
    :param preset: ``"VAE1"``..``"GAN9"`` of paper table 1; explicit hyperparameters must agree with it
    :param latent_dim: ``N_alpha``
    :param beta: KL weight (VAE)
    :param info_weight: ``lambda`` (InfoGAN)
    :param std_floor: floor of each normalisation std as a fraction of the largest (``None``: the model's default,
        :data:`~sb3_genrl.generative.common.STD_FLOOR`)
    :param epochs: training epochs (paper: 5000)
    :param batch_size: minibatch size (paper: 256)
    :param lr: Adam learning rate (paper: 2e-4)
    :param seed: training seed
    :param validation_fraction: held-out fraction for model selection
    :param eval_every: epochs between model-selection evaluations
    :param selection_samples: generated trajectories per evaluation (paper: 100)
    :param selection: how the checkpoint is chosen (:data:`~sb3_genrl.generative.torch_generator.SELECTIONS`):
        ``"prior"``, paper appendix B's (generated trajectories against their nearest held-out ones), or
        ``"reconstruction"`` (a VAE: the held-out trajectories decoded from their posterior means)
    :param min_steps: at least this many minibatch steps: on a small dataset the epochs are raised until they are
        reached (default 0: ``epochs`` as given)
    :param even_batches: minibatches of nearly equal sizes (at most ``batch_size``) instead of full ones and a
        remainder (see :meth:`~sb3_genrl.generative.torch_generator.TorchTrajectoryGenerator.fit`)
    :param out: file to save the trained generator to (``None``: not saved)
    :param tensorboard_log: TensorBoard log directory
    :param progress_bar: show a progress bar
    :param device: torch device or ``"auto"``
    :return: the trained generator
    """
    for name, value in (
        ("epochs", epochs),
        ("batch_size", batch_size),
        ("eval_every", eval_every),
        ("selection_samples", selection_samples),
    ):
        check_positive_int(value, name)
    check_positive_float(lr, "lr")
    check_int(min_steps, "min_steps", minimum=0)
    check_device(device)
    if seed is not None:
        check_seed(seed)
    if out is not None:
        check_output_file(out, "out")
        check_not_in_input(out, data, "out", "writing the generator there would overwrite its training data")
    if preset is not None:
        spec: dict[str, Any] = {"preset_or_kind": preset}
        preset_model = (PRESETS | TASK_PRESETS).get(preset.upper(), {}).get("model")
        if model is not None and preset_model is not None and model.lower() != preset_model:
            raise ValueError(f"preset {preset} is a {preset_model} model, got model={model!r}")
        kind = preset_model or model
    else:
        spec = {"preset_or_kind": model or "vae"}
        kind = model or "vae"
    if kind is not None and kind.lower() in GENERATOR_KINDS:
        check_selection(GENERATOR_KINDS[kind.lower()], selection)
    trajectories = load_trajectories(data)
    generator = make_generator(
        **spec,
        horizon=trajectories.shape[1],
        action_dim=trajectories.shape[2],
        latent_dim=latent_dim,
        beta=beta,
        info_weight=info_weight,
        std_floor=std_floor,
        device=device,
    )
    generator.fit(
        trajectories,
        epochs=epochs,
        batch_size=batch_size,
        lr=lr,
        seed=seed,
        validation_fraction=validation_fraction,
        tensorboard_log=tensorboard_log,
        progress_bar=progress_bar,
        device=device,
        selection_samples=selection_samples,
        eval_every=eval_every,
        selection=selection,
        min_steps=min_steps,
        even_batches=even_batches,
    )
    if out is not None:
        generator.save(os.fspath(out))
    return generator
