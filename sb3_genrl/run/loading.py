"""Load a saved GenRL policy without unpickling anything from the file.

An SB3 model zip stores the objects that JSON cannot hold (the policy class, the spaces, the policy's keyword
arguments, buffers) as cloudpickle payloads, and SB3's ``load`` unpickles them: a zip from an untrusted source can
run arbitrary code. The weights themselves are read with ``torch.load(weights_only=True)``, which is safe.

:func:`load_policy` gives SB3 a replacement for every pickled entry (``custom_objects``), so none is unpickled:
the spaces are rebuilt from the env and the generator, the policy class and its keyword arguments from their
readable description in the zip and an allow-list of classes, and what only training needs (buffers, schedules)
is left empty and rebuilt by SB3. A zip that holds anything else is refused unless ``trust=True``.
"""

from __future__ import annotations

import base64
import binascii
import json
import os
import pickletools
import zipfile
from typing import Any

import gymnasium as gym
import torch as th
from stable_baselines3.common.torch_layers import CombinedExtractor, FlattenExtractor

from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl.generator_files import check_model_data, check_recorded_generator, generator_file, load_generator
from sb3_genrl.genrl.genrl import GenRL
from sb3_genrl.genrl.policies import BoxScaler, ContextStdPolicy, MlpPolicy, MultiInputPolicy
from sb3_genrl.wrappers import LatentActionWrapper

# What a prediction does not need: SB3 rebuilds it (schedules, buffer classes) or leaves it empty until learn().
_LEFT_EMPTY = (
    "lr_schedule",
    "clip_range",
    "clip_range_vf",
    "rollout_buffer_class",
    "_last_obs",
    "_last_episode_starts",
    "_last_original_obs",
    "ep_info_buffer",
    "ep_success_buffer",
)
# Classes a policy's keyword arguments may name, by the text SB3 writes for them beside the pickle.
_ALLOWED_CLASSES = {
    str(cls): cls
    for cls in (
        BoxScaler,
        FlattenExtractor,
        CombinedExtractor,
        th.nn.Tanh,
        th.nn.ReLU,
        th.nn.ELU,
        th.nn.LeakyReLU,
        th.nn.GELU,
        th.nn.SiLU,
        th.optim.Adam,
        th.optim.AdamW,
        th.optim.SGD,
        th.optim.RMSprop,
    )
}
_POLICIES = {f"{cls.__module__}.{cls.__qualname__}": cls for cls in (MlpPolicy, MultiInputPolicy, ContextStdPolicy)}
# The pickle opcodes of a reference to a class by its module and name, and nothing else
_REFERENCE_OPCODES = {
    "PROTO",
    "FRAME",
    "SHORT_BINUNICODE",
    "BINUNICODE",
    "UNICODE",
    "MEMOIZE",
    "BINPUT",
    "LONG_BINPUT",
    "PUT",
    "STACK_GLOBAL",
    "GLOBAL",
    "STOP",
}


def load_policy(
    path: str | os.PathLike,
    env: gym.Env,
    *,
    generator: TrajectoryGenerator | str | None = None,
    device: th.device | str = "cpu",
    trust: bool = False,
) -> GenRL:
    """Load a GenRL model zip for ``env``'s task, unpickling nothing from the zip unless ``trust`` is set.

    :param path: the ``.zip`` written by :meth:`GenRL.save <sb3_genrl.GenRL.save>`
    :param env: the task env the policy was trained on (not wrapped in :class:`~sb3_genrl.LatentActionWrapper`)
    :param generator: the generator (or its file); default: the one the zip names, else the file saved beside it
    :param device: torch device
    :param trust: load the zip as SB3 does, unpickling its objects (only for files from a trusted source)
    :return: the model, with its generator
    """
    path = os.fspath(path)
    data = _read_data(path)
    check_model_data(path, data)  # another algorithm's zip: said first, before its generator or its pickles
    generator = _resolve_generator(path, data, generator, device)
    if trust:
        return GenRL.load(path, device=device, generator=generator)
    latent_env = LatentActionWrapper(env, generator, latent_clip=data.get("latent_clip", 3.0))
    custom_objects = {"observation_space": latent_env.observation_space, "action_space": latent_env.action_space}
    for key, entry in data.items():
        if not (isinstance(entry, dict) and ":serialized:" in entry) or key in custom_objects:
            continue
        if key in _LEFT_EMPTY:
            custom_objects[key] = None
        elif key == "policy_class":
            custom_objects[key] = _policy_class(entry, path)
        elif key == "policy_kwargs":
            custom_objects[key] = {
                name: _allowed_value(value, name, path) for name, value in entry.items() if not name.startswith(":")
            }
        else:
            raise ValueError(
                f"{path} holds a pickled {key!r}, which cannot be loaded without unpickling it; load it "
                "with trust=True (genrl video --trust-policy) only if you trust the file's source"
            )
    _check_space(data, "observation_space", latent_env.observation_space, path)
    _check_space(data, "action_space", latent_env.action_space, path)
    return GenRL.load(path, device=device, custom_objects=custom_objects, generator=generator)


def _read_data(path: str) -> dict[str, Any]:
    """The zip's ``data`` entry as JSON (the pickled objects stay base64 text)."""
    try:
        with zipfile.ZipFile(path) as archive:
            return json.loads(archive.read("data"))
    except (FileNotFoundError, IsADirectoryError):
        raise
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{path} is not an SB3 model zip ({error})") from None


def _resolve_generator(
    path: str, data: dict[str, Any], generator: TrajectoryGenerator | str | None, device: th.device | str
) -> TrajectoryGenerator:
    """The given generator, else the file the zip names, else ``<name>.generator.pt`` beside the zip, onto ``device``;
    refused when it is not the one the policy was trained with."""
    if isinstance(generator, TrajectoryGenerator):
        return generator
    candidates = [generator] if generator is not None else [data.get("generator_path"), generator_file(path)]
    for candidate in candidates:
        if isinstance(candidate, str | os.PathLike) and os.path.isfile(candidate):
            generator = load_generator(os.fspath(candidate), device)
            check_recorded_generator(generator, data.get("generator_sha256"), candidate, path)  # the file named here
            return generator
    raise ValueError(
        f"no generator for {path}: none of {[str(c) for c in candidates if c is not None]} exists; pass the generator "
        f"file (generator=...), or copy it beside the zip as {generator_file(path)} (genrl video reads it there)"
    )


def _policy_class(entry: dict[str, Any], path: str) -> type:
    """The allowed policy class that the pickled class reference names, read without unpickling it."""
    name = _class_reference(entry.get(":serialized:"))
    if name not in _POLICIES:
        raise ValueError(
            f"{path} uses a policy class ({name or 'not a plain class reference'}) that cannot be loaded "
            "without unpickling it; use trust=True only if you trust the file's source"
        )
    return _POLICIES[name]


def _class_reference(serialized: Any) -> str | None:
    """``module.name`` when ``serialized`` (base64 pickle) only references a class by name, else None.

    The opcodes are read with :func:`pickletools.genops`, which parses and runs nothing.
    """
    try:
        operations = list(pickletools.genops(base64.b64decode(str(serialized), validate=True)))
    except (binascii.Error, ValueError):
        return None
    if any(opcode.name not in _REFERENCE_OPCODES for opcode, _, _ in operations):
        return None
    strings = [str(argument) for opcode, argument, _ in operations if "UNICODE" in opcode.name or opcode.name == "GLOBAL"]
    globals_ = [opcode.name for opcode, _, _ in operations if opcode.name in ("STACK_GLOBAL", "GLOBAL")]
    if globals_ == ["STACK_GLOBAL"] and len(strings) == 2:
        return ".".join(strings)
    if globals_ == ["GLOBAL"] and len(strings) == 1:
        return ".".join(strings[0].split(" ", 1))
    return None


def _allowed_value(value: Any, name: str, path: str) -> Any:
    """A policy keyword argument: JSON values as they are, classes from the allow-list."""
    if isinstance(value, str) and value.startswith("<class "):
        if value not in _ALLOWED_CLASSES:
            raise ValueError(
                f"{path}: policy_kwargs[{name!r}] is {value}, which is not among the classes loaded without "
                "unpickling; use trust=True only if you trust the file's source"
            )
        return _ALLOWED_CLASSES[value]
    if isinstance(value, str) and value.startswith("<"):
        raise ValueError(f"{path}: policy_kwargs[{name!r}] ({value}) cannot be loaded without unpickling it")
    return value


def _check_space(data: dict[str, Any], key: str, space: gym.spaces.Space, path: str) -> None:
    """The saved space's shape and dtype (readable beside the pickle) must be those rebuilt from the env."""
    entry = data.get(key)
    if not isinstance(entry, dict):
        raise ValueError(f"{path} has no {key}")
    saved = (tuple(entry.get("_shape") or ()), entry.get("dtype"))
    if saved != (space.shape, str(space.dtype)):
        raise ValueError(
            f"{path} was trained with {key} of shape and dtype {saved}, not {(space.shape, str(space.dtype))}"
            ": another task or generator"
        )
