"""Checks of arguments and output paths, shared by the library functions and the ``genrl`` command line.

Library functions call these first, before any simulation or training, so that a bad value fails at once with a
``ValueError`` that names the argument and what was expected. The command line uses the same checks as argparse
types (:func:`option`), so its messages name the option (``genrl demos: error: argument --seed: ...``).
"""

from __future__ import annotations

import argparse
import json
import math
import numbers
import os
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import torch

T = TypeVar("T")

MAX_SEED = 2**32 - 1  # NumPy's legacy seeding (used by SB3's set_random_seed) takes seeds below 2**32
MAX_EPISODES = 10**8  # a budget of episodes beyond this is a typo (a paper-scale run plays some thousands)
MAX_VIDEO_EPISODES = 100  # episodes one video shows (each is rendered frame by frame and held in memory)


class SettingError(ValueError, AssertionError):
    """A bad setting: a ``ValueError`` as sb3-genrl raises them, and an ``AssertionError`` as SB3 and sb3-contrib raise
    for the same setting (``n_steps * n_envs == 1`` with advantage normalisation), so code written for either
    convention catches it."""


def _named(name: str, text: str) -> str:
    return f"{name} {text}" if name else text


def is_finite_number(value: Any) -> bool:
    """Whether ``value`` is a finite real number (not a bool, a string, NaN or an infinity)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def is_whole_number(value: Any) -> bool:
    """Whether ``value`` is a finite whole number: an integer, or a float such as 30.0."""
    return is_finite_number(value) and int(value) == value


def check_int(value: Any, name: str, *, minimum: int = 1, maximum: int | None = None) -> int:
    """An integer within ``[minimum, maximum]``: Python and NumPy integers pass, ``bool``, floats and strings do not.

    :param value: the value to check
    :param name: the argument's name, for the error message
    :param minimum: the smallest value allowed
    :param maximum: the largest value allowed (``None``: no bound)
    :return: ``value`` as an ``int``
    """
    bound = f"between {minimum} and {maximum}" if maximum is not None else f">= {minimum}"
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(_named(name, f"must be an integer {bound}, got {value!r} ({type(value).__name__})"))
    if value < minimum or (maximum is not None and value > maximum):
        raise ValueError(_named(name, f"must be an integer {bound}, got {value!r}"))
    return int(value)


def check_positive_int(value: Any, name: str) -> int:
    """An integer >= 1 (see :func:`check_int`)."""
    return check_int(value, name, minimum=1)


def check_seed(value: Any, name: str = "seed") -> int:
    """A seed: an integer between 0 and 2**32 - 1 (what NumPy, torch and SB3 all accept)."""
    return check_int(value, name, minimum=0, maximum=MAX_SEED)


def sub_seed(seed: int, key: int) -> int:
    """A seed for the sub-stream ``key`` of a run seeded with ``seed``, within :func:`check_seed`'s range.

    ``seed + key`` while that is in range (the derivation the committed results were made with), else a seed drawn
    from ``np.random.SeedSequence(seed, spawn_key=(key,))``: addition past ``2**32 - 1`` made a valid ``--seed`` fail
    partway through a run.

    :param seed: the run's seed (0 to ``2**32 - 1``)
    :param key: which sub-stream (a non-negative integer: an offset, a count of episodes)
    """
    check_seed(seed)
    check_int(key, "key", minimum=0)
    if seed + key <= MAX_SEED:
        return int(seed + key)
    return int(np.random.SeedSequence(seed, spawn_key=(key,)).generate_state(1)[0])


def check_positive_float(value: Any, name: str) -> float:
    """A finite number > 0 (a learning rate, a weight)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value <= 0:
        raise ValueError(_named(name, f"must be a finite number > 0, got {value!r}"))
    return float(value)


def check_non_negative_float(value: Any, name: str) -> float:
    """A finite number >= 0 (a loss weight that may switch its term off)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
        raise ValueError(_named(name, f"must be a finite number >= 0, got {value!r}"))
    return float(value)


def check_fraction(value: Any, name: str) -> float:
    """A number in [0, 1] (a share, a threshold on a share)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 <= value <= 1:
        raise ValueError(_named(name, f"must be a number in [0, 1], got {value!r}"))
    return float(value)


def check_device(device: Any, name: str = "device") -> Any:
    """``"auto"``, or a torch device (``"cpu"``, ``"cuda"``, ``"cuda:1"``, ``"mps"``, a ``torch.device``) that exists
    on this machine. Unlike SB3, which quietly falls back to the CPU, an unavailable GPU is an error here.

    :param device: the device
    :param name: the argument's name, for the error message
    :return: ``device`` unchanged
    """
    if isinstance(device, str) and device == "auto":
        return device

    try:
        parsed = torch.device(device)
    except (RuntimeError, TypeError, ValueError):
        raise ValueError(
            _named(name, f"must be 'auto' or a torch device such as 'cpu', 'cuda' or 'cuda:0', got {device!r}")
        ) from None
    if parsed.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if (parsed.index or 0) >= count:
            raise ValueError(
                _named(name, f"{device!r} is not available: this machine has {count} CUDA device(s); use 'cpu' or 'auto'")
            )
    elif parsed.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(_named(name, f"{device!r} is not available on this machine; use 'cpu' or 'auto'"))
    elif parsed.type not in ("cpu", "cuda", "mps"):
        raise ValueError(_named(name, f"must be 'auto', 'cpu', 'cuda[:N]' or 'mps', got {device!r}"))
    return device


def check_input_path(path: str | os.PathLike[str], name: str) -> Path:
    """A file or folder that exists.

    :param path: the path
    :param name: the argument's name, for the error message
    """
    if not os.fspath(path):  # Path("") is the current folder
        raise ValueError(_named(name, "is empty; expected a path"))
    path = Path(path)
    if not path.exists():
        raise ValueError(_named(name, f"{str(path)!r} does not exist"))
    return path


def check_not_in_input(out: str | os.PathLike[str], data: Any, out_name: str, what: str) -> None:
    """Refuse an output ``out`` that is the input ``data`` (a file or a dataset folder) or lies inside its folder:
    writing there would overwrite or change the input.

    :param out: the output file or folder
    :param data: the input: a path (anything else, an array in memory, is not checked)
    :param out_name: the output's argument name, for the message
    :param what: what writing there would do, for the message
    """
    if not isinstance(data, str | os.PathLike):
        return
    data_path, out_path = Path(data).resolve(), Path(out).resolve()
    if out_path == data_path or (data_path.is_dir() and data_path in out_path.parents):
        where = "inside the dataset" if out_path != data_path else "the dataset" if data_path.is_dir() else "the data file"
        raise ValueError(f"{out_name} {os.fspath(out)!r} is {where} {os.fspath(data)!r}: {what}; choose another path")


def check_not_in_a_dataset(out: str | os.PathLike[str], name: str = "out") -> None:
    """Refuse an output folder that is a demonstration dataset (a folder with ``data/metadata.json``) or lies in one:
    the output's files would join the dataset's own."""
    path = Path(out).resolve()
    for folder in (path, *path.parents):
        if (folder / "data" / "metadata.json").is_file():
            where = "the demonstration dataset" if folder == path else f"inside the demonstration dataset {str(folder)!r}"
            raise ValueError(_named(name, f"{os.fspath(out)!r} is {where}: its files would join the dataset's own"))


def check_output_dir(path: str | os.PathLike[str], name: str = "out_dir", *, empty: bool = False) -> Path:
    """A folder that can be created (or exists) and written to, checked without creating it.

    :param path: the folder
    :param name: the argument's name, for the error message
    :param empty: also require that it does not exist yet or is empty
    :return: the folder
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(_named(name, f"{str(path)!r} is a file; expected a folder"))
    if empty and path.is_dir() and any(path.iterdir()):
        raise ValueError(_named(name, f"{str(path)!r} already exists and is not empty; choose another folder"))
    _check_writable(path, name)
    return path


def check_output_file(path: str | os.PathLike[str], name: str = "out", *, suffixes: Sequence[str] = ()) -> Path:
    """A file that can be written: not a folder, in a folder that can be created and written to.

    :param path: the file
    :param name: the argument's name, for the error message
    :param suffixes: the allowed suffixes, lower case with the dot (empty: any)
    :return: the file
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(_named(name, f"{str(path)!r} is a folder; expected a file name"))
    if suffixes and path.suffix.lower() not in suffixes:
        raise ValueError(_named(name, f"{str(path)!r} must end in {' or '.join(suffixes)}"))
    _check_writable(path.parent, name, target=path)
    return path


def _check_writable(folder: Path, name: str, target: Path | None = None) -> None:
    """Try to create (and remove) a file in the nearest existing ancestor of ``folder``: the permission bits do not
    tell (``root`` passes ``os.access`` on read-only file systems)."""
    target = target or folder
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(_named(name, f"{str(target)!r} cannot be created: {str(existing)!r} is a file"))
    try:
        handle, probe = tempfile.mkstemp(dir=existing, prefix=".genrl-write-check-")
    except OSError as error:
        raise ValueError(
            _named(name, f"{str(target)!r} cannot be written: {str(existing)!r} is not writable ({error.strerror})")
        ) from None
    os.close(handle)
    os.unlink(probe)


def option(check: Callable[..., T], parse: Callable[[str], Any] = str, **kwargs: Any) -> Callable[[str], T]:
    """An argparse ``type`` that parses the text with ``parse`` and checks it with ``check(value, "", **kwargs)``.

    :param check: one of the checks above
    :param parse: turns the command-line text into a value (``int``, ``float``, ``str``)
    :param kwargs: further arguments of ``check``
    """

    def convert(text: str) -> T:
        try:
            value = parse(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if parse is int else 'a number'}, got {text!r}"
            ) from None
        try:
            return check(value, "", **kwargs)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None

    convert.__name__ = check.__name__.removeprefix("check_")  # argparse names the type in some messages
    return convert


def check_episodes(value: Any, name: str = "episodes") -> int:
    """A budget of episodes: an integer between 1 and :data:`MAX_EPISODES`."""
    return check_int(value, name, minimum=1, maximum=MAX_EPISODES)


# The argparse types the command line and the benchmark scripts share.
COUNT = option(check_positive_int, int)
EPISODES = option(check_episodes, int)
SEED = option(check_seed, int)
EXISTING = option(check_input_path)
OUT_DIR = option(check_output_dir)
JSON_OUT = option(check_output_file, suffixes=(".json",))


def json_argument(text: str) -> Any:
    """An argparse ``type``: the value a JSON text holds (callers check its shape, e.g. ``--genrl-kwargs``)."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"not JSON: {error}") from None


def json_object_argument(text: str) -> dict[str, Any]:
    """An argparse ``type``: a JSON object (``--genrl-kwargs``, ``--algorithm-kwargs``), checked by name and value by
    its caller once the settings it changes are known."""
    value = json_argument(text)
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r}")
    return value
