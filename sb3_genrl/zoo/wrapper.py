"""The env wrapper that rl-zoo3 applies to a GenRL task (``env_wrapper: sb3_genrl.zoo.latent_action``).

rl-zoo3 builds each env as ``wrapper(Monitor(gym.make(env_id)), **kwargs)``. A latent-action episode is one step of
the wrapper, which plays the whole trajectory at once, so a Monitor beneath it would never see an episode end (and
SB3's ``evaluate_policy`` would wait for one forever): the Monitor is moved above the wrapper.
"""

from __future__ import annotations

import functools
import os
import pathlib
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.monitor import Monitor

from sb3_genrl.generative import load
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl.generator_files import generator_digest
from sb3_genrl.wrappers import LatentActionWrapper
from sb3_genrl.zoo.generators import build_command, check_cache, default_generator


class ZooLatentActionWrapper(LatentActionWrapper):
    """:class:`~sb3_genrl.LatentActionWrapper` whose ``render()`` (``rgb_array``) shows where the last episode ended
    (the arm tasks: its trajectory replayed, the goal marked), one frame per episode, for rl-zoo3's
    ``record_video``; before the first episode, the task as it is."""

    _last_episode: tuple[np.ndarray, np.ndarray] | None = None

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        task = self.env.unwrapped
        if self.render_mode == "rgb_array" and hasattr(task, "episode_frames") and not self._needs_reset:
            self._last_episode = (self.trajectory(action), np.array(task.goal))
        return super().step(action)

    def render(self) -> Any:
        task = self.env.unwrapped
        if self._last_episode is None or self.render_mode != "rgb_array":
            return self.env.render()
        goal_now = np.array(task.goal)  # the next episode's (the VecEnv has reset the task already)
        task.episode_frames(*self._last_episode, every=np.iinfo(np.int32).max)
        frame = task.render()
        task.reset(options={"goal": goal_now, "allow_outside_region": True})
        return frame


def latent_action(
    env: gym.Env, generator: str | os.PathLike | None = None, generator_sha256: str | None = None, latent_clip: float = 3.0
) -> gym.Env:
    """``env`` in the latent-action wrapper with the generator named in the settings (rl-zoo3's ``env_wrapper``).

    :param env: the task as rl-zoo3 makes it (in SB3's ``Monitor``, which is moved above the wrapper)
    :param generator: the generator's file; ``None``: the task's quickstart generator in the cache
        (:func:`sb3_genrl.zoo.generators.default_generator`, made by ``python -m sb3_genrl.zoo build-generator``, or
        by ``train`` on first use)
    :param generator_sha256: the generator's content digest, when known (a saved run records it): a generator file
        whose content differs is refused
    :param latent_clip: as :class:`~sb3_genrl.LatentActionWrapper`'s
    """
    monitor = env if isinstance(env, Monitor) else None
    task_env = monitor.env if monitor is not None else env
    path = resolve_generator(generator, task_env.spec.id if task_env.spec is not None else None)
    loaded = load_generator(path)
    if generator_sha256 is not None:
        if generator_digest(loaded) != generator_sha256:
            raise ValueError(
                f"the generator {path} is not the one this run was trained with (content SHA-256 "
                f"{generator_sha256[:12]}...): it was changed or rebuilt; train again, or restore it"
            )
    wrapped = ZooLatentActionWrapper(task_env, loaded, latent_clip=latent_clip)
    if monitor is None:
        return wrapped
    monitor.env = wrapped  # the Monitor now sees each one-step episode
    return monitor


def resolve_generator(generator: str | os.PathLike | None, env_id: str | None) -> pathlib.Path:
    """The generator file: ``generator`` (``~`` expanded), or the cached quickstart generator of ``env_id``'s task
    (refused when made with other settings, :func:`~sb3_genrl.zoo.generators.check_cache`); a ``FileNotFoundError``
    saying how to make a missing one."""
    if generator is None:
        if env_id is None:
            raise ValueError("sb3_genrl.zoo.latent_action: an env without a Gymnasium id needs its generator file")
        path = default_generator(env_id)
        check_cache(env_id)
        if not path.is_file():
            raise FileNotFoundError(
                f"{env_id}'s generator {path} is not made yet: `{build_command(env_id)}` makes it (as "
                f"`python -m sb3_genrl.zoo train --algo genrl --env {env_id}` does on first use), or give a "
                "generator file as the wrapper's `generator`"
            )
        return path
    path = pathlib.Path(generator).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"sb3_genrl.zoo.latent_action: no generator file {str(path)!r}")
    return path


def load_generator(path: pathlib.Path) -> TrajectoryGenerator:
    """The generator of ``path``, on the CPU, loaded once per process and file version (a run builds several envs)."""
    return _load(str(path), path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=4)
def _load(path: str, mtime_ns: int) -> TrajectoryGenerator:
    return load(path, device="cpu")
