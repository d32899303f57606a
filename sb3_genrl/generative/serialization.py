"""One-file storage of a generator: weights, configuration, normalisation statistics and package version.

The file is a :func:`torch.save` of a dictionary that holds only tensors and strings (the configuration and the
training history are JSON text), so it is read back with ``torch.load(weights_only=True)`` and never unpickles an
arbitrary object. The ``"format"`` entry marks it as ours.
"""

from __future__ import annotations

import json
import os
from typing import TYPE_CHECKING, Any

import torch

if TYPE_CHECKING:
    from sb3_genrl.generative.torch_generator import TorchTrajectoryGenerator

FORMAT_MARKER = "sb3_genrl.generative.TrajectoryGenerator"
FORMAT_VERSION = 1


def _generator_classes() -> dict[str, type[TorchTrajectoryGenerator]]:
    from sb3_genrl.generative.infogan import InfoGAN
    from sb3_genrl.generative.vae import BetaVAE

    return {"BetaVAE": BetaVAE, "InfoGAN": InfoGAN}


def save_generator(generator: TorchTrajectoryGenerator, path: str | os.PathLike[str]) -> None:
    """Write ``generator`` to ``path`` (parent folders are created)."""
    from sb3_genrl import __version__

    directory = os.path.dirname(os.fspath(path))
    if directory:
        os.makedirs(directory, exist_ok=True)
    payload = {
        "format": FORMAT_MARKER,
        "format_version": FORMAT_VERSION,
        "class": type(generator).__name__,
        "sb3_genrl_version": __version__,
        "config": json.dumps(generator.config()),
        "history": json.dumps({"history": generator.history, "best_epoch": generator.best_epoch, "seed": generator.seed}),
        "state": generator.state_tensors(),
    }
    torch.save(payload, os.fspath(path))


def _read_payload(path: str) -> dict[str, Any]:
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no generator file at {path!r}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises several types for foreign files (pickle, zip, runtime errors)
        raise ValueError(f"{path!r} is not a sb3-genrl generator file: torch.load could not read it "
                         f"({type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT_MARKER:
        raise ValueError(f"{path!r} is not a sb3-genrl generator file: it lacks the format marker {FORMAT_MARKER!r}")
    if payload.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{path!r} has generator file format version {payload.get('format_version')!r}; this "
                         f"version of sb3-genrl reads version {FORMAT_VERSION}")
    missing = {"class", "sb3_genrl_version", "config", "history", "state"} - set(payload)
    if missing:
        raise ValueError(f"{path!r} is a corrupt generator file: missing entries {sorted(missing)}")
    return payload


def load(path: str | os.PathLike[str], device: torch.device | str = "auto") -> TorchTrajectoryGenerator:
    """Restore a generator written by ``save``.

    :param path: file written by :meth:`TrajectoryGenerator.save`
    :param device: torch device or ``"auto"`` to place the networks on
    :return: the generator, in evaluation mode; ``saved_version`` holds the sb3-genrl version that wrote the file
    :raises ValueError: when the file is not a generator file or is corrupt (the message names the file)
    """
    path = os.fspath(path)
    payload = _read_payload(path)
    classes = _generator_classes()
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
    generator.saved_version = payload["sb3_genrl_version"]
    return generator
