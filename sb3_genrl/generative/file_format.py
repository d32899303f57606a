"""The generator file format: weights, configuration, normalisation statistics and package version in one file.

The file is a :func:`torch.save` of a dictionary that holds only tensors and strings (the configuration and the
training history are JSON text), so it is read back with ``torch.load(weights_only=True)`` and never unpickles an
arbitrary object. The ``"format"`` entry marks it as ours; the ``"sha256"`` entry is a SHA-256 digest of everything
else (weights, normalisation statistics, configuration, history), checked on load, so a damaged file is refused
instead of decoding wrong trajectories. The file is written atomically (:func:`sb3_genrl.utils.atomic_path`).
"""

from __future__ import annotations

import hashlib
import json
import os
from typing import TYPE_CHECKING, Any

import torch

from sb3_genrl.utils import atomic_path
from sb3_genrl.version import __version__

if TYPE_CHECKING:
    from sb3_genrl.generative.torch_generator import TorchTrajectoryGenerator

FORMAT_MARKER = "sb3_genrl.generative.TrajectoryGenerator"
FORMAT_VERSION = 2  # 2: with the "sha256" digest
_TEXT_ENTRIES = ("format", "class", "sb3_genrl_version", "config", "history")


def payload_digest(payload: dict[str, Any]) -> str:
    """SHA-256 hex digest of a generator file's entries other than ``"sha256"``: the text entries and, in name
    order, each state tensor's name, dtype, shape and bytes."""
    digest = hashlib.sha256(f"format_version={payload['format_version']}".encode())
    for key in _TEXT_ENTRIES:
        digest.update(f"\0{key}={payload[key]}".encode())
    for name in sorted(payload["state"]):
        tensor = payload["state"][name].detach().cpu().contiguous()
        digest.update(f"\0{name}:{tensor.dtype}:{tuple(tensor.shape)}:".encode())
        digest.update(tensor.reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def check_savable(generator: TorchTrajectoryGenerator, path: str) -> None:
    """Raise a ``ValueError`` saying why, when ``generator`` is not worth saving: training ran but selected no
    checkpoint (every model-selection error was nan), or a weight or normalisation statistic is not finite."""
    if generator.history and generator.best_epoch is None:
        raise ValueError(
            f"refusing to save the generator to {path!r}: training diverged, no checkpoint was selected "
            "(every model-selection MSE was nan); lower the learning rate or the loss weights"
        )
    bad = [
        name
        for name, tensor in generator.state_tensors().items()
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all())
    ]
    if bad:
        raise ValueError(
            f"refusing to save the generator to {path!r}: training diverged, these tensors hold "
            f"non-finite values (nan or inf): {bad[:5]}{' ...' if len(bad) > 5 else ''}; lower the "
            "learning rate or the loss weights"
        )


def save_generator(generator: TorchTrajectoryGenerator, path: str | os.PathLike[str]) -> None:
    """Write ``generator`` to ``path`` atomically (parent folders are created), with a digest of its content.

    :raises ValueError: when training diverged (see :func:`check_savable`); nothing is written then
    """
    check_savable(generator, os.fspath(path))
    payload: dict[str, Any] = {
        "format": FORMAT_MARKER,
        "format_version": FORMAT_VERSION,
        "class": type(generator).__name__,
        "sb3_genrl_version": __version__,
        "config": json.dumps(generator.config()),
        "history": json.dumps(
            {
                "history": generator.history,
                "best_epoch": generator.best_epoch,
                "seed": generator.seed,
                "selection": generator.selection,
            }
        ),
        "state": generator.state_tensors(),
    }
    payload["sha256"] = payload_digest(payload)
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def read_payload(path: str) -> dict[str, Any]:
    """The checked entries of the generator file at ``path``; a ``ValueError`` naming it when it is not one or is corrupt."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no generator file at {path!r}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises several types for foreign files (pickle, zip, runtime errors)
        raise ValueError(
            f"{path!r} is not a sb3-genrl generator file: torch.load could not read it "
            f"({type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT_MARKER:
        raise ValueError(f"{path!r} is not a sb3-genrl generator file: it lacks the format marker {FORMAT_MARKER!r}")
    if payload.get("format_version") == 1:
        raise ValueError(
            f"{path!r} predates checksums (generator file format version 1, written by sb3-genrl "
            f"{payload.get('sb3_genrl_version')}): its weights cannot be verified; train the generator "
            "again with this version"
        )
    if payload.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{path!r} has generator file format version {payload.get('format_version')!r}; this "
            f"version of sb3-genrl reads version {FORMAT_VERSION}"
        )
    missing = {*_TEXT_ENTRIES, "sha256", "state"} - set(payload)
    if missing:
        raise ValueError(f"{path!r} is a corrupt generator file: missing entries {sorted(missing)}")
    if not isinstance(payload["state"], dict) or not all(isinstance(v, torch.Tensor) for v in payload["state"].values()):
        raise ValueError(f"{path!r} is a corrupt generator file: its state is not a dictionary of tensors")
    if payload["sha256"] != payload_digest(payload):
        raise ValueError(
            f"{path!r} is corrupt: the checksum (SHA-256) of its weights, normalisation statistics and "
            "configuration does not match the one stored when it was saved"
        )
    return payload
