"""The horizon of a task's demonstrations, read from its expert: the fewest control steps after which the expert's
success has settled.

GenRL reads an episode's success at its last step, and an env's own episode length is rarely the length its task
needs: a Meta-World episode lasts up to 500 steps, where its scripted expert has pushed the puck to the goal within
100 on nearly every reset. Every step past the need costs simulation in the recording, in GenRL's search and in the
evaluation. In an env that runs on after a success, an expert that keeps acting can also undo its task (in
Meta-World's training env, push-v3's expert pushes on past the goal: on 100 tuning resets its success at the last step
is 0.99 at step 100, 0.96 at step 150 and 0.57 at step 500); in one that ends at the first success (Meta-World's
evaluation protocol, :mod:`sb3_genrl.envs.metaworld`) the success by step only grows, and the horizon is where it has
reached its best.

:func:`expert_horizon` plays the expert unperturbed and closed loop from seeded resets (drawn below ``2**31``, as the
recorder draws its own, so never one of the held-out resets), reads its success at every step, and returns the
shortest horizon at which that success is within ``tolerance`` of its best and has stayed there for the last
``settled_share`` of the horizon: a margin for perturbed or reconstructed trajectories that reach the goal a little
later than the expert. Where the success never settles (an expert that undoes its task more and more often as it
goes on), the horizon is the one whose last fifth holds the highest mean success.
"""

from __future__ import annotations

import concurrent.futures
import functools
import math
import multiprocessing
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.envs.control import default_threads
from sb3_genrl.envs.demonstrations.recorder import (
    MAIN_GUARD,
    _expert_action,
    _probe,
    _reset_seed,
    _worker_job,
    in_worker,
    task_expert,
    worker_pool,
)
from sb3_genrl.envs.external import task_env_and_horizon, task_name

from sb3_genrl.checks import check_non_negative_float, check_positive_int, check_seed

HORIZON_RESETS = 100  # seeded resets the expert plays to find the horizon
HORIZON_TOLERANCE = 0.02  # about twice the standard error of a success near 0.99 over 100 resets
SETTLED_SHARE = 0.2  # the success must have held for the last fifth of the horizon
# The stream of random draws of the resets (np.random.default_rng([seed, HORIZON_STREAM, i])): apart from the
# recorder's episodes (default_rng([seed, k])), so that the probe's resets are not the demonstrations' own
HORIZON_STREAM = 2**32 - 1
# Below this many steps in all (resets x the longest horizon), the default plays the resets in this process: a pool of
# worker processes takes seconds to start (each imports the package), more than so short a probe gains. Meta-World's
# probe (100 resets of 500 steps) is above it.
SMALL_PROBE_STEPS = 20_000


def expert_horizon(
    task: str | Callable[[], gym.Env],
    expert: Callable[[Any], np.ndarray] | None = None,
    *,
    resets: int = HORIZON_RESETS,
    seed: int = 0,
    max_steps: int | None = None,
    success_key: str = "is_success",
    tolerance: float = HORIZON_TOLERANCE,
    settled_share: float = SETTLED_SHARE,
    n_threads: int | None = None,
) -> dict[str, Any]:
    """The shortest horizon at which the expert's success has settled (see the module's description).

    :param task: a task name (:func:`~sb3_genrl.envs.external.resolve_task`) or a callable that makes the env
    :param expert: observation -> action; None: the task's own expert (``metaworld/<name>``)
    :param resets: seeded resets the expert plays
    :param seed: seed of the resets' draws
    :param max_steps: the longest horizon considered (None: the env's ``max_episode_steps``)
    :param success_key: the info key of the env's success
    :param tolerance: how far below its best (a share of the resets) the success may be
    :param settled_share: the share of the horizon, at its end, over which the success must have been within
        ``tolerance`` of its best
    :param n_threads: worker processes that play the resets (default: the available cores, or this process alone for
        a probe of fewer than :data:`SMALL_PROBE_STEPS` steps in all); the answer is the same for any number. As with
        :func:`~sb3_genrl.envs.demonstrations.record_demonstrations`, a script that uses more than one must call this
        under ``if __name__ == "__main__":``
    :return: ``horizon`` (where the success never settles, ``settled`` False: the shortest whose last
        ``settled_share`` has the highest mean success), ``success`` (the
        expert's success at the last step of that horizon), ``best`` (its best
        over the steps) and ``best_step`` (the first step where it is reached), ``max_steps``, ``resets``, ``seed`` and
        ``success_by_step`` (the success at the end of each horizon ``1..max_steps``)
    :raises ValueError: when the expert succeeds on none of the resets at any step
    """
    name = task_name(task)
    expert = task_expert(task, expert)
    check_positive_int(resets, "resets")
    check_seed(seed)
    tolerance = check_non_negative_float(tolerance, "tolerance")
    settled_share = check_non_negative_float(settled_share, "settled_share")
    if settled_share >= 1.0:
        raise ValueError(f"settled_share must be below 1, got {settled_share}")
    if n_threads is not None:
        check_positive_int(n_threads, "n_threads")
    env, steps = task_env_and_horizon(task, max_steps, success_key)
    workers = (default_threads() if resets * steps >= SMALL_PROBE_STEPS else 1) if n_threads is None else int(n_threads)
    workers = min(workers, resets)
    if workers > 1 and getattr(multiprocessing.current_process(), "_inheriting", False):  # Python's own test
        env.close()
        raise RuntimeError(MAIN_GUARD)  # in a worker process that re-imports the script: its stderr shows why
    seeds = [_reset_seed(np.random.default_rng([seed, HORIZON_STREAM, i])) for i in range(resets)]
    _probe(env, expert, seeds[0], success_key, name)
    job = _worker_job(task, expert, steps, success_key, seed, np.zeros(0), recording=False) if workers > 1 else None
    if job is None:  # one process, or a task or an expert that cannot be sent to another: the same answer
        successes = np.array([_successes(env, expert, reset_seed, steps) for reset_seed in seeds])
    else:
        successes = np.array(_successes_in_workers(job, workers, seeds, name))
    env.close()
    by_step = successes.mean(axis=0)
    best = float(by_step.max())
    if best == 0.0:
        raise ValueError(
            f"{name}: the expert succeeded on none of {resets} seeded resets within {steps} steps, so no horizon suits "
            "it: check the expert and the success key, or give a longer max_steps"
        )
    near = by_step >= best - tolerance - 1e-12
    windows = [slice(_settled_from(h, settled_share) - 1, h) for h in range(1, steps + 1)]
    settled = [h for h, window in enumerate(windows, start=1) if near[window].all()]
    # never settled (an expert that undoes its task, more and more often): where the success holds best over the window
    horizon = settled[0] if settled else int(np.argmax([by_step[window].mean() for window in windows])) + 1
    return {
        "horizon": horizon,
        "settled": bool(settled),
        "success": float(by_step[horizon - 1]),
        "best": best,
        "best_step": int(np.argmax(by_step)) + 1,
        "max_steps": steps,
        "resets": resets,
        "seed": seed,
        "success_by_step": by_step.tolist(),
    }


def describe_horizon(found: dict[str, Any]) -> str:
    """Where a horizon of :func:`expert_horizon` lies, in words: ``"where the expert's success settles (0.97 of 100
    seeded resets; its best 0.98 at step 73)"``, for the CLI, the quickstart's log and its report."""
    where = "settles" if found["settled"] else "never settles, but holds best over the horizon's last fifth"
    return (
        f"where the expert's success {where} ({found['success']:.2f} of {found['resets']} seeded resets; its best "
        f"{found['best']:.2f} at step {found['best_step']})"
    )


def _settled_from(horizon: int, settled_share: float) -> int:
    """The first step of the window, at the end of ``horizon``, over which the success must have settled."""
    return max(1, math.ceil((1.0 - settled_share) * horizon))


def _successes_in_workers(job: bytes, workers: int, seeds: list[int], name: str) -> list[np.ndarray]:
    """:func:`_successes` of each reset seed, in ``workers`` worker processes, in the seeds' order."""
    pool = worker_pool(job, workers, name)
    try:
        return list(pool.map(functools.partial(in_worker, _successes), seeds, chunksize=max(1, len(seeds) // (4 * workers))))
    except concurrent.futures.process.BrokenProcessPool as error:  # killed (out of memory), crashed, or never started
        raise RuntimeError(
            f"a worker process ended abruptly while it played the expert of {name} (its error, if it had one, is "
            f"above). Where it could not start: {MAIN_GUARD}"
        ) from error
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _successes(env: gym.Env, expert: Callable[[Any], np.ndarray], reset_seed: int, steps: int) -> np.ndarray:
    """``(steps,)``: whether the expert, closed loop from ``reset(seed=reset_seed)``, succeeds at each step (an episode
    that ends early keeps its last step's success for the steps after it)."""
    space = env.action_space
    observation, _ = env.reset(seed=int(reset_seed))
    success = np.zeros(steps, dtype=bool)
    for t in range(steps):
        action = np.clip(_expert_action(expert, observation, space), space.low, space.high).astype(space.dtype)
        observation, _, terminated, truncated, info = env.step(action)
        success[t] = bool(info.get("is_success", False))
        if terminated or truncated:
            success[t + 1 :] = success[t]
            break
    return success
