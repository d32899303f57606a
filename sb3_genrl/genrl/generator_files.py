"""Where a GenRL model finds its generator: the file it was built from, else ``<name>.generator.pt`` saved beside the
model's zip (for a generator built in memory)."""

from __future__ import annotations

import hashlib
import io
import os
import pathlib
from typing import Any

import torch as th

from sb3_genrl.generative.base import TrajectoryGenerator


def generator_file(path: str | pathlib.Path) -> pathlib.Path:
    """``dir/model.zip`` -> ``dir/model.generator.pt``."""
    path = pathlib.Path(path)
    if path.suffix == ".zip":
        path = path.with_suffix("")
    return path.with_name(path.name + ".generator.pt")


def load_generator(path: str, device: th.device | str) -> TrajectoryGenerator:
    """The generator saved at ``path``, onto ``device`` (:func:`sb3_genrl.generative.load`)."""
    from sb3_genrl.generative import load  # imported lazily: the model classes are only needed here

    return load(path, device=device)


def save_generator_beside(generator: TrajectoryGenerator, model_path: pathlib.Path) -> None:
    """Save ``generator`` as :func:`generator_file` of ``model_path``, unless it cannot be saved (then loading the
    model needs the generator given)."""
    try:
        generator.save(str(generator_file(model_path)))
    except NotImplementedError:
        pass


def saved_generator(path: str | pathlib.Path | io.BufferedIOBase, data: dict[str, Any],
                    generator: TrajectoryGenerator | str | None, device: th.device | str,
                    ) -> tuple[TrajectoryGenerator | None, str | None]:
    """The generator of a model loaded from ``path`` whose saved ``data`` is given, and its file: ``generator`` when
    given (a file is loaded onto ``device``), else the file ``data`` names, else :func:`generator_file` of ``path``;
    ``(None, None)`` when there is none."""
    generator_path = os.path.abspath(generator) if isinstance(generator, str | os.PathLike) else None
    if generator is None:
        candidates = [data.get("generator_path")]
        candidates += [generator_file(path)] if isinstance(path, str | pathlib.Path) else []
        generator_path = next((str(p) for p in candidates if p is not None and os.path.isfile(p)), None)
    if generator_path is not None:
        generator = load_generator(generator_path, device)
    return generator, generator_path  # type: ignore[return-value]


def file_sha256(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's bytes (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_generator_file(path: str | os.PathLike, recorded: str | None, model: Any) -> None:
    """Refuse a generator file whose SHA-256 is not the one ``recorded`` by the model ``model`` (named in the error):
    the file was replaced (e.g. by another ``train-generator`` run) since the policy was trained on it. A model saved
    without a record (an older version) is not checked."""
    if recorded is not None and (actual := file_sha256(path)) != recorded:
        raise ValueError(f"the generator file {os.fspath(path)!r} is not the one {model} was trained with: its SHA-256 is "
                         f"{actual[:16]}..., the policy recorded {recorded[:16]}... (the file was replaced since); pass the "
                         "generator it was trained with")
