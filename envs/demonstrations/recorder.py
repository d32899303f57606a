"""The demonstration recorder of any episodic Gymnasium env with an expert (a callable, observation -> action).

:func:`record_demonstrations` plays the expert closed loop from seeded resets of the task's env
(:func:`sb3_genrl.envs.external.make_task_env`), with the perturbation of the paper's demonstrations (smooth random
changes of the actions, :func:`smooth_noise`), and keeps an episode only when it succeeds and its actions, replayed open
loop from the same seeded reset, still succeed: GenRL plays a generator's trajectories open loop, so only such
trajectories can teach it. The share kept and the reasons for the others are recorded in the dataset's metadata.
The episodes are played in worker processes on all available cores by default, each on its own env; the dataset is the
same whatever their number.
"""

from __future__ import annotations

import concurrent.futures
import copy
import itertools
import multiprocessing
import os
import pickle
import time
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cloudpickle
import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces
from sb3_genrl.envs.control import default_threads
from sb3_genrl.envs.demonstrations.arm import refuse_existing_output
from sb3_genrl.envs.external import (
    check_reports_success,
    check_reproducible_reset,
    check_success_key,
    resolve_task,
    task_env_and_horizon,
    task_name,
)
from sb3_genrl.envs.motions import bump
from tqdm.auto import tqdm

import sb3_genrl
from sb3_genrl.checks import check_non_negative_float, check_output_dir, check_positive_int, check_seed
from sb3_genrl.data import write_dataset
from sb3_genrl.provenance import package_versions
from sb3_genrl.utils import folder_lock, same_observation

DEFAULT_NOISE = 0.3  # largest height of one bump, as a share of each action dimension's half-range
BUMP_DURATIONS = (6, 30)  # smallest and largest bump width (steps), as the arm's and Fetch's perturbations
FIRST_TRIES = 200  # episodes tried without any kept before the recorder gives up
CHUNK = 8  # most episodes a worker process plays in one go (fewer when there are few to keep)
# Below this many demonstrations, the default plays them in this process: a pool of worker processes takes seconds to
# start (each imports the package), more than so short a run gains. The dataset is the same either way.
SMALL_RUN = 100

MAIN_GUARD = (
    "the worker processes that play the episodes (n_threads > 1, the default on more than one core) import the script "
    'that started them: a script must call record_demonstrations or expert_horizon under `if __name__ == "__main__":`, '
    "as any script with SB3's SubprocVecEnv, or pass n_threads=1"
)

_WORKER: dict[str, Any] = {}  # in each worker process: what it plays (its job) and its env, made at its first chunk


def smooth_noise(
    horizon: int,
    rng: np.random.Generator,
    heights: np.ndarray,
    *,
    max_bumps: int = 4,
    durations: tuple[int, int] = BUMP_DURATIONS,
) -> np.ndarray:
    """Random smooth changes of the actions: the paper's perturbation (random changes of different strengths and
    directions) for any action space, as :func:`sb3_genrl.envs.demonstrations.arm.perturbation` makes for the arm.

    :param horizon: control steps T
    :param rng: the random generator
    :param heights: ``(M,)`` the largest height of one bump per action dimension (action units)
    :param max_bumps: bumps per trajectory, uniformly in ``1..max_bumps``
    :param durations: smallest and largest bump width (steps; cut to the horizon)
    :return: ``(T, M)`` additions to the actions: each bump a raised cosine on a random dimension, at a random step,
        of random width and of height uniform in ``[-level, level] * heights[dimension]``, with one ``level ~ U(0, 1)``
        per trajectory
    """
    out = np.zeros((horizon, len(heights)))
    level = rng.uniform(0.0, 1.0)
    shortest = min(durations[0], horizon)
    for _ in range(int(rng.integers(1, max_bumps + 1))):
        dimension = int(rng.integers(len(heights)))
        duration = int(rng.integers(shortest, max(shortest, min(durations[1], horizon)) + 1))
        start = int(rng.integers(0, horizon - shortest + 1))
        height = level * heights[dimension] * rng.uniform(-1.0, 1.0)
        out[:, dimension] += bump(horizon, start, duration, height * duration / 2.0)  # a raised cosine peaks at 2x its mean
    return out


def record_demonstrations(
    task: str | Callable[[], gym.Env],
    expert: Callable[[Any], np.ndarray] | None,
    episodes: int,
    out_dir: str | os.PathLike[str],
    *,
    seed: int = 0,
    noise: float | np.ndarray = DEFAULT_NOISE,
    horizon: int | None = None,
    success_key: str = "is_success",
    n_threads: int | None = None,
    progress_bar: bool = False,
) -> Path:
    """Record ``episodes`` demonstrations of an expert on any episodic Gymnasium env as a Minari dataset in ``out_dir``.

    Episode ``k`` draws its reset seed and its perturbation from ``np.random.default_rng([seed, k])``: the env is reset
    with that seed and the expert plays closed loop, each of its actions changed by :func:`smooth_noise` and clipped to
    the action space, for ``horizon`` steps (or until the episode ends; the rest of the trajectory is the hold action,
    zeros, as :class:`~sb3_genrl.LatentActionWrapper` plays after a trajectory). The episode is kept when its last step
    succeeds and its actions, replayed open loop from a reset with the same seed, succeed too (replayed in the env that
    GenRL plays, where the task records in another: Meta-World's replay ends at its first success, with the outcome of
    the training env, which runs on). Episodes are tried in
    order until ``episodes`` are kept, so the dataset depends on ``seed`` only, and a smaller set is a prefix of a
    larger one.

    With ``n_threads`` above 1 the episodes are played in that many worker processes (multiprocessing's
    ``forkserver`` context, ``spawn`` where there is none, as SB3's ``SubprocVecEnv``), each on its own env made as
    this process makes it, the episodes handed out in order in small chunks; this process keeps the first ``episodes``
    successes in episode order and counts the episodes as one process would (those played after the last one kept
    are dropped uncounted), so the dataset is the same, bit for bit, for any ``n_threads``. The task and the expert are
    sent to the workers with cloudpickle: an expert must therefore be a function of the observation alone (as it is in
    one process: an expert that keeps state from one episode to the next is not supported), and a task or an expert
    that cannot be pickled (one holding a lock, an open file or a simulator handle) is played in this process instead,
    with the same result. An error in a worker is raised here as a ``RuntimeError`` naming the episode and the error.
    The workers import the script that started them: a script must call this under ``if __name__ == "__main__":``, as
    any script with SB3's ``SubprocVecEnv`` (the workers refuse to start otherwise, saying so).

    Checked before any work and before ``out_dir`` is claimed: the arguments, the horizon (the env's
    ``max_episode_steps`` unless ``horizon`` is given; an env without one needs it), that ``reset(seed=s)`` twice gives
    the same observation, that the expert's action fits the action space, and that the env reports a success.

    The dataset (:func:`sb3_genrl.data.write_dataset`, written atomically) holds the kept episodes' actions ``(N, T,
    M)``, observations ``(N, T + 1, D)`` (a ``Dict`` observation flattened by ``gymnasium.spaces.flatten``), rewards
    and end flags; ``reached`` and ``sampled_goals`` are the last achieved and the first desired goal of a
    goal-conditioned env (``(N, 0)`` otherwise). Its metadata (``sb3_genrl.data.dataset_info``) records the reset seed
    of each kept episode (``reset_seeds``), the episodes ``tried``, ``kept_share``, and why the others were dropped:
    ``failed_closed_loop`` (the expert did not succeed), ``failed_open_loop`` (its replay did not succeed).

    :param task: a task name (:func:`~sb3_genrl.envs.external.resolve_task`: a Gymnasium id, ``metaworld/<name>``,
        ...) or a callable that makes the env
    :param expert: observation -> action (the raw observation of the env: an array, or a dict for a ``Dict`` space);
        None: the task's own expert (``metaworld/<name>``)
    :param episodes: demonstrations to keep
    :param out_dir: the dataset directory to create (must not exist or be empty)
    :param seed: seed of every random draw (reset seeds and perturbations)
    :param noise: the largest height of one bump, as a share of each action dimension's half-range (default 0.3; 0:
        the expert unperturbed), or an ``(M,)`` array of heights in action units (needed for an unbounded action space)
    :param horizon: control steps of a demonstration; None: the env's ``max_episode_steps``
    :param success_key: the info key of the env's success (default ``"is_success"``, falling back to ``"success"``)
    :param n_threads: worker processes that play the episodes (default: the available cores, or this process alone
        below :data:`SMALL_RUN` demonstrations; 1: in this process); the dataset does not depend on it
    :param progress_bar: show a tqdm progress bar (of the episodes kept)
    :return: the dataset directory
    """
    name = task_name(task)
    expert = task_expert(task, expert)
    check_positive_int(episodes, "episodes")
    check_seed(seed)
    check_success_key(success_key)
    if n_threads is not None:
        check_positive_int(n_threads, "n_threads")
    workers = (default_threads() if episodes >= SMALL_RUN else 1) if n_threads is None else int(n_threads)
    if workers > 1 and getattr(multiprocessing.current_process(), "_inheriting", False):  # Python's own test
        raise RuntimeError(MAIN_GUARD)  # in a worker process that re-imports the script: its stderr shows why
    env, steps = task_env_and_horizon(task, horizon, success_key, recording=True)
    replay_env = _replay_env(task, env, steps, success_key)
    heights = _noise_heights(env.action_space, noise)
    first_seed = _reset_seed(np.random.default_rng([seed, 0]))
    _probe(env, expert, first_seed, success_key, name)
    job = _worker_job(task, expert, steps, success_key, seed, heights) if workers > 1 else None
    out_dir = check_output_dir(out_dir, "out_dir").absolute()
    with folder_lock(out_dir, lock_file=out_dir.parent / f".{out_dir.name}.lock"):
        refuse_existing_output(out_dir)
        began = time.perf_counter()
        if job is None:
            kept, counts = _record(env, replay_env, expert, episodes, steps, seed, heights, progress_bar, name)
        else:
            kept, counts = _record_in_workers(job, workers, episodes, progress_bar, name)
        path = write_demonstrations(
            out_dir,
            env,
            task,
            kept,
            steps,
            counts=counts,
            success_key=success_key,
            description=f"{episodes} perturbed expert demonstrations of {name} whose open-loop replay succeeds (sb3-genrl)",
            algorithm_name=f"expert {expert_name(expert)} closed loop with smooth perturbations, replayed open loop",
            seed=int(seed),
            drawn=counts["tried"],
            noise=np.asarray(noise, dtype=np.float64).tolist(),
            expert=expert_name(expert),
            seconds=round(time.perf_counter() - began, 1),
        )
    env.close()
    if replay_env is not env:
        replay_env.close()
    return path


def _replay_env(task: str | Callable[[], gym.Env], env: gym.Env, steps: int, success_key: str) -> gym.Env:
    """The env a recorded episode's actions are replayed in: the one GenRL plays (``env`` itself, unless the task
    records in another env, :attr:`~sb3_genrl.envs.external.Task.recording_kwargs`). Meta-World's ends at the
    first success, so a replay stops there (its outcome is the training env's, whose success says solved so far)."""
    if callable(task) or not resolve_task(task).recording_kwargs:
        return env
    return task_env_and_horizon(task, steps, success_key)[0]


def task_expert(task: str | Callable[[], gym.Env], expert: Callable[[Any], np.ndarray] | None) -> Callable[[Any], Any]:
    """``expert``, or the task's own where it is None (``metaworld/<name>``'s scripted policy), checked callable.

    :raises ValueError: naming the task when it has no expert of the package's, or the type of a non-callable expert
    """
    if expert is None:
        make_expert = None if callable(task) else resolve_task(task).make_expert
        if make_expert is None:
            raise ValueError(f"task {task_name(task)!r} has no expert of the package's: give expert= (observation -> action)")
        expert = make_expert()
    if not callable(expert):
        raise ValueError(f"expert must be a callable observation -> action, got {type(expert).__name__}")
    return expert


def write_demonstrations(
    out_dir: Path,
    env: gym.Env,
    task: str | Callable[[], gym.Env],
    kept: list[dict[str, Any]],
    steps: int,
    *,
    counts: dict[str, int],
    success_key: str,
    description: str,
    algorithm_name: str,
    **extra: Any,
) -> Path:
    """Write kept episodes as the recorder's dataset (:func:`sb3_genrl.data.write_dataset`, atomically): the arrays
    of :func:`record_demonstrations` and its metadata's entries that do not depend on how the episodes were made.

    :param out_dir: the dataset directory to create
    :param env: the task's env that played them (its spaces shape the arrays)
    :param task: the task, as given (its name and Gymnasium id go to the metadata)
    :param kept: the kept episodes, each as :func:`play_episode` returns it, with its ``actions`` padded to ``steps``
        (:func:`pad_actions`) and its ``reset_seed``
    :param steps: the horizon T
    :param counts: ``tried``, ``failed_closed_loop`` and ``failed_open_loop`` episodes
    :param success_key: the info key of the env's success
    :param description: Minari's dataset description
    :param algorithm_name: Minari's ``algorithm_name``: what made the episodes
    :param extra: further metadata entries (how the episodes were made: ``seed``, ``expert``, ``source``, ...)
    :return: the dataset directory
    """
    name = task_name(task)
    arrays = _dataset_arrays(env, kept, steps)
    genrl = {
        "task": name,
        "env_id": None if callable(task) else resolve_task(task).env_id,
        "horizon": steps,
        "version": sb3_genrl.__version__,
        "mujoco": package_versions().get("mujoco"),
        "episodes": len(kept),
        "tried": counts["tried"],
        "kept_share": len(kept) / counts["tried"],
        "failed_closed_loop": counts["failed_closed_loop"],
        "failed_open_loop": counts["failed_open_loop"],
        "success_key": success_key,
        "reset_seeds": [episode["reset_seed"] for episode in kept],
        "observation": "the env's observation"
        + (", flattened by gymnasium.spaces.flatten" if not isinstance(env.observation_space, spaces.Box) else ""),
        "goal": "the env's own (no relabelling)",
        **extra,
    }
    return write_dataset(
        out_dir,
        arrays,
        dataset_id=f"genrl/{_dataset_name(name)}-v0",
        observation_space=spaces.Box(-np.inf, np.inf, shape=arrays["observations"].shape[2:], dtype=np.float32),
        action_space=env.action_space,
        genrl=genrl,
        description=description,
        algorithm_name=algorithm_name,
    )


def expert_name(expert: Callable[[Any], np.ndarray]) -> str:
    """How a dataset's metadata names an expert: ``module:qualified name`` of the function (or of a callable's class)."""
    name = getattr(expert, "__qualname__", None) or type(expert).__qualname__
    return f"{getattr(expert, '__module__', None) or type(expert).__module__}:{name}"


def _dataset_name(name: str) -> str:
    """A Minari dataset name made of the task's name: letters, digits and single dashes."""
    parts = "".join(c.lower() if c.isalnum() else " " for c in name).split()
    return "-".join(parts) or "task"


def _reset_seed(rng: np.random.Generator) -> int:
    return int(rng.integers(2**31))


def _noise_heights(action_space: spaces.Space, noise: float | np.ndarray) -> np.ndarray:
    """The bumps' largest heights in action units (see :func:`record_demonstrations`'s ``noise``)."""
    if not isinstance(action_space, spaces.Box) or len(action_space.shape) != 1:
        raise ValueError(f"the env's actions must be a Box of shape (M,) (per-step vectors), got {action_space}")
    if np.ndim(noise) == 0:
        share = check_non_negative_float(noise, "noise")
        half_range = (action_space.high.astype(np.float64) - action_space.low.astype(np.float64)) / 2.0
        if share > 0 and not np.all(np.isfinite(half_range)):
            raise ValueError(
                f"noise {share} is a share of the action space's half-range, but {action_space} is unbounded: give "
                f"noise as an array of {action_space.shape[0]} heights in action units"
            )
        return share * np.nan_to_num(half_range)
    heights = np.asarray(noise, dtype=np.float64)
    if heights.shape != action_space.shape or not np.all(np.isfinite(heights)) or np.any(heights < 0):
        raise ValueError(
            f"noise as heights must be {action_space.shape[0]} finite non-negative numbers (one per action dimension), "
            f"got {noise!r}"
        )
    return heights


def _expert_action(expert: Callable[[Any], np.ndarray], observation: Any, action_space: spaces.Box) -> np.ndarray:
    # the expert gets a copy: one that changes its observation in place (Meta-World's door-open-v3 policy shifts the
    # handle's position in it) would otherwise change the recorded episode's observations
    try:
        raw = expert(copy.deepcopy(observation))
    except Exception as error:  # the user's code: its error in one line, named as the expert's
        raise ValueError(
            f"the expert raised {type(error).__name__}: {error} (it is called as expert(observation) -> action)"
        ) from error
    if raw is None:
        raise ValueError(f"the expert returned None; expected an action of the env's action space {action_space}")
    action = np.asarray(raw, dtype=np.float64)
    if action.shape != action_space.shape or not np.all(np.isfinite(action)):
        raise ValueError(
            f"the expert returned {action.tolist()!r} (shape {action.shape}); expected {action_space.shape[0]} finite "
            "numbers, an action of the env's action space"
        )
    return action


def _probe(env: gym.Env, expert: Callable[[Any], np.ndarray], reset_seed: int, success_key: str, name: str) -> None:
    """Before any work: reproducible resets, the expert's action, a success in the step's info."""
    observation = check_reproducible_reset(env, reset_seed, name)
    action = _expert_action(expert, observation, env.action_space)
    _, _, _, _, info = env.step(np.clip(action, env.action_space.low, env.action_space.high).astype(env.action_space.dtype))
    check_reports_success(info, success_key, name)


def play_episode(
    env: gym.Env, reset_seed: int, steps: int, expert: Callable[[Any], np.ndarray] | None, actions: np.ndarray | None
) -> dict[str, Any]:
    """One episode from ``reset(seed=reset_seed)``: the expert closed loop (``actions`` adds to its actions) or
    ``actions`` open loop, each action clipped to the action space; stops when the episode ends.

    :param env: the task's env (:func:`~sb3_genrl.envs.external.make_task_env`)
    :param reset_seed: the reset's seed
    :param steps: the most steps to play
    :param expert: observation -> action, or None (``actions`` alone)
    :param actions: ``(steps, M)``: the actions (expert None), or the additions to the expert's
    :return: the ``observations`` (the reset's first), the ``actions`` played, the ``rewards``, ``terminated``,
        ``truncated`` and ``success`` (of the last step)
    """
    space = env.action_space
    observation, _ = env.reset(seed=int(reset_seed))
    observations, played, rewards, info = [observation], [], [], {}
    terminated = truncated = False
    for t in range(steps):
        if expert is None:
            action = actions[t]
        else:
            action = _expert_action(expert, observation, space) + actions[t]
        action = np.clip(action, space.low, space.high).astype(space.dtype)
        observation, reward, terminated, truncated, info = env.step(action)
        observations.append(observation)
        played.append(action)
        rewards.append(float(reward))
        if terminated or truncated:
            break
    return {
        "observations": observations,
        "actions": np.array(played),
        "rewards": rewards,
        "terminated": bool(terminated),
        "truncated": bool(truncated),
        "success": bool(info.get("is_success", False)),
    }


def pad_actions(actions: np.ndarray, steps: int, action_space: spaces.Box) -> np.ndarray:
    """``(T, M)`` actions, ``T <= steps``, followed by the hold action (zeros) up to ``steps``, in the space's dtype."""
    actions = np.asarray(actions, dtype=np.float64).reshape(-1, *action_space.shape)
    return np.concatenate([actions, np.zeros((steps - len(actions), *action_space.shape))]).astype(action_space.dtype)


def _episode(
    env: gym.Env,
    replay_env: gym.Env,
    expert: Callable[[Any], np.ndarray],
    steps: int,
    seed: int,
    k: int,
    heights: np.ndarray,
) -> dict[str, Any]:
    """Episode ``k`` (see :func:`record_demonstrations`): its closed-loop play in ``env`` and, when that succeeds, its
    open-loop replay in ``replay_env`` (:func:`_replay_env`). Returns the kept episode (the played one with its padded
    ``actions`` and its ``reset_seed``), or ``{"failed": reason}`` with the reason the metadata counts
    (``failed_closed_loop``, ``failed_open_loop``)."""
    rng = np.random.default_rng([seed, k])
    reset_seed = _reset_seed(rng)
    played = play_episode(env, reset_seed, steps, expert, smooth_noise(steps, rng, heights))
    if not played["success"]:
        return {"failed": "failed_closed_loop"}
    actions = pad_actions(played["actions"], steps, env.action_space)
    replayed = play_episode(replay_env, reset_seed, steps, None, actions)
    if not (replayed["success"] and same_observation(replayed["observations"][0], played["observations"][0])):
        return {"failed": "failed_open_loop"}
    return played | {"actions": actions, "reset_seed": reset_seed}


def _record(
    env: gym.Env,
    replay_env: gym.Env,
    expert: Callable[[Any], np.ndarray],
    episodes: int,
    steps: int,
    seed: int,
    heights: np.ndarray,
    progress_bar: bool,
    name: str,
) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """The episodes played one after the other in this process (``n_threads=1``)."""
    outcomes = (_episode(env, replay_env, expert, steps, seed, k, heights) for k in itertools.count())
    return _keep(outcomes, episodes, progress_bar, name)


def _record_in_workers(
    job: bytes, workers: int, episodes: int, progress_bar: bool, name: str
) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """The episodes played in ``workers`` worker processes (:func:`_play_chunk`), read here in episode order."""
    chunk = max(1, min(CHUNK, episodes // (2 * workers)))
    pool = worker_pool(job, workers, name)
    try:
        return _keep(_chunk_outcomes(pool, workers, chunk, name), episodes, progress_bar, name)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)  # the chunks not begun are dropped


def worker_pool(job: bytes, workers: int, name: str) -> concurrent.futures.ProcessPoolExecutor:
    """``workers`` worker processes for ``job`` (:func:`_worker_job`): each makes the task's env at its first call."""
    context = multiprocessing.get_context("forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn")
    return concurrent.futures.ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker, initargs=(job, name))


def in_worker(function: Callable[[gym.Env, Callable[[Any], np.ndarray], Any, int], Any], argument: Any) -> Any:
    """``function(env, expert, argument, steps)`` in a worker process of :func:`worker_pool`, with its env and its
    job's expert and steps (``function`` a module-level function, sent by reference)."""
    env, _, job = _worker_env(f"{function.__name__}({argument!r})")
    return function(env, job["expert"], argument, job["steps"])


def _keep(
    outcomes: Iterator[dict[str, Any]], episodes: int, progress_bar: bool, name: str
) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """The first ``episodes`` kept of the outcomes of episodes 0, 1, 2, ... (:func:`_episode`), and the counts of
    those tried up to the last one kept; gives up after :data:`FIRST_TRIES` episodes without one kept."""
    kept: list[dict[str, Any]] = []
    counts = {"tried": 0, "failed_closed_loop": 0, "failed_open_loop": 0}
    with tqdm(total=episodes, disable=not progress_bar, unit="episode", desc=f"{name} demonstrations") as bar:
        while len(kept) < episodes:
            if counts["tried"] >= FIRST_TRIES and not kept:
                raise RuntimeError(
                    f"none of the first {counts['tried']} demonstrations of {name} was kept ({counts['failed_closed_loop']}"
                    f" failed closed loop, {counts['failed_open_loop']} failed when replayed open loop): check the "
                    "expert, the noise and the success key"
                )
            outcome = next(outcomes)
            counts["tried"] += 1
            if "failed" in outcome:
                counts[outcome["failed"]] += 1
                continue
            kept.append(outcome)
            bar.update(1)
    return kept, counts


def _worker_job(
    task: str | Callable[[], gym.Env],
    expert: Callable[[Any], np.ndarray],
    steps: int,
    success_key: str,
    seed: int,
    heights: np.ndarray,
    recording: bool = True,
) -> bytes | None:
    """What a worker process needs to play episodes, cloudpickled (as SB3's ``SubprocVecEnv`` sends its env makers);
    None when the task or the expert cannot be pickled. A task's Gymnasium registration goes with it, so that a worker
    makes the same env where the id is registered only in this process (by a notebook, say)."""
    spec = None if callable(task) else gym.spec(resolve_task(task).env_id)
    job = {
        "task": task,
        "spec": spec,
        "expert": expert,
        "steps": steps,
        "success_key": success_key,
        "seed": seed,
        "heights": heights,
        "recording": recording,  # the env demonstrations are recorded in (Task.recording_kwargs)
    }
    try:
        return cloudpickle.dumps(job)
    except Exception:  # a lock, an open file, a simulator handle: played in this process instead, with the same result
        return None


def _start_worker(job: bytes, name: str) -> None:
    """A worker process's start: one torch thread (an expert may be a network), its job kept for its first chunk."""
    th.set_num_threads(1)
    _WORKER.update(pickled=job, name=name)


def _worker_env(what: str) -> tuple[gym.Env, gym.Env, dict[str, Any]]:
    """In a worker process: the task's env and the env its episodes are replayed in (:func:`_replay_env`), made at the
    first call (``what`` names the work, for an env that cannot be made), and the job."""
    if "env" not in _WORKER:
        try:
            job = pickle.loads(_WORKER["pickled"])
            if job["spec"] is not None:
                gym.registry.setdefault(job["spec"].id, job["spec"])
            env, _ = task_env_and_horizon(job["task"], job["steps"], job["success_key"], recording=job["recording"])
            replay_env = _replay_env(job["task"], env, job["steps"], job["success_key"]) if job["recording"] else env
        except Exception as error:
            raise RuntimeError(
                f"a worker process could not make the env of {_WORKER['name']} for {what}: {type(error).__name__}: {error}"
            ) from error
        _WORKER.update(env=env, replay_env=replay_env, job=job)
    return _WORKER["env"], _WORKER["replay_env"], _WORKER["job"]


def _play_chunk(start: int, stop: int) -> list[dict[str, Any]]:
    """Episodes ``start`` to ``stop - 1`` (:func:`_episode`), in a worker process."""
    env, replay_env, job = _worker_env(f"episodes {start} to {stop - 1}")
    outcomes = []
    for k in range(start, stop):
        try:
            outcomes.append(_episode(env, replay_env, job["expert"], job["steps"], job["seed"], k, job["heights"]))
        except Exception as error:
            raise RuntimeError(
                f"episode {k} of {_WORKER['name']} (seed {job['seed']}) failed in a worker process: "
                f"{type(error).__name__}: {error}"
            ) from error
    return outcomes


def _chunk_outcomes(pool: concurrent.futures.Executor, workers: int, chunk: int, name: str) -> Iterator[dict[str, Any]]:
    """The outcomes of episodes 0, 1, 2, ..., played ``chunk`` at a time by the pool's workers (two chunks a worker
    handed out ahead), in episode order."""
    pending: deque[tuple[int, concurrent.futures.Future]] = deque()
    for start in itertools.count(0, chunk):
        pending.append((start, pool.submit(_play_chunk, start, start + chunk)))
        if len(pending) < 2 * workers:
            continue
        first, future = pending.popleft()
        try:
            outcomes = future.result()
        except concurrent.futures.process.BrokenProcessPool as error:  # killed (out of memory), crashed, or never started
            raise RuntimeError(
                f"a worker process ended abruptly while it played episodes {first} to {first + chunk - 1} of {name} (its "
                f"error, if it had one, is above). Where it could not start: {MAIN_GUARD}"
            ) from error
        yield from outcomes


def _dataset_arrays(env: gym.Env, kept: list[dict[str, Any]], steps: int) -> dict[str, np.ndarray]:
    """The stored arrays (:mod:`sb3_genrl.data.minari_io`): an episode that ended early is padded with its last
    observation, zero rewards and no further end flags."""
    space = env.observation_space
    goal_env = isinstance(space, spaces.Dict) and {"achieved_goal", "desired_goal"} <= set(space.spaces)
    n = len(kept)
    observations, rewards = [], np.zeros((n, steps))
    terminations, truncations = np.zeros((n, steps), dtype=bool), np.zeros((n, steps), dtype=bool)
    reached, sampled = [], []
    for i, episode in enumerate(kept):
        flat = [np.asarray(spaces.flatten(space, o), dtype=np.float32) for o in episode["observations"]]
        observations.append(np.stack(flat + [flat[-1]] * (steps + 1 - len(flat))))
        played = len(episode["rewards"])
        rewards[i, :played] = episode["rewards"]
        terminations[i, played - 1] = episode["terminated"]
        truncations[i, played - 1] = episode["truncated"] or not episode["terminated"]
        if goal_env:
            reached.append(episode["observations"][-1]["achieved_goal"])
            sampled.append(episode["observations"][0]["desired_goal"])
    goal_shape = (n, 0) if not goal_env else (n, -1)
    return {
        "observations": np.stack(observations),
        "actions": np.stack([episode["actions"] for episode in kept]).astype(np.float32),
        "rewards": rewards,
        "terminations": terminations,
        "truncations": truncations,
        "reached": np.asarray(reached, dtype=np.float64).reshape(goal_shape),
        "sampled_goals": np.asarray(sampled, dtype=np.float64).reshape(goal_shape),
    }
