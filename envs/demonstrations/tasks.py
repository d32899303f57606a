"""The one way in to a task's demonstrations, for every task: :func:`task_demonstrations`.

``genrl demos``, ``genrl quickstart`` and the API make a task's demonstrations through it, whichever task it is: the
package's own, Meta-World's, or a user's (a Gymnasium id, ``module:Id``, or one named with
:func:`sb3_genrl.envs.external.register`). A task with its own maker makes them with it; any other records its
expert's (:func:`~sb3_genrl.envs.demonstrations.record_demonstrations`).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.envs.demonstrations.arm import make_demonstrations
from sb3_genrl.envs.demonstrations.recorder import DEFAULT_NOISE, record_demonstrations
from sb3_genrl.envs.external import Task, resolve_task


def own_maker(task: Task) -> Callable[..., Path] | None:
    """The task's own demonstration maker, ``(episodes, out_dir, *, seed, n_threads, progress_bar) -> Path``: its
    ``make_demonstrations``, or that of its :class:`~sb3_genrl.envs.spec.TaskSpec`
    (:func:`~sb3_genrl.envs.demonstrations.make_demonstrations`); None: its demonstrations are its expert's."""
    if task.make_demonstrations is not None:
        return task.make_demonstrations
    return None if task.spec is None else functools.partial(make_demonstrations, task.spec)


def task_demonstrations(
    task: str | Callable[[], gym.Env],
    episodes: int,
    out_dir: str | os.PathLike[str],
    *,
    expert: Callable[[Any], np.ndarray] | None = None,
    seed: int = 0,
    noise: float | np.ndarray | None = None,
    horizon: int | None = None,
    success_key: str | None = None,
    n_threads: int | None = None,
    progress_bar: bool = False,
) -> Path:
    """Make ``episodes`` demonstrations of ``task`` as a dataset in ``out_dir``: with the task's own maker where it has
    one and no ``expert`` is given (:func:`own_maker`), else recorded from the expert (``expert``, or the task's own:
    :func:`~sb3_genrl.envs.demonstrations.record_demonstrations`, each episode kept when its open-loop replay
    succeeds). Either way the dataset depends on ``seed`` only.

    :param task: a task's name (:func:`~sb3_genrl.envs.external.resolve_task`) or a callable that makes the env
    :param episodes: demonstrations to keep
    :param out_dir: the dataset directory to create (must not exist or be empty)
    :param expert: observation -> action; None: the task's own maker, or its own expert
    :param seed: seed of every random draw
    :param noise: the recorder's perturbation (default :data:`~sb3_genrl.envs.demonstrations.DEFAULT_NOISE`)
    :param horizon: the recorder's control steps of a demonstration (None: the env's)
    :param success_key: the info key of the env's success (default ``"is_success"``, falling back to ``"success"``)
    :param n_threads: processes or threads that play the episodes (default: the available cores); the dataset does not
        depend on it
    :param progress_bar: show a progress bar
    :return: the dataset directory
    :raises ValueError: for ``noise``, ``horizon`` or ``success_key`` given to a task's own maker, which takes none
    """
    maker = None if callable(task) or expert is not None else own_maker(resolve_task(task))
    if maker is None:
        return record_demonstrations(
            task,
            expert,
            episodes,
            out_dir,
            seed=seed,
            noise=DEFAULT_NOISE if noise is None else noise,
            horizon=horizon,
            success_key=success_key or "is_success",
            n_threads=n_threads,
            progress_bar=progress_bar,
        )
    given = [name for name, value in dict(noise=noise, horizon=horizon, success_key=success_key).items() if value is not None]
    if given:
        raise ValueError(
            f"{', '.join(given)} {'applies' if len(given) == 1 else 'apply'} to demonstrations recorded from an expert, "
            f"not to {task}'s own maker "
            "(give an expert to record its demonstrations instead)"
        )
    return maker(episodes, out_dir, seed=seed, n_threads=n_threads, progress_bar=progress_bar)
