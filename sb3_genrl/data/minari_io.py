"""Demonstration datasets on disk: a Minari dataset directory with the episodes also stored as bulk arrays.

Layout of a dataset directory ``DIR`` (what :func:`write_dataset` writes and the loaders read)::

    DIR/data/metadata.json        Minari's dataset metadata plus a "genrl" entry (task, horizon, seed, version, ...)
    DIR/data/main_data.hdf5       Minari's HDF5 episode storage (written when h5py, ``minari[hdf5]``, is installed)
    DIR/data/genrl_episodes.npz   every episode as stacked arrays, for loading 40K episodes in about a second

``minari.MinariDataset("DIR/data")`` opens it with Minari's own API when the HDF5 storage is there (without h5py
the metadata says ``"data_format": "none"`` and ``"genrl": {"storage": ["npz"]}``, and only these loaders read it).
The arrays of ``genrl_episodes.npz`` (N episodes, horizon T, action dimension M, observation dimension D):
``observations (N, T+1, D) float32``, ``actions (N, T, M) float32``, ``rewards (N, T) float64``,
``terminations`` and ``truncations (N, T) bool``, ``reached (N, 2)`` and ``sampled_goals (N, 2) float64``.

A dataset is written into a temporary sibling directory and renamed into place at the end, so a directory that
carries a ``metadata.json`` with a ``"genrl"`` entry is complete. A file damaged later (truncated, overwritten) is
refused with a ``ValueError`` naming it: the loaders read ``genrl_episodes.npz`` and check that the HDF5 storage
beside it still opens, and refuse non-finite observations, actions or rewards. This module does not import the
tasks: the task and horizon come from the dataset's own metadata.
"""

from __future__ import annotations

import glob
import importlib.util
import json
import os
import secrets
import shutil
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import h5py
import minari
import numpy as np
from minari.data_collector.episode_buffer import EpisodeBuffer
from minari.dataset.minari_dataset import parse_dataset_id
from minari.dataset.minari_storage import MinariStorage
from minari.serialization import serialize_space

ARRAYS_FILE = "genrl_episodes.npz"
METADATA_FILE = "metadata.json"
HDF5_FILE = "main_data.hdf5"
_ARRAY_KEYS = ("observations", "actions", "rewards", "terminations", "truncations", "reached", "sampled_goals")
_FINITE_KEYS = ("observations", "actions", "rewards")  # "reached" is nan where Minari's metadata lacks it
# What numpy, zipfile, h5py and Minari raise on damaged files.
_READ_ERRORS = (OSError, EOFError, ValueError, KeyError, RuntimeError, zipfile.BadZipFile)


def _data_dir(path: str | os.PathLike[str]) -> Path:
    """The directory holding ``metadata.json``: ``path/data`` (a dataset directory) or ``path`` itself."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"no demonstration dataset at {str(path)!r}: the path does not exist")
    if not path.is_dir():
        raise ValueError(f"{str(path)!r} is not a demonstration dataset: expected a Minari dataset directory, got a file")
    for candidate in (path / "data", path):
        if (candidate / METADATA_FILE).is_file():
            return candidate
    raise ValueError(f"{str(path)!r} is not a Minari dataset directory: no data/{METADATA_FILE} in it")


def read_metadata(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The raw metadata of a demonstration dataset (Minari's keys plus ``"genrl"``).

    :param path: the dataset directory (or its ``data`` folder)
    :raises ValueError: if the path is not a complete sb3-genrl demonstration dataset
    """
    data_dir = _data_dir(path)
    try:
        metadata = json.loads((data_dir / METADATA_FILE).read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise ValueError(f"cannot read the dataset metadata {str(data_dir / METADATA_FILE)!r}: {error}") from None
    if not isinstance(metadata, dict) or not isinstance(metadata.get("genrl"), dict):
        raise ValueError(
            f"{str(path)!r} is a Minari dataset but not an sb3-genrl demonstration dataset (its metadata has no 'genrl' entry)"
        )
    return metadata


def dataset_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Summary of a demonstration dataset.

    :param path: the dataset directory
    :return: ``task``, ``horizon``, ``episodes``, ``seed``, ``version`` (of sb3-genrl that wrote it), ``dataset_id``
        and the rest of the ``"genrl"`` metadata entry
    """
    metadata = read_metadata(path)
    info = dict(metadata["genrl"])
    info.setdefault("episodes", metadata.get("total_episodes"))
    info["dataset_id"] = metadata.get("dataset_id")
    return info


def _check_expected(info: dict[str, Any], path: str | os.PathLike[str], task: str | None, horizon: int | None) -> None:
    if task is not None and info.get("task") != task:
        raise ValueError(f"dataset {str(path)!r} holds demonstrations of task {info.get('task')!r}, not {task!r}")
    if horizon is not None and info.get("horizon") != horizon:
        raise ValueError(f"dataset {str(path)!r} has horizon {info.get('horizon')}, expected {horizon}")


def load_arrays(
    path: str | os.PathLike[str], *, task: str | None = None, horizon: int | None = None, keys: tuple[str, ...] = _ARRAY_KEYS
) -> dict[str, np.ndarray]:
    """All episodes of a dataset as stacked arrays (see the module docstring for their names and shapes).

    :param path: the dataset directory
    :param task: if given, raise unless the dataset holds this task's demonstrations
    :param horizon: if given, raise unless the dataset's episodes have this many steps
    :param keys: the arrays to read (default: all)
    """
    info = dataset_info(path)
    _check_expected(info, path, task, horizon)
    data_dir = _data_dir(path)
    arrays_file = data_dir / ARRAYS_FILE
    if arrays_file.is_file():
        if "hdf5" in info.get("storage", []):
            _check_hdf5_opens(data_dir / HDF5_FILE)
        arrays, source = _load_npz(arrays_file, keys), arrays_file
    else:
        arrays, source = _load_with_minari(data_dir), data_dir / HDF5_FILE
    for key in set(keys) & set(_FINITE_KEYS):
        bad = int(np.size(arrays[key]) - np.count_nonzero(np.isfinite(arrays[key])))
        if bad:
            raise ValueError(
                f"{str(source)!r} is damaged or was written wrongly: its {key} hold {bad} non-finite values (nan or inf)"
            )
    return {key: arrays[key] for key in keys}


def _load_npz(arrays_file: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    try:
        with np.load(arrays_file, allow_pickle=False) as stored:
            missing = [key for key in keys if key not in stored.files]
            arrays = {key: stored[key] for key in keys if key in stored.files}
    except _READ_ERRORS as error:
        raise ValueError(
            f"{str(arrays_file)!r} is damaged (truncated or overwritten?) and cannot be read: {type(error).__name__}: {error}"
        ) from None
    if missing:
        raise ValueError(f"{str(arrays_file)!r} lacks the arrays {missing}")
    return arrays


def _check_hdf5_opens(hdf5_file: Path) -> None:
    """Refuse a Minari HDF5 storage that no longer opens (e.g. truncated), though the loaders read the npz."""
    if importlib.util.find_spec("h5py") is None:
        return

    if not hdf5_file.is_file():
        raise ValueError(f"{str(hdf5_file)!r} is missing: the dataset is incomplete (remake it with genrl demos)")
    try:
        with h5py.File(hdf5_file, "r") as storage:
            len(storage)
    except _READ_ERRORS as error:
        raise ValueError(
            f"{str(hdf5_file)!r} is damaged (truncated or overwritten?) and cannot be opened: {type(error).__name__}: {error}"
        ) from None


def _load_with_minari(data_dir: Path) -> dict[str, np.ndarray]:
    """Read the episodes through Minari's storage API (slower: one call per episode)."""
    try:
        storage = MinariStorage.read(data_dir)
        episodes = list(storage.get_episodes(range(storage.total_episodes)))
        arrays = {key: np.stack([episode[key] for episode in episodes]) for key in _ARRAY_KEYS[:5]}
        metadata = list(storage.get_episode_metadata(range(storage.total_episodes)))
    except (ImportError, *_READ_ERRORS) as error:
        raise ValueError(
            f"cannot read the episodes of {str(data_dir / HDF5_FILE)!r}: there is no {ARRAYS_FILE} and "
            f"Minari's storage failed, the file may be damaged ({type(error).__name__}: {error})"
        ) from None
    for key in ("reached", "sampled_goals"):
        arrays[key] = np.array([m.get(key, [np.nan, np.nan]) for m in metadata], dtype=np.float64)
    return arrays


def load_actions(path: str | os.PathLike[str], *, task: str | None = None, horizon: int | None = None) -> np.ndarray:
    """The demonstrations' action sequences, the training data of the trajectory generators.

    :param path: the dataset directory
    :param task: if given, raise unless the dataset holds this task's demonstrations
    :param horizon: if given, raise unless the episodes have this many steps
    :return: ``(N, T, M)`` float32 joint position deltas (rad per control step)
    """
    actions = load_arrays(path, task=task, horizon=horizon, keys=("actions",))["actions"]
    return np.ascontiguousarray(actions, dtype=np.float32)


def load_reached(path: str | os.PathLike[str]) -> np.ndarray:
    """Where each demonstration ended (the hockey puck's rest point, the ball's crossing of the rim height).

    :param path: the dataset directory
    :return: ``(N, 2)`` positions (x, y) in metres
    """
    return load_arrays(path, keys=("reached",))["reached"]


def load_transitions(path: str | os.PathLike[str], *, task: str | None = None) -> dict[str, np.ndarray]:
    """The demonstrations as flat transitions, for behaviour cloning and replay-buffer prefilling.

    An episode that ended before the dataset's horizon (terminated early) is stored padded to it (its last observation
    repeated, hold actions); those padding steps are no transitions of the env and are left out.

    :param path: the dataset directory
    :param task: if given, raise unless the dataset holds this task's demonstrations
    :return: ``observations (K, D)``, ``actions (K, M)``, ``rewards (K,)``, ``next_observations (K, D)`` and ``dones
        (K,)`` (True on each episode's last step), episode by episode in time order (``K = N*T`` when every episode
        lasts the whole horizon)
    """
    arrays = load_arrays(path, task=task, keys=("observations", "actions", "rewards", "terminations", "truncations"))
    observations = arrays["observations"]
    n, steps = arrays["actions"].shape[:2]
    ends = arrays["terminations"] | arrays["truncations"]
    # the steps up to each episode's first end flag (an episode without one: every step)
    played = np.cumsum(ends, axis=1) - ends < 1
    keep = played.reshape(-1)
    return {
        "observations": observations[:, :-1].reshape(n * steps, -1)[keep],
        "actions": arrays["actions"].reshape(n * steps, -1)[keep],
        "rewards": arrays["rewards"].reshape(-1).astype(np.float32)[keep],
        "next_observations": observations[:, 1:].reshape(n * steps, -1)[keep],
        "dones": ends.reshape(-1)[keep],
    }


def write_dataset(
    path: str | os.PathLike[str],
    arrays: dict[str, np.ndarray],
    *,
    dataset_id: str,
    observation_space: gym.spaces.Box,
    action_space: gym.spaces.Box,
    genrl: dict[str, Any],
    description: str = "",
    algorithm_name: str = "scripted expert with joint-velocity perturbations",
    extra_files: Callable[[Path], Any] | None = None,
) -> Path:
    """Write a demonstration dataset atomically (temporary sibling directory, renamed at the end).

    The temporary directory ``.NAME.partial-PID-HEX`` of a killed writer is removed by the next write of ``path``
    (:func:`remove_stale_partials`).

    :param path: the dataset directory to create; it must not exist, or be empty
    :param arrays: the arrays named in the module docstring
    :param dataset_id: Minari dataset id, ``namespace/name-vN``
    :param observation_space: the step env's observation space
    :param action_space: the step env's action space
    :param genrl: the ``"genrl"`` metadata entry (at least ``task``, ``horizon``, ``seed``, ``version``)
    :param description: Minari's dataset description
    :param algorithm_name: Minari's ``algorithm_name``, what made the episodes (default: the package's tasks' scripted
        experts)
    :param extra_files: called with the temporary directory before it is renamed into place, to add files (such as
        a coverage report) that a complete dataset must never be without
    :return: the dataset directory
    """
    parse_dataset_id(dataset_id)  # raises on a malformed id
    missing = [key for key in _ARRAY_KEYS if key not in arrays]
    if missing:
        raise ValueError(f"write_dataset needs the arrays {list(_ARRAY_KEYS)}; missing {missing}")
    path = Path(path).absolute()  # Minari's storage resolves relative paths against its own directory
    if path.exists() and (not path.is_dir() or any(path.iterdir())):
        raise ValueError(f"{str(path)!r} already exists and is not an empty directory; choose another output path")
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_partials(path)
    n, steps = arrays["actions"].shape[:2]
    tmp = path.parent / f".{path.name}.partial-{os.getpid()}-{secrets.token_hex(4)}"
    tmp.mkdir()
    try:
        data_dir = tmp / "data"
        data_dir.mkdir()
        np.savez(data_dir / ARRAYS_FILE, **{key: arrays[key] for key in _ARRAY_KEYS})
        has_hdf5 = importlib.util.find_spec("h5py") is not None
        if has_hdf5:
            _write_minari_hdf5(data_dir, arrays, observation_space, action_space)
        metadata = (
            json.loads((data_dir / METADATA_FILE).read_text())
            if has_hdf5
            else {
                "data_format": "none",
                "jpeg_encoding": False,
                "observation_space": serialize_space(observation_space),
                "action_space": serialize_space(action_space),
            }
        )

        metadata.update(
            dataset_id=dataset_id,
            total_episodes=int(n),
            total_steps=int(n * steps),
            minari_version=minari.__version__,
            description=description,
            algorithm_name=algorithm_name,
            genrl={**genrl, "episodes": int(n), "storage": ["npz"] + (["hdf5"] if has_hdf5 else [])},
        )
        (data_dir / METADATA_FILE).write_text(json.dumps(metadata, indent=1, default=_json_default))
        if extra_files is not None:
            extra_files(tmp)
        if path.exists():
            path.rmdir()
        os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path


def remove_stale_partials(path: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary directories (``.NAME.partial-PID-HEX``) of earlier writes of ``path`` whose writer
    process is no longer running, and only those.

    :param path: the dataset directory
    :return: the removed directories
    """
    path = Path(path).absolute()
    removed = []
    for candidate in path.parent.glob(f".{glob.escape(path.name)}.partial-*-*"):
        pid = candidate.name[len(path.name) + len(".partial-") + 1 :].split("-", 1)[0]
        if candidate.is_dir() and pid.isdigit() and not _running(int(pid)):
            shutil.rmtree(candidate, ignore_errors=True)
            removed.append(candidate)
    return removed


def _running(pid: int) -> bool:
    """Whether a process with this PID runs on this machine (a zombie counts as ended)."""
    if pid == os.getpid() or os.name == "nt":  # on Windows, os.kill(pid, 0) would end the process: keep it
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # it exists (another user's), or we cannot tell: keep its directory
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def _write_minari_hdf5(
    data_dir: Path, arrays: dict[str, np.ndarray], observation_space: gym.spaces.Box, action_space: gym.spaces.Box
) -> None:
    """Minari's own HDF5 episode storage, through its storage API."""
    storage = MinariStorage.new(
        data_dir, observation_space=observation_space, action_space=action_space, data_format="hdf5", jpeg_encoding=False
    )
    buffers = (
        EpisodeBuffer(
            id=i,
            observations=arrays["observations"][i],
            actions=arrays["actions"][i],
            rewards=arrays["rewards"][i],
            terminations=arrays["terminations"][i],
            truncations=arrays["truncations"][i],
            infos={},
        )
        for i in range(len(arrays["actions"]))
    )
    storage.update_episodes(buffers)
    storage.update_episode_metadata(
        [{"reached": r, "sampled_goals": g} for r, g in zip(arrays["reached"], arrays["sampled_goals"], strict=True)]
    )


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, set):
        return sorted(value)
    raise TypeError(f"cannot store {type(value).__name__} in the dataset metadata")
