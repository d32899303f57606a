"""Checkpoints of a training run, so that a stopped run resumes where it stopped: one mechanism for GenRL
(``genrl train-policy``) and the off-policy baselines (``genrl baseline``, :mod:`sb3_genrl.baselines.checkpoint`).

Every ``every`` episodes, at the start of a rollout that follows an episode's end (after the last update, before the
next episode is played), an :class:`EpisodeCheckpoint` writes into ``OUT/checkpoint/`` its files and then
``state.json``, as one unit (:func:`sb3_genrl.utils.write_checkpoint`: the files under new names, ``state.json``,
naming them, last, so a run killed at any moment leaves the previous checkpoint whole). ``state.json`` holds the run's
identity, the episodes done (the Monitor file's rows) and the Monitor's clocks, with what each kind of run adds. A rerun
of the same run resumes from it: :func:`resume_state` reads it (a checkpoint of another run is refused, naming what
differs), :func:`~sb3_genrl.run.folder.keep_episodes` keeps the Monitor file's rows up to it (``logs/progress.csv``
starts again there, the earlier one kept as ``progress.until_episode_K.csv``), and :func:`continue_clocks` makes the
Monitor's ``t`` and ``cpu_seconds`` columns go on from its clocks.

GenRL's checkpoint (:class:`GenRLCheckpoint`) adds, at the start of an iteration:

- ``model.zip``: SB3's save of the model: the weights, the value function's and the regression's Adam, the policy
  average, and SB3's counters (``num_timesteps``, ``_n_updates``, ``_last_obs``, ``_last_episode_starts``, the
  ``ep_info_buffer``);
- ``memories.pt`` (read back with ``torch.load(weights_only=True)``): the value function's batches, the hindsight
  relabelling's pulls of the last batches, the pulls kept for the whole run (the demonstrations), the solving pulls and
  initial weights of the refits, the random states (torch, NumPy, Python, and every env's: its own, its goal sampler's
  and its spaces', as they were before the env drew its current context), and the logger's values not yet written;
- in ``state.json``, the episodes at which the run was resumed before.

:func:`resume_genrl` rebuilds the model from it on a new env, which draws the same context again from the restored
states, so a resumed run plays the same episodes and ends with the same parameters, bit for bit, as one that was not
stopped.
"""

from __future__ import annotations

import json
import os
import pathlib
import pickle
import random
import time
import warnings
import zipfile
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper, VecMonitor

from sb3_genrl.curves import _EpisodeInfo
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl.genrl import GenRL
from sb3_genrl.run.folder import CHECKPOINT_DIR, RunFolderError, differing
from sb3_genrl.utils import read_checkpoint, same_observation, write_checkpoint

CHECKPOINT_EVERY = 640  # episodes between checkpoints of genrl train-policy (ten of GenRL's default iterations)
MODEL, MEMORIES = "model.zip", "memories.pt"


class EpisodeCheckpoint(BaseCallback):
    """Write a checkpoint of the run into ``out/checkpoint`` every ``every`` episodes, at the start of a rollout that
    follows an episode's end (see the module doc): the files of :meth:`_files`, then ``state.json`` with the run's
    identity, the episodes done, the Monitor's clocks and the entries of :meth:`_state`. The run's env is a
    ``VecMonitor`` or one SB3 ``Monitor`` (in a one-env VecEnv) over :func:`sb3_genrl.curves.episode_info`'s wrapper.

    :param out: the run folder (the checkpoint goes into ``out/checkpoint``)
    :param every: episodes between checkpoints
    :param identity: what the run is (JSON values), checked on resume (:func:`resume_state`)
    :param start: the state the run was resumed from (its ``"episodes"``; ``None``: a new run)
    """

    def __init__(
        self, out: str | os.PathLike[str], every: int, identity: dict[str, Any], start: dict[str, Any] | None
    ) -> None:
        super().__init__()
        self.out, self.every, self.identity = pathlib.Path(out), int(every), identity
        self.start_episodes = 0 if start is None else int(start["episodes"])
        self._last = self.start_episodes
        self._seen = 0  # episodes this process has seen end

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:
        # Called before each rollout, after the last update: GenRL's iteration, an off-policy algorithm's step.
        ended = _episodes_ended(_monitor(self.model.get_env()))
        if ended == self._seen:  # no episode ended since the last call: not at an episode's end
            return
        self._seen = ended
        episodes = self.start_episodes + ended
        if episodes - self._last >= self.every:
            self.save(episodes)
            self._last = episodes

    def save(self, episodes: int) -> None:
        """Write the checkpoint's files and then the state naming them, as one unit (see the module doc).

        :param episodes: the episodes the run has played
        """
        venv = self.model.get_env()
        write_checkpoint(
            self.out / CHECKPOINT_DIR,
            self._files(),
            {
                "identity": self.identity,
                "episodes": int(episodes),
                "monitor_seconds": time.time() - _monitor(venv).t_start,
                "cpu_seconds": self._cpu_seconds(),
                **self._state(),
            },
        )

    def _files(self) -> dict[str, tuple[str, Callable[[pathlib.Path], None]]]:
        """The checkpoint's files: entry -> (file name, a writer that writes the file at the path it is given)."""
        raise NotImplementedError

    def _state(self) -> dict[str, Any]:
        """The entries of ``state.json`` that this kind of run adds (JSON values)."""
        return {}

    def _cpu_seconds(self) -> list[float] | float:
        """The CPU seconds of each env's process so far, as :func:`continue_clocks` reads them back."""
        return [float(seconds) for seconds in self.model.get_env().env_method("cpu_seconds")]


def resume_state(out: str | os.PathLike[str], identity: dict[str, Any]) -> dict[str, Any] | None:
    """The state of the checkpoint in ``out/checkpoint`` (:func:`sb3_genrl.utils.read_checkpoint`; its ``"paths"``
    entry names the checkpoint's files), or ``None`` when there is none.

    :param out: the run folder
    :param identity: what the run is (JSON values); a checkpoint of another run (another algorithm, other settings) is
        refused with a :class:`~sb3_genrl.run.folder.RunFolderError` naming what differs
    """
    out = pathlib.Path(out)
    state = read_checkpoint(out / CHECKPOINT_DIR)
    if state is None:
        return None
    recorded = state.get("identity")
    recorded = recorded if isinstance(recorded, dict) else {}
    identity = json.loads(json.dumps(identity))  # as state.json holds it: tuples as lists, keys as strings
    if recorded != identity:
        raise RunFolderError(
            f"{out} holds a checkpoint of another run (it differs in {', '.join(differing(recorded, identity))}); use "
            f"another out_dir, or delete {out / CHECKPOINT_DIR} to start this run afresh"
        )
    return state


def continue_clocks(env: Monitor | VecEnv, state: dict[str, Any]) -> None:
    """Make the resumed run's Monitor ``t`` and ``cpu_seconds`` columns go on from the checkpoint's.

    :param env: the resumed run's env: its ``Monitor``, or its VecEnv (a ``VecMonitor``, or one ``Monitor`` in a
        one-env VecEnv), each env under :func:`sb3_genrl.curves.episode_info`'s wrapper
    :param state: the checkpoint's state (:func:`resume_state`); its ``cpu_seconds`` are one per env, or one number (a
        run of one ``Monitor``)
    """
    monitor = env if isinstance(env, Monitor) else _monitor(env)
    monitor.t_start = time.time() - float(state["monitor_seconds"])
    seconds = state["cpu_seconds"]
    seconds = [seconds] if isinstance(seconds, int | float) else seconds
    if isinstance(env, Monitor):
        (only,) = seconds
        _episode_info(env).continue_from(float(only))
        return
    for index, value in enumerate(seconds):
        env.env_method("continue_from", float(value), indices=[index])


class RandomStateRecorder(gym.Wrapper):
    """Keeps the random states of the env it wraps as they were before its last reset (see :func:`random_states`),
    so that a resumed run can make the env draw the same context again."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.states_before_reset: dict[str, Any] = {}

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self.states_before_reset = random_states(self.env)
        return self.env.reset(**kwargs)

    def random_states_before_reset(self) -> dict[str, Any]:
        return self.states_before_reset

    def set_random_states(self, states: dict[str, Any]) -> None:
        set_random_states(self.env, states)


class GenRLCheckpoint(EpisodeCheckpoint):
    """GenRL's checkpoint: every ``every`` episodes, at the start of an iteration, the model, its memories and random
    states, and the logger's values not yet written (see the module doc).

    :param out: the run folder (the checkpoint goes into ``out/checkpoint``)
    :param every: episodes between checkpoints
    :param identity: what the run is, checked on resume
    :param start: the state the run was resumed from (``None``: a new run)
    """

    def __init__(
        self, out: str | os.PathLike[str], every: int, identity: dict[str, Any], start: dict[str, Any] | None
    ) -> None:
        super().__init__(out, every, identity, start)
        self._resumed = [] if start is None else [*start.get("resumed_at_episodes", []), self.start_episodes]

    def _files(self) -> dict[str, tuple[str, Callable[[pathlib.Path], None]]]:
        model, env = self.model, self.model.get_env()
        memories = {
            "value_memory": list(model._value_memory),
            "hindsight_memory": [] if model.hindsight is None else list(model.hindsight.memory),
            "hindsight_kept_pulls": None if model.kept_pulls is None else model.kept_pulls.pulls,
            "hindsight_solved": [] if model.refits is None else list(model.refits.solved),
            "hindsight_initial_mean": None if model.refits is None else model.refits.initial_mean,
            "random_states": _global_random_states(model),
            "env_random_states": env.env_method("random_states_before_reset"),
            "logger": _pending_logs(model.logger),
        }
        return {
            "model": (MODEL, lambda path: OnPolicyAlgorithm.save(model, path)),  # without the generator file beside it
            "memories": (MEMORIES, lambda path: th.save(memories, path)),
        }

    def _state(self) -> dict[str, Any]:
        return {"resumed_at_episodes": self._resumed}


def resume_genrl(state: dict[str, Any], env: Any, generator: TrajectoryGenerator | str, device: Any, logger: Logger) -> GenRL:
    """The model as the checkpoint ``state`` left it, on ``env`` (a new monitored env of the run, its envs wrapped in
    :class:`RandomStateRecorder`), which is reset to draw the checkpoint's contexts again, with ``logger`` holding the
    values the stopped run had not written yet."""
    memories = _load_memories(state["paths"]["memories"])
    model = GenRL.load(state["paths"]["model"], env=env, device=device, force_reset=False, generator=generator)
    model._value_memory.extend(_to_device(memories["value_memory"], model.device))
    if model.hindsight is not None:
        model.hindsight.memory.extend(_to_device(memories["hindsight_memory"], model.device))
        if memories.get("hindsight_kept_pulls") is not None:  # the demonstrations kept for the whole run
            model.kept_pulls.keep(*memories["hindsight_kept_pulls"])
    if model.refits is not None:  # the solving pulls and the initial weights of the refits
        model.refits.solved.extend(_to_device(memories.get("hindsight_solved", []), model.device))
        if memories.get("hindsight_initial_mean") is not None:
            model.refits.initial_mean = _to_device(memories["hindsight_initial_mean"], model.device)
    venv = model.get_env()
    for index, states in enumerate(memories["env_random_states"]):
        venv.env_method("set_random_states", states, indices=[index])
    venv.unwrapped._reset_seeds()  # no seed at this reset (loading seeded the env): the restored states draw
    model.seed_contexts()  # with pulls_per_context: the groups' seeds, from the checkpoint's episode on
    observations = venv.reset()
    if not same_observation(observations, model._last_obs):
        warnings.warn(
            "the resumed env did not draw the checkpoint's contexts again: the resumed run is not the "
            "uninterrupted one bit for bit",
            stacklevel=2,
        )
        model._last_obs = observations
    _set_global_random_states(model, memories["random_states"])
    model.set_logger(logger)
    _restore_pending_logs(memories["logger"], logger)
    continue_clocks(venv, state)
    return model


def _load_memories(path: pathlib.Path) -> dict[str, Any]:
    """The checkpoint's memories file, or a ``ValueError`` naming it when it cannot be read (truncated or corrupt)."""
    try:
        return th.load(path, weights_only=True, map_location="cpu")
    except (OSError, EOFError, RuntimeError, pickle.UnpicklingError, zipfile.BadZipFile) as error:
        reason = str(error).strip().split(". ")[0].split("\n")[0] or "it ends early"  # torch's first sentence
        raise ValueError(
            f"the checkpoint file {path} is truncated or corrupt ({type(error).__name__}: {reason}); "
            f"delete {path.parent} to start afresh"
        ) from error


def random_states(env: gym.Env) -> dict[str, Any]:
    """The states of every NumPy random generator held by ``env`` and the wrappers in it (their own, a goal
    sampler's, their spaces'), by ``"<depth>.<attribute>"``."""
    states = {}
    for depth, layer in enumerate(_layers(env)):
        for name, value in vars(layer).items():
            if isinstance(value, np.random.Generator):
                states[f"{depth}.{name}"] = value.bit_generator.state
            elif isinstance(value, gym.spaces.Space) and isinstance(value._np_random, np.random.Generator):
                states[f"{depth}.{name}._np_random"] = value._np_random.bit_generator.state
    return states


def set_random_states(env: gym.Env, states: dict[str, Any]) -> None:
    """Give the generators :func:`random_states` names the states it recorded (a generator not made yet is made)."""
    layers = list(_layers(env))
    for key, state in states.items():
        depth, *path, attribute = key.split(".")
        owner = layers[int(depth)]
        for name in path:
            owner = getattr(owner, name)
        generator = getattr(owner, attribute, None)
        if not isinstance(generator, np.random.Generator):
            generator = np.random.Generator(getattr(np.random, state["bit_generator"])())
            setattr(owner, attribute, generator)
        generator.bit_generator.state = state


def _layers(env: gym.Env) -> Any:
    while isinstance(env, gym.Wrapper):
        yield env
        env = env.env
    yield env


def _global_random_states(model: GenRL) -> dict[str, Any]:
    name, keys, position, has_gauss, cached = np.random.get_state()  # noqa: NPY002 (SB3 seeds the global one)
    version, internal, gauss = random.getstate()
    space = model.action_space._np_random
    return {
        "torch": th.get_rng_state(),
        "cuda": th.cuda.get_rng_state_all() if th.cuda.is_available() else [],
        "numpy": (name, th.from_numpy(keys.astype(np.int64)), position, has_gauss, cached),
        "python": (version, internal, gauss),
        "action_space": None if space is None else space.bit_generator.state,
    }


def _set_global_random_states(model: GenRL, states: dict[str, Any]) -> None:
    th.set_rng_state(states["torch"])
    if states["cuda"] and th.cuda.is_available():
        th.cuda.set_rng_state_all(states["cuda"])
    name, keys, position, has_gauss, cached = states["numpy"]
    np.random.set_state((name, keys.numpy().astype(np.uint32), position, has_gauss, cached))  # noqa: NPY002
    random.setstate(states["python"])
    if states["action_space"] is not None:
        model.action_space.seed(0)
        model.action_space._np_random.bit_generator.state = states["action_space"]


def _pending_logs(logger: Any) -> dict[str, Any]:
    """What SB3's logger holds and has not written yet (the last update's ``train/`` values: SB3 writes them with the
    next batch's ``rollout/`` values)."""
    values = {
        key: value.item() if isinstance(value, np.generic) else value
        for key, value in logger.name_to_value.items()
        if isinstance(value, int | float | str | np.generic)
    }
    return {
        "values": values,
        "counts": {key: int(logger.name_to_count[key]) for key in values},
        "excluded": {key: logger.name_to_excluded.get(key) for key in values},
    }


def _restore_pending_logs(logs: dict[str, Any], logger: Logger) -> None:
    logger.name_to_value.update(logs["values"])
    logger.name_to_count.update(logs["counts"])
    logger.name_to_excluded.update(
        {key: tuple(value) if value is not None else value for key, value in logs["excluded"].items()}
    )


def _monitor(venv: VecEnv) -> Monitor | VecMonitor:
    """The run's Monitor: its ``VecMonitor`` (under any VecEnv wrappers), or the ``Monitor`` of its one env."""
    layer = venv
    while isinstance(layer, VecEnvWrapper) and not isinstance(layer, VecMonitor):
        layer = layer.venv
    if isinstance(layer, VecMonitor):
        return layer
    envs = getattr(layer, "envs", [])
    if len(envs) != 1 or not isinstance(envs[0], Monitor):
        raise TypeError(
            f"the checkpointed run's env must be a VecMonitor or one Monitor, got {type(layer).__name__} of "
            f"{', '.join(type(env).__name__ for env in envs) or 'envs in other processes'}"
        )
    return envs[0]


def _episodes_ended(monitor: Monitor | VecMonitor) -> int:
    """The episodes that ended under ``monitor`` in this process."""
    return monitor.episode_count if isinstance(monitor, VecMonitor) else len(monitor.get_episode_lengths())


def _episode_info(monitor: Monitor) -> _EpisodeInfo:
    if not isinstance(monitor.env, _EpisodeInfo):
        raise TypeError("the checkpointed run's Monitor must wrap sb3_genrl.curves.episode_info's wrapper")
    return monitor.env


def _to_device(value: Any, device: th.device) -> Any:
    if isinstance(value, th.Tensor):
        return value.to(device)
    if isinstance(value, dict):
        return {key: _to_device(item, device) for key, item in value.items()}
    return type(value)(_to_device(item, device) for item in value)
