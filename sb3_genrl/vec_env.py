"""Batched collection: every env's latent action of a VecEnv step decoded and played in one threaded fast-path call.

GenRL's episodes are open-loop: each is one trajectory that the task's fast path
(``play_trajectories(trajectories, goals, n_threads=...)``, MuJoCo's threaded ``rollout`` for the arm tasks) plays
without Python in the loop. :class:`BatchedLatentVecEnv` is SB3's ``DummyVecEnv`` whose step hands all its envs'
trajectories to that path at once, on all cores, in the training process: no env process, no pickling, one call per
step instead of one per episode. Each env is then stepped as ``DummyVecEnv`` steps it, through all its wrappers, and
its :class:`~sb3_genrl.LatentActionWrapper` returns the result already played for that very latent action, so
Monitor records, ``VecMonitor``, callbacks, ``EvalCallback``, ``get_attr``/``env_method``, seeding and resets are
SB3's own, and every reward and info is the one the env's own ``step`` gives (each latent action is decoded alone, as
``step`` decodes it: a batch decode rounds in the last bit, which would change a run's results).

The route of a result, all through public methods: the VecEnv asks each env's wrapper for the checked latent action
(``check_action``), its trajectory (``trajectory``) and the goal the fast path plays (``fast_path_goal``), plays the batch
with the task's ``play_trajectories``, and hands each result to its wrapper with
:meth:`~sb3_genrl.LatentActionWrapper.prepare_step` before stepping the env. A step cannot carry the result itself:
Gymnasium's ``step`` takes only the action, and the VecEnv cannot return the result in the env's place, since every
wrapper above the latent-action wrapper (Monitor, the run's recorders, a user's) must see the step. ``prepare_step`` is
the wrapper's documented way to be told that an action was played elsewhere: it holds the result for the one action it
was played for, and a ``step`` with any other action plays that action itself, so a wrapper above that changes actions
gets what it asked for.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecMonitor

from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.wrappers import LatentActionWrapper, env_id_has_fast_path, find_latent_wrapper


def default_threads() -> int:
    """The cores this process may run on (``os.sched_getaffinity``; ``os.cpu_count`` where that is missing)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def has_batched_fast_path(env: gym.Env) -> bool:
    """Whether ``env`` holds a :class:`~sb3_genrl.LatentActionWrapper` that plays through its task's fast path."""
    wrapper = find_latent_wrapper(env)
    return wrapper is not None and wrapper.use_fast_path


class BatchedLatentVecEnv(DummyVecEnv):
    """SB3's ``DummyVecEnv`` over latent-action envs whose step plays all envs' trajectories in one fast-path call.

    Every env must hold a :class:`~sb3_genrl.LatentActionWrapper` (possibly inside further wrappers) on the fast
    path, and all must wrap the same task (one type, one spec): their trajectories are played by the first env's
    task. An env whose step is not handed the latent action that was played for it (a wrapper above the
    ``LatentActionWrapper`` that changes actions) plays its own, as without batching.

    :param env_fns: functions that build the envs (as for ``DummyVecEnv``)
    :param n_threads: simulation threads of the fast path (default: all cores, :func:`default_threads`)
    """

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], n_threads: int | None = None) -> None:
        super().__init__(list(env_fns))
        self.n_threads = default_threads() if n_threads is None else n_threads
        if isinstance(self.n_threads, bool) or not isinstance(self.n_threads, int | np.integer) or self.n_threads < 1:
            raise ValueError(f"n_threads must be a positive integer, got {n_threads!r}")
        wrappers = [find_latent_wrapper(env) for env in self.envs]
        if any(wrapper is None or not wrapper.use_fast_path for wrapper in wrappers):
            raise ValueError(
                "BatchedLatentVecEnv needs envs with a LatentActionWrapper on its task's fast path "
                "(play_trajectories and get_context); use DummyVecEnv or SubprocVecEnv for the others"
            )
        self.latent_wrappers: list[LatentActionWrapper] = wrappers  # type: ignore[assignment]
        tasks = [wrapper.env.unwrapped for wrapper in self.latent_wrappers]
        if any(type(task) is not type(tasks[0]) or task.spec != tasks[0].spec for task in tasks):
            raise ValueError(
                "BatchedLatentVecEnv plays all envs' trajectories with one task: its envs must wrap the "
                f"same task, got {sorted({f'{type(task).__name__} {task.spec}' for task in tasks})}"
            )

    def step_wait(self) -> Any:
        play_together(self.latent_wrappers, self.actions, n_threads=int(self.n_threads))
        return super().step_wait()


def latent_vec_env(env_fns: Sequence[Callable[[], gym.Env]], **kwargs: Any) -> DummyVecEnv:
    """A VecEnv for SB3's ``make_vec_env(vec_env_cls=...)``: :class:`BatchedLatentVecEnv` (on all cores) when there are
    several envs and all play one task through its fast path, else SB3's ``DummyVecEnv``; the results are the same."""
    venv = DummyVecEnv(list(env_fns), **kwargs)
    if len(venv.envs) < 2 or not all(has_batched_fast_path(env) for env in venv.envs):
        return venv
    return BatchedLatentVecEnv([lambda env=env: env for env in venv.envs])


MAIN_GUARD = (
    "n_envs > 1 plays the envs in their own processes, which import the script that started them: a script "
    'must run its work under `if __name__ == "__main__":`, as any script with SB3\'s SubprocVecEnv'
)


def make_latent_vec_env(
    env_id: str,
    generator: TrajectoryGenerator,
    n_envs: int,
    *,
    n_threads: int | None = None,
    latent_clip: float = 3.0,
    monitor_file: str | None = None,
) -> VecEnv:
    """``n_envs`` latent-action envs of a task (:class:`~sb3_genrl.LatentActionWrapper` over ``gym.make(env_id)``)
    under SB3's ``VecMonitor``, for GenRL or any SB3 algorithm: played together in one threaded fast-path call
    (:class:`BatchedLatentVecEnv`, ``n_threads``: default all cores) where the task has a fast path, else each in its
    own process (SB3's ``SubprocVecEnv``: a script must then start its work under ``if __name__ == "__main__":``); one
    env is SB3's ``DummyVecEnv``. The envs are seeded as SB3 seeds a VecEnv (``seed``, ``seed + 1``, ...), so a run's
    result depends on ``n_envs`` and its seed, never on ``n_threads``.

    :param env_id: a Gymnasium id (``"GenRL/Hockey-v0"``)
    :param generator: the generator whose latent actions the envs take
    :param n_envs: envs played at a time; GenRL's iteration is then ``n_steps x n_envs`` episodes
    :param monitor_file: where ``VecMonitor`` writes its episodes (default: nowhere)
    """
    if isinstance(n_envs, bool) or not isinstance(n_envs, int | np.integer) or n_envs < 1:
        raise ValueError(f"n_envs must be a positive integer, got {n_envs!r}")
    if n_envs == 1:
        venv: VecEnv = DummyVecEnv([functools.partial(_latent_env, env_id, generator, latent_clip, False)])
    else:  # the spec, not the id: env processes need not know the id
        make = functools.partial(_latent_env, gym.spec(env_id), generator, latent_clip)
        venv = latent_envs(make, n_envs, batched=env_id_has_fast_path(env_id), n_threads=n_threads)
    return VecMonitor(venv, monitor_file)


def latent_envs(
    make_env: Callable[[bool], gym.Env], n_envs: int, *, batched: bool, n_threads: int | None = None
) -> BatchedLatentVecEnv | SubprocVecEnv:
    """``n_envs`` envs, each ``make_env(own_process)``: played together in one threaded fast-path call
    (:class:`BatchedLatentVecEnv` on ``n_threads``) when ``batched`` (a task with a fast path), else each in its own
    process (:func:`env_processes`)."""
    if batched:
        return BatchedLatentVecEnv([functools.partial(make_env, False) for _ in range(n_envs)], n_threads)
    return env_processes([functools.partial(make_env, True) for _ in range(n_envs)])


def env_processes(env_fns: Sequence[Callable[[], gym.Env]]) -> SubprocVecEnv:
    """SB3's ``SubprocVecEnv`` of ``env_fns``, with the reason when its processes do not start: a script that starts
    them outside ``if __name__ == "__main__":`` (each process imports the script again, and would start its own)."""
    if getattr(multiprocessing.current_process(), "_inheriting", False):  # Python's own test of that import
        raise RuntimeError(MAIN_GUARD)  # in the env process: its stderr shows why
    try:
        return SubprocVecEnv(list(env_fns))
    except (BrokenPipeError, EOFError, ConnectionResetError) as error:  # a process died while starting
        raise RuntimeError(f"the {len(env_fns)} env processes did not start. {MAIN_GUARD}") from error


def _latent_env(
    env_id: str | gym.envs.registration.EnvSpec, generator: TrajectoryGenerator, latent_clip: float, own_process: bool
) -> gym.Env:
    """One env of :func:`make_latent_vec_env` (an env process plays on one torch thread)."""
    if own_process:
        torch.set_num_threads(1)
    return LatentActionWrapper(gym.make(env_id), generator, latent_clip=latent_clip)


def play_together(wrappers: Sequence[LatentActionWrapper], actions: np.ndarray, *, n_threads: int) -> None:
    """Play ``actions[i]`` for ``wrappers[i]``'s current episode, all in one fast-path call of the first wrapper's
    task, and leave each result with its wrapper, for its next ``step`` with that action
    (:meth:`~sb3_genrl.LatentActionWrapper.prepare_step`)."""
    alphas = [wrapper.check_action(action)[0] for wrapper, action in zip(wrappers, actions, strict=True)]
    trajectories = np.stack([wrapper.trajectory(alpha) for wrapper, alpha in zip(wrappers, alphas, strict=True)])
    goals = np.stack([wrapper.fast_path_goal() for wrapper in wrappers])
    rewards, infos = wrappers[0].env.unwrapped.play_trajectories(trajectories, goals, n_threads=n_threads)
    for wrapper, alpha, reward, info in zip(wrappers, alphas, rewards, infos, strict=True):
        wrapper.prepare_step(alpha, float(reward), info)
