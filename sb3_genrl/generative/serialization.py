"""Loading a generator file (:mod:`~sb3_genrl.generative.file_format`) back into its model class."""

from __future__ import annotations

import json
import os

import torch

from sb3_genrl.generative.file_format import read_payload
from sb3_genrl.generative.infogan import InfoGAN
from sb3_genrl.generative.torch_generator import TorchTrajectoryGenerator
from sb3_genrl.generative.vae import BetaVAE

GENERATOR_CLASSES: dict[str, type[TorchTrajectoryGenerator]] = {"BetaVAE": BetaVAE, "InfoGAN": InfoGAN}


def load(path: str | os.PathLike[str], device: torch.device | str = "auto") -> TorchTrajectoryGenerator:
    """Restore a generator written by ``save``.

    :param path: file written by :meth:`TrajectoryGenerator.save`
    :param device: torch device or ``"auto"`` to place the networks on
    :return: the generator, in evaluation mode; ``saved_version`` holds the sb3-genrl version that wrote the file
    :raises ValueError: when the file is not a generator file or is corrupt (the message names the file)
    """
    path = os.fspath(path)
    payload = read_payload(path)
    classes = GENERATOR_CLASSES
    if payload["class"] not in classes:
        raise ValueError(f"{path!r} holds an unknown generator class {payload['class']!r}; known: {sorted(classes)}")
    try:
        config = json.loads(payload["config"])
        extra = json.loads(payload["history"])
        generator = classes[payload["class"]](**config, device=device)
        generator.load_state_tensors(payload["state"])
    except (TypeError, ValueError, json.JSONDecodeError) as error:
        raise ValueError(f"{path!r} is a corrupt generator file: {error}") from None
    generator.history = extra.get("history", [])
    generator.best_epoch = extra.get("best_epoch")
    generator.seed = extra.get("seed")
    generator.selection = extra.get("selection", "prior")  # a file written before the choice existed: the paper's
    generator.saved_version = payload["sb3_genrl_version"]
    return generator
