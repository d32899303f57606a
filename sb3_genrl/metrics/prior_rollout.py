"""The prior rollout: how well a generator's prior alone does on a task, before any policy training.

For each of ``contexts`` goals, ``draws`` latent actions are drawn from the generator's prior, decoded and played
through the task; the measure is the distribution over goals of the best reward that the draws reach for that goal
(median and quartiles). It is a task-grounded check of a generator beside precision and recall: a latent space in
which some draw lands near every goal gives GenRL's search somewhere to start. Its cost, ``contexts x draws``
episodes and the seconds they took, is reported with it.

The goals are drawn with ``np.random.default_rng(seed)`` from the task's goal distribution, as
:func:`sb3_genrl.run.evaluate_on_goals` draws them; the default seed :data:`PRIOR_ROLLOUT_SEED` is neither the
final evaluations' :data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED` nor the tuning's
:data:`~sb3_genrl.hyperparams.TUNING_GOAL_SEED`, so the measure never sees the goals a policy is judged on. The latent
actions are drawn from a seed of their own spawned from ``seed``; they are clipped to GenRL's action box and played
through :meth:`sb3_genrl.wrappers.LatentActionWrapper.play_batch`, the fast path GenRL itself uses.

A task without the fast path (any episodic Gymnasium env that :class:`~sb3_genrl.wrappers.LatentActionWrapper` takes:
Gymnasium-Robotics' Fetch tasks, Reacher) is played through the wrapper's step path instead: its contexts are its reset
states of the seeds ``seed, seed + 1, ...``, and each draw is one episode from the reset of its context's seed. Where
the env reports ``info["is_success"]`` (the goal-conditioned envs), the share of contexts that some draw solves is
reported too: with a sparse 0/-1 reward, the best reward's median says little and that share says it all.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_genrl.checks import check_positive_int, check_seed
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.hyperparams import PRIOR_ROLLOUT_SEED
from sb3_genrl.task_ids import task_env_id
from sb3_genrl.vec_env import default_threads
from sb3_genrl.wrappers import LatentActionWrapper

DEFAULT_CONTEXTS = 64
DEFAULT_DRAWS = 16


@dataclasses.dataclass(frozen=True, eq=False)
class PriorRollout:
    """The best reward of ``draws`` prior draws for each of ``contexts`` goals.

    :param best: the best reward per goal, ``(contexts,)``
    :param draws: prior draws per goal
    :param seed: seed of the goals (and, spawned from it, of the draws)
    :param episodes: episodes played (``contexts x draws``)
    :param seconds: wall-clock seconds of the decoding and playing
    :param cpu_seconds: CPU seconds of this process for the same
    :param solved: per goal, whether some draw solved it (``info["is_success"]``); None where the env does not say
    """

    best: np.ndarray
    draws: int
    seed: int
    episodes: int
    seconds: float
    cpu_seconds: float
    solved: np.ndarray | None = None

    def summary(self) -> dict[str, Any]:
        """Median, quartiles and mean of the best reward per goal, with the sizes and the cost, and the share of goals
        solved by some draw where the env reports success (JSON-ready)."""
        q25, median, q75 = np.percentile(self.best, [25, 50, 75])
        success = {} if self.solved is None else {"prior_success": float(np.mean(self.solved))}
        return {
            "prior_median": float(median),
            "prior_q25": float(q25),
            "prior_q75": float(q75),
            "prior_mean": float(np.mean(self.best)),
            **success,
            "prior_contexts": len(self.best),
            "prior_draws": self.draws,
            "prior_seed": self.seed,
            "prior_episodes": self.episodes,
            "prior_seconds": self.seconds,
            "prior_cpu_seconds": self.cpu_seconds,
        }


def _latent_env(task: str | gym.Env | Callable[[], gym.Env], generator: TrajectoryGenerator) -> Any:
    if isinstance(task, gym.Env):
        env = task
    elif callable(task):  # a task from outside the package: a callable that makes its env
        env = task()
    else:
        env = gym.make(task_env_id(task))
    return LatentActionWrapper(env, generator)


def prior_rollout(
    generator: TrajectoryGenerator,
    task: str | gym.Env | Callable[[], gym.Env],
    *,
    contexts: int | np.ndarray = DEFAULT_CONTEXTS,
    draws: int = DEFAULT_DRAWS,
    seed: int = PRIOR_ROLLOUT_SEED,
    n_threads: int | None = None,
) -> PriorRollout:
    """The best reward that ``draws`` prior draws reach for each goal (see the module's description).

    :param generator: the trained generator
    :param task: a task name or Gymnasium id, or an env (with ``play_trajectories``: the fast path; else the step
        path, see the module's description), or a callable that makes the env
    :param contexts: how many goals to draw (the task's ``sample_goal``; the step path: reset seeds), or the goals
        themselves ``(G, goal_dim)`` (the fast path only)
    :param draws: prior draws per goal
    :param seed: seed of the goals; the draws come from a seed spawned from it
    :param n_threads: simulation threads of the fast path (default: all cores; the result does not depend on it; the
        step path plays in this process)
    :return: a :class:`PriorRollout`
    """
    check_positive_int(draws, "draws")
    check_seed(seed)
    env = _latent_env(task, generator)
    try:
        if not env.use_fast_path:
            return _step_path_rollout(env, generator, contexts, draws, seed)
        if np.ndim(contexts) == 0:
            check_positive_int(contexts, "contexts")
            rng = np.random.default_rng(seed)
            goals = np.array([env.unwrapped.sample_goal(rng) for _ in range(int(contexts))], dtype=np.float64)
        else:
            goals = np.asarray(contexts, dtype=np.float64)
            if goals.ndim != 2 or not len(goals):
                raise ValueError(f"contexts must be a count or goals of shape (G, goal_dim), got {goals.shape}")
        wall, cpu = time.perf_counter(), time.process_time()
        latent_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
        alphas = generator.sample_prior(len(goals) * draws, latent_rng)  # goal g plays draws g*draws .. (g+1)*draws-1
        threads = default_threads() if n_threads is None else n_threads
        rewards, _ = env.play_batch(alphas, np.repeat(goals, draws, axis=0), n_threads=threads)
        best = rewards.reshape(len(goals), draws).max(axis=1)
        return PriorRollout(best, draws, seed, len(goals) * draws, time.perf_counter() - wall, time.process_time() - cpu)
    finally:
        env.close()


def _step_path_rollout(env: Any, generator: TrajectoryGenerator, contexts: Any, draws: int, seed: int) -> PriorRollout:
    """:func:`prior_rollout` through ``env``'s step path: goal ``g`` is the reset state of seed ``seed + g``."""
    if np.ndim(contexts) != 0:
        raise ValueError(
            f"{type(env.unwrapped).__name__} has no fast path: its contexts are reset states, so contexts "
            f"must be a count, got an array of shape {np.shape(contexts)}"
        )
    count = check_positive_int(contexts, "contexts")
    wall, cpu = time.perf_counter(), time.process_time()
    latent_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
    alphas = generator.sample_prior(count * draws, latent_rng)  # goal g plays draws g*draws .. (g+1)*draws-1
    alphas = np.clip(alphas, env.action_space.low, env.action_space.high)
    rewards, successes = np.empty(count * draws), []
    for index, alpha in enumerate(alphas):
        env.reset(seed=seed + index // draws)
        _, rewards[index], _, _, info = env.step(alpha)
        successes.append(info.get("is_success"))
    best = rewards.reshape(count, draws).max(axis=1)
    solved = (
        None
        if any(success is None for success in successes)
        else np.asarray(successes, dtype=float).reshape(count, draws).max(axis=1) > 0
    )
    return PriorRollout(best, draws, seed, count * draws, time.perf_counter() - wall, time.process_time() - cpu, solved)
