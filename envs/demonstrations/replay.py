"""Demonstrations of any episodic Gymnasium env from a dataset of actions: a Minari dataset, or arrays of actions with
their reset seeds.

:func:`replay_demonstrations` replays each episode's actions open loop from the env's ``reset(seed=...)`` with the
episode's own reset seed, and keeps the episode only when its last step succeeds: GenRL plays a generator's
trajectories open loop, so only such trajectories can teach it, whatever made them (a human, a closed-loop policy, a
planner). The kept episodes are written as :func:`~sb3_genrl.envs.demonstrations.record_demonstrations` writes its
own (:func:`~sb3_genrl.envs.demonstrations.recorder.write_demonstrations`), with the share kept in the metadata.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import minari
import numpy as np
from gymnasium import spaces
from sb3_genrl.envs.demonstrations.arm import refuse_existing_output
from sb3_genrl.envs.demonstrations.recorder import pad_actions, play_episode, write_demonstrations
from sb3_genrl.envs.external import (
    check_reports_success,
    check_reproducible_reset,
    check_success_key,
    task_env_and_horizon,
    task_name,
)
from tqdm.auto import tqdm

from sb3_genrl.checks import check_output_dir, check_positive_int
from sb3_genrl.data import read_metadata
from sb3_genrl.utils import folder_lock

ARRAY_KEYS = ("actions", "reset_seeds")  # what a mapping or an .npz file of demonstrations holds


@dataclass(frozen=True)
class ReplaySource:
    """The episodes of a dataset of actions, read and checked (:func:`read_replay_source`).

    :param actions: one ``(T_i, M)`` float64 array of finite actions per episode
    :param reset_seeds: the reset seed of each episode (non-negative integers)
    :param labels: how messages name each episode (``"episode 3"``: its index in the arrays, or its Minari episode id)
    :param name: where the actions came from, as the dataset's metadata records it (``source``)
    """

    actions: list[np.ndarray]
    reset_seeds: list[int]
    labels: list[str]
    name: str


def replay_demonstrations(
    task: str | Callable[[], gym.Env],
    source: Mapping[str, Any] | str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    horizon: int | None = None,
    success_key: str = "is_success",
    progress_bar: bool = False,
    episodes: int | None = None,
) -> Path:
    """Keep the episodes of a dataset of actions whose open-loop replay on a task succeeds, as a Minari dataset in
    ``out_dir``.

    Each episode's actions are played open loop from ``reset(seed=s)`` with the episode's reset seed ``s`` for
    ``horizon`` steps (or until the episode ends), each clipped to the action space; actions shorter than the horizon
    are padded with the hold action, zeros, as :class:`~sb3_genrl.LatentActionWrapper` plays after a trajectory. The
    episode is kept when its last step succeeds. The stored actions are those played (clipped, and zeros after an
    episode that ended early), the observations, rewards and end flags those of the replay: the dataset is what the
    recorder (:func:`~sb3_genrl.envs.demonstrations.record_demonstrations`) writes, bit for bit the same format.

    Checked before any work and before ``out_dir`` is claimed: the source (below: shapes, dtypes, finite actions,
    integer reset seeds), that the actions have the env's action dimension and are at most ``horizon`` steps long,
    that ``reset(seed=s)`` twice gives the same observation (the first episode's seed) and that the env reports a
    success. A dataset of which no episode is kept is refused (nothing is written), naming the counts.

    Metadata (``sb3_genrl.data.dataset_info``): ``reset_seeds`` of the kept episodes, ``source_episodes`` (their
    indices among the source's episodes), ``tried`` (the source's episodes), ``kept_share``, ``failed_open_loop`` (those
    whose replay did not succeed), ``failed_closed_loop`` 0, ``expert`` None and ``source``, where the actions came
    from.

    :param task: a task name (:func:`~sb3_genrl.envs.external.resolve_task`: a Gymnasium id, ``metaworld/<name>``,
        ...) or a callable that makes the env
    :param source: the episodes (:func:`read_replay_source`): a mapping, or the path of an ``.npz`` file, with
        ``actions`` ``(N, T, M)`` and ``reset_seeds`` ``(N,)`` integers; a Minari dataset folder; or the id of a Minari
        dataset that ``minari.load_dataset`` finds locally (nothing is downloaded), whose episodes carry their reset
        seed (as Minari's ``DataCollector`` records it; an episode's reset options are not replayed)
    :param out_dir: the dataset directory to create (must not exist or be empty)
    :param horizon: control steps of a demonstration; None: the env's ``max_episode_steps``
    :param success_key: the info key of the env's success (default ``"is_success"``, falling back to ``"success"``)
    :param progress_bar: show a tqdm progress bar (of the episodes replayed)
    :param episodes: replay only the source's first ``episodes`` episodes (default: all of them)
    :return: the dataset directory
    """
    name = task_name(task)
    check_success_key(success_key)
    if episodes is not None:
        check_positive_int(episodes, "episodes")
    first = episodes
    episodes = read_replay_source(source)
    if first is not None:
        if first > len(episodes.actions):
            raise ValueError(f"episodes ({first}) is more than the {len(episodes.actions)} episodes of {episodes.name}")
        episodes = ReplaySource(episodes.actions[:first], episodes.reset_seeds[:first], episodes.labels[:first], episodes.name)
    env, steps = task_env_and_horizon(task, horizon, success_key, recording=True)
    try:
        _check_episodes(env, episodes, steps, name)
        _probe(env, episodes, success_key, name)
        out_dir = check_output_dir(out_dir, "out_dir").absolute()
        with folder_lock(out_dir, lock_file=out_dir.parent / f".{out_dir.name}.lock"):
            refuse_existing_output(out_dir)
            began = time.perf_counter()
            kept = _replay(env, episodes, steps, progress_bar, name)
            tried = len(episodes.actions)
            if not kept:
                raise ValueError(
                    f"none of the {tried} episodes of {episodes.name} succeeded when replayed open loop on {name} from "
                    f"their seeded resets (0 kept of {tried} tried, {tried} failed open loop): check that the actions are "
                    "this task's, the horizon and the success key"
                )
            return write_demonstrations(
                out_dir,
                env,
                task,
                kept,
                steps,
                counts={"tried": tried, "failed_closed_loop": 0, "failed_open_loop": tried - len(kept)},
                success_key=success_key,
                description=f"{len(kept)} demonstrations of {name} from {episodes.name} whose open-loop replay succeeds "
                "(sb3-genrl)",
                algorithm_name=f"actions of {episodes.name} replayed open loop from their reset seeds",
                seed=None,
                expert=None,
                source=episodes.name,
                source_episodes=[episode["index"] for episode in kept],
                seconds=round(time.perf_counter() - began, 1),
            )
    finally:
        env.close()


def read_replay_source(source: Mapping[str, Any] | str | os.PathLike[str]) -> ReplaySource:
    """The episodes of a dataset of actions with their reset seeds, checked (see :func:`replay_demonstrations`).

    :param source: a mapping with ``actions`` ``(N, T, M)`` (real numbers) and ``reset_seeds`` ``(N,)`` (non-negative
        integers); the path of an ``.npz`` file holding them; a Minari dataset folder (or its ``data`` folder), whose
        episodes carry a ``seed`` in their metadata (an sb3-genrl dataset: its ``reset_seeds``); or a Minari dataset id
        found locally by ``minari.load_dataset`` (under ``MINARI_DATASETS_PATH``; nothing is downloaded)
    :raises ValueError: naming the bad value and what was expected
    """
    if isinstance(source, Mapping):
        return _from_arrays(source, "arrays given in memory")
    if not isinstance(source, str | os.PathLike):
        raise ValueError(
            f"source must be a mapping of arrays, an .npz file, a Minari dataset folder or id, got {type(source).__name__}"
        )
    path = Path(source)
    if path.is_file():
        if path.suffix.lower() != ".npz":
            raise ValueError(f"source {str(path)!r} is a file but not an .npz file of actions and reset_seeds")
        return _from_npz(path)
    if path.is_dir():
        return _from_minari(_open_minari(path, str(path)), f"the Minari dataset folder {str(path.absolute())}")
    if path.suffix.lower() == ".npz":
        raise ValueError(f"source {str(path)!r} does not exist; expected an .npz file of actions and reset_seeds")
    try:
        dataset = minari.load_dataset(str(source), download=False)
    except (FileNotFoundError, ValueError, TypeError) as error:
        raise ValueError(
            f"source {str(source)!r} is no file or folder, and no Minari dataset of that id is stored locally ({error}); "
            "nothing is downloaded: give a dataset folder, an .npz file, or the id of a dataset that `minari list local` "
            "shows"
        ) from None
    return _from_minari(dataset, f"the Minari dataset {dataset.id}")


def _from_arrays(arrays: Mapping[str, Any], name: str) -> ReplaySource:
    """Arrays of actions ``(N, T, M)`` and reset seeds ``(N,)``, checked."""
    missing = [key for key in ARRAY_KEYS if key not in arrays]
    if missing:
        raise ValueError(f"{name} lacks {missing}: expected {list(ARRAY_KEYS)}, got {sorted(arrays)}")
    actions = np.asarray(arrays["actions"])
    if actions.dtype.kind not in "fiu" or actions.ndim != 3 or 0 in actions.shape:
        raise ValueError(
            f"the actions of {name} must be a non-empty (N, T, M) array of real numbers (N episodes of T steps of M "
            f"numbers), got shape {actions.shape} and dtype {actions.dtype}"
        )
    seeds = np.asarray(arrays["reset_seeds"])
    if seeds.dtype.kind not in "iu" or seeds.shape != actions.shape[:1] or np.any(seeds < 0):
        raise ValueError(
            f"the reset_seeds of {name} must be {len(actions)} non-negative integers (N,), one per episode of the "
            f"actions, got {seeds.tolist() if seeds.size <= 10 else f'shape {seeds.shape}'} (dtype {seeds.dtype})"
        )
    labels = [f"episode {i}" for i in range(len(actions))]
    return _checked(list(actions.astype(np.float64)), [int(seed) for seed in seeds], labels, name)


def _from_npz(path: Path) -> ReplaySource:
    try:
        with np.load(path, allow_pickle=False) as stored:
            arrays = {key: stored[key] for key in stored.files}
    except (OSError, ValueError, EOFError) as error:
        raise ValueError(f"cannot read the .npz file {str(path)!r}: {type(error).__name__}: {error}") from None
    return _from_arrays(arrays, f"the file {str(path.absolute())}")


def _open_minari(path: Path, shown: str) -> minari.MinariDataset:
    """A Minari dataset folder (the one ``minari.load_dataset`` finds, or its ``data`` folder)."""
    data_dir = next((folder for folder in (path / "data", path) if (folder / "metadata.json").is_file()), None)
    if data_dir is None:
        raise ValueError(f"source {shown!r} is a folder but not a Minari dataset: no data/metadata.json in it")
    try:
        return minari.MinariDataset(data_dir)
    except (OSError, ValueError, KeyError, AssertionError) as error:
        raise ValueError(f"cannot open the Minari dataset {shown!r}: {type(error).__name__}: {error}") from None


def _from_minari(dataset: minari.MinariDataset, name: str) -> ReplaySource:
    """A Minari dataset's episodes with the reset seed of each (its episode metadata's ``seed``, or an sb3-genrl
    dataset's ``reset_seeds``)."""
    if not isinstance(dataset.action_space, spaces.Box) or len(dataset.action_space.shape) != 1:
        raise ValueError(f"the actions of {name} must be a Box of shape (M,) (per-step vectors), got {dataset.action_space}")
    indices = [int(index) for index in dataset.episode_indices]
    if not indices:
        raise ValueError(f"{name} holds no episodes")
    seeds = [metadata.get("seed") for metadata in dataset.storage.get_episode_metadata(indices)]
    if None in seeds:
        recorded = _recorded_seeds(dataset)
        seeds = recorded if recorded is not None and len(recorded) == len(indices) else seeds
    for index, seed in zip(indices, seeds, strict=True):
        if not isinstance(seed, int | np.integer) or isinstance(seed, bool) or seed < 0:
            raise ValueError(
                f"episode {index} of {name} has no reset seed (its metadata's seed is {seed!r}): its start cannot be "
                "reproduced, so its actions cannot be replayed. Record with minari.DataCollector and reset(seed=...) "
                "(or its automatic seed), or give the actions with their reset seeds as arrays"
            )
    actions = [np.asarray(episode["actions"], dtype=np.float64) for episode in dataset.storage.get_episodes(indices)]
    labels = [f"episode {index}" for index in indices]
    return _checked(actions, [int(seed) for seed in seeds], labels, name)


def _recorded_seeds(dataset: minari.MinariDataset) -> list[int] | None:
    """The reset seeds that an sb3-genrl dataset (the recorder's, or this module's) records in its metadata."""
    try:
        seeds = read_metadata(dataset.storage.data_path)["genrl"].get("reset_seeds")
    except ValueError:
        return None
    return seeds if isinstance(seeds, list) else None


def _checked(actions: list[np.ndarray], reset_seeds: list[int], labels: list[str], name: str) -> ReplaySource:
    """The episodes, once each is a ``(T, M)`` array of finite numbers."""
    for episode, label in zip(actions, labels, strict=True):
        if episode.ndim != 2 or len(episode) == 0:
            raise ValueError(f"{label} of {name}: its actions must be a (T, M) array, got shape {episode.shape}")
        bad = int(episode.size - np.count_nonzero(np.isfinite(episode)))
        if bad:
            raise ValueError(f"{label} of {name}: {bad} of its actions' numbers are not finite (nan or inf)")
    return ReplaySource(actions, reset_seeds, labels, name)


def _check_episodes(env: gym.Env, episodes: ReplaySource, steps: int, name: str) -> None:
    """Before any work: the env's actions are per-step vectors of the episodes' dimension, the episodes fit the
    horizon."""
    space = env.action_space
    if not isinstance(space, spaces.Box) or len(space.shape) != 1:
        raise ValueError(f"the env's actions must be a Box of shape (M,) (per-step vectors), got {space}")
    for actions, label in zip(episodes.actions, episodes.labels, strict=True):
        if actions.shape[1] != space.shape[0]:
            raise ValueError(
                f"{label} of {episodes.name} has actions of {actions.shape[1]} numbers, but {name} takes "
                f"{space.shape[0]} (its action space is {space})"
            )
        if len(actions) > steps:
            raise ValueError(
                f"{label} of {episodes.name} has {len(actions)} steps of actions, more than the horizon of {steps} steps: "
                f"give horizon= (--horizon) of at least {len(actions)}, up to {name}'s own episode length"
            )


def _probe(env: gym.Env, episodes: ReplaySource, success_key: str, name: str) -> None:
    """Before any work: reproducible resets, a success in the step's info."""
    check_reproducible_reset(env, episodes.reset_seeds[0], name)
    space = env.action_space
    _, _, _, _, info = env.step(np.clip(episodes.actions[0][0], space.low, space.high).astype(space.dtype))
    check_reports_success(info, success_key, name)


def _replay(env: gym.Env, episodes: ReplaySource, steps: int, progress_bar: bool, name: str) -> list[dict[str, Any]]:
    """The episodes whose actions, replayed open loop from their seeded reset, succeed: each as
    :func:`~sb3_genrl.envs.demonstrations.recorder.play_episode` returns it, with its padded ``actions``, its
    ``reset_seed`` and its ``index`` in the source."""
    kept = []
    total = len(episodes.actions)
    for index in tqdm(range(total), disable=not progress_bar, unit="episode", desc=f"{name} replays"):
        reset_seed = episodes.reset_seeds[index]
        actions = pad_actions(episodes.actions[index], steps, env.action_space)
        replayed = play_episode(env, reset_seed, steps, None, actions)
        if replayed["success"]:
            played = pad_actions(replayed["actions"], steps, env.action_space)
            kept.append(replayed | {"actions": played, "reset_seed": reset_seed, "index": index})
    return kept
