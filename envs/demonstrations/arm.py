"""The demonstration generator (paper section 6.1.4): a scripted expert perturbed by random joint-velocity changes.

The paper recorded a few kinesthetic demonstrations and made 40K episodes from them with random changes of the
joint velocities of different strengths and orientations. Here the expert is each task's family of smooth base
motions with random parameters (:attr:`TaskSpec.sample_expert <sb3_genrl.envs.spec.TaskSpec>`, e.g. a hockey hit of
random strength and direction), and the perturbation (:func:`perturbation`) adds to its per-step joint position
deltas (joint velocities times the control step) a few raised-cosine velocity bumps, each on a random joint, at a
random time, of random width, sign and size, the sizes scaled by the task's ``perturbation_scales`` and one random
level per episode. Trajectories outside the action box or the joint ranges are redrawn before simulation (nothing
relies on the env's clipping); after simulation only valid episodes are kept (:func:`is_valid`): stable, no
clipping, and valid for the task (e.g. no stick-table contact in hockey).

Every stored demonstration is a successful one: its goal is the point it reached (hindsight relabelling; the
randomly drawn goal it was simulated with is kept as ``sampled_goals``), so its terminal reward is ``-0.0``.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from sb3_genrl.envs.arm import JOINT_RANGE
from sb3_genrl.envs.base import ArmTaskEnv
from sb3_genrl.envs.control import default_threads
from sb3_genrl.envs.coverage import coverage_report
from sb3_genrl.envs.motions import bump
from sb3_genrl.envs.registry import get_task
from sb3_genrl.envs.spec import TaskSpec
from tqdm.auto import tqdm

import sb3_genrl
from sb3_genrl.checks import check_output_dir, check_positive_int, check_seed
from sb3_genrl.data import dataset_info, write_dataset
from sb3_genrl.provenance import package_versions
from sb3_genrl.utils import folder_lock

ACTION_MARGIN = 0.95  # trajectories use at most this share of the action box
JOINT_MARGIN = 0.05  # rad kept from each joint limit


def perturbation(
    horizon: int, rng: np.random.Generator, scales: np.ndarray, *, max_bumps: int = 4, durations: tuple[int, int] = (6, 30)
) -> np.ndarray:
    """Random smooth joint-velocity changes, as per-step joint position deltas.

    :param horizon: control steps T
    :param rng: the random generator
    :param scales: ``(M,)`` largest travel of one bump per action dimension (rad for the arm's 7 joints)
    :param max_bumps: bumps drawn per trajectory, uniformly in ``1..max_bumps``
    :param durations: smallest and largest bump width (control steps)
    :return: ``(T, M)`` deltas; each bump has a random joint, start, width and a travel uniform in
        ``[-level, level] * scales[joint]`` with one ``level ~ U(0, 1)`` per trajectory
    """
    out = np.zeros((horizon, len(scales)))
    level = rng.uniform(0.0, 1.0)
    for _ in range(int(rng.integers(1, max_bumps + 1))):
        joint = int(rng.integers(len(scales)))
        duration = int(rng.integers(durations[0], durations[1] + 1))
        start = int(rng.integers(0, horizon - durations[0]))
        out[:, joint] += bump(horizon, start, duration, level * scales[joint] * rng.uniform(-1.0, 1.0))
    return out


def within_limits(trajectories: np.ndarray, home: np.ndarray, max_joint_delta: float = 0.5) -> np.ndarray:
    """Per trajectory: whether every delta is inside the action box and every command inside the joint ranges,
    each with a margin (:data:`ACTION_MARGIN`, :data:`JOINT_MARGIN`)."""
    in_box = np.abs(trajectories).max(axis=(1, 2)) <= ACTION_MARGIN * max_joint_delta
    commands = home + np.cumsum(trajectories, axis=1)
    in_range = np.all(
        (commands >= JOINT_RANGE[:, 0] + JOINT_MARGIN) & (commands <= JOINT_RANGE[:, 1] - JOINT_MARGIN), axis=(1, 2)
    )
    return in_box & in_range


def sample_trajectories(
    task: str | TaskSpec, n: int, rng: np.random.Generator, *, home: np.ndarray | None = None, max_joint_delta: float = 0.5
) -> np.ndarray:
    """Draw ``n`` perturbed expert trajectories (before simulation; see the module docstring).

    :param task: a task name from :data:`sb3_genrl.envs.TASKS` (or its spec)
    :param n: number of trajectories
    :param rng: the random generator (all draws come from it)
    :param home: the task's home pose (7,) for the joint-range check; made from the task's env when None
    :param max_joint_delta: the action bound (rad per step)
    :return: ``(n, T, 7)`` float32 joint position deltas, all inside the action box and joint ranges
    """
    spec = get_task(task)
    if n < 0:
        raise ValueError(f"n must be non-negative, got {n}")
    base, scales = spec.sample_expert, spec.perturbation_scales
    if home is None:
        home = spec.make_env().home_qpos()
    out: list[np.ndarray] = []
    count = 0
    while count < n:
        drawn = []
        for _ in range(n - count):
            motion = base(rng)
            drawn.append(motion + perturbation(len(motion), rng, scales))
        batch = np.stack(drawn).astype(np.float32)  # what is stored is exactly what is simulated
        batch = batch[within_limits(batch.astype(np.float64), home, max_joint_delta)]
        out.append(batch)
        count += len(batch)
    return np.concatenate(out)[:n] if out else np.zeros((0, 0, 7), dtype=np.float32)


def is_valid(task: str | TaskSpec, info: dict[str, Any]) -> bool:
    """Whether a simulated episode may be a demonstration: stable, unclipped, and valid for the task
    (:attr:`TaskSpec.is_valid <sb3_genrl.envs.spec.TaskSpec>`).

    :param task: a task name from :data:`sb3_genrl.envs.TASKS` (or its spec)
    :param info: the episode's final info
    """
    if info.get("unstable") or info.get("joint_limit_clipped"):
        return False
    return bool(get_task(task).is_valid(info))


def make_demonstrations(
    task: str | TaskSpec,
    episodes: int,
    out_dir: str | os.PathLike[str],
    *,
    seed: int = 0,
    n_threads: int | None = None,
    progress_bar: bool = True,
    chunk: int = 256,
) -> Path:
    """Generate ``episodes`` valid demonstrations of ``task`` and write them as a Minari dataset in ``out_dir``.

    Trajectory ``k`` (and its sampled goal) is drawn from its own generator ``np.random.default_rng([seed, k])``;
    trajectories are simulated in chunks until enough are valid and the first ``episodes`` valid ones are kept. So
    the result depends on ``seed`` only (not on ``n_threads`` or ``chunk``), and a smaller set with the same seed
    is a prefix of a larger one. The dataset directory is written
    atomically (see :func:`sb3_genrl.data.write_dataset`) together with its coverage report (``coverage.json`` and
    ``coverage.png`` beside its ``data`` folder), so a dataset is never visible without its report. While it runs,
    the sibling lock file ``.NAME.lock`` keeps a second writer of the same directory out
    (:func:`sb3_genrl.utils.folder_lock`); temporary directories left by a killed writer are removed.

    :param task: a task name from :data:`sb3_genrl.envs.TASKS` (or its spec)
    :param episodes: number of demonstrations (paper: 40000)
    :param out_dir: the dataset directory to create (must not exist or be empty)
    :param seed: seed of every random draw
    :param n_threads: simulation threads (default: the available cores)
    :param progress_bar: show a tqdm progress bar
    :param chunk: trajectories drawn and simulated per round
    :return: the dataset directory
    """
    spec = get_task(task)
    check_positive_int(episodes, "episodes")
    check_seed(seed)
    check_positive_int(chunk, "chunk")
    if n_threads is not None:
        check_positive_int(n_threads, "n_threads")
    out_dir = check_output_dir(out_dir, "out_dir").absolute()
    with folder_lock(out_dir, lock_file=out_dir.parent / f".{out_dir.name}.lock"):
        refuse_existing_output(out_dir)
        return _make_demonstrations(spec, episodes, out_dir, seed, n_threads, progress_bar, chunk)


def refuse_existing_output(out_dir: Path) -> None:
    """Raise unless ``out_dir`` is missing or an empty directory, saying what is in the way (``genrl demos`` checks
    its ``--out`` with it before any work).

    :param out_dir: the dataset directory to create
    """
    if not out_dir.exists() or (out_dir.is_dir() and not any(out_dir.iterdir())):
        return
    try:
        info = dataset_info(out_dir)
    except ValueError:
        raise ValueError(
            f"{str(out_dir)!r} already exists and is not an empty directory; choose another output path"
        ) from None
    held = f"{info.get('episodes')} {info.get('task')} demonstrations, seed {info.get('seed')}"
    if not (out_dir / "coverage.json").is_file():
        raise ValueError(
            f"{str(out_dir)!r} already exists: it holds a dataset ({held}) without its coverage report, "
            "left by an interrupted run of an older sb3-genrl version, which wrote the report after the "
            "dataset. Delete the folder and rerun, or add the report with "
            "sb3_genrl.envs.coverage.coverage_report(path, None, path)"
        )
    raise ValueError(
        f"{str(out_dir)!r} already exists and holds a complete dataset ({held}); choose another output "
        "path, or delete it to make it again"
    )


def _make_demonstrations(
    spec: TaskSpec, episodes: int, out_dir: Path, seed: int, n_threads: int | None, progress_bar: bool, chunk: int
) -> Path:
    task = spec.name
    began = time.perf_counter()
    n_threads = default_threads() if n_threads is None else int(n_threads)
    if spec.demonstrations is not None:  # a task with its own (not an ArmTaskEnv)
        arrays, drawn, described = spec.demonstrations(spec, episodes, seed, n_threads, progress_bar)
        observation_space, action_space, details = (
            described["observation_space"],
            described["action_space"],
            {"observation": described["observation"]},
        )
    else:
        env = spec.make_env()
        kept, drawn = _valid_episodes(spec, env, episodes, seed, n_threads, chunk, progress_bar)
        arrays = _episode_arrays(env, kept)
        observation_space, action_space = env.observation_space, env.action_space
        details = {"observation": "goal xy, 7 joint positions, 7 joint velocities", "max_joint_delta": env.max_joint_delta}
    genrl = {
        "task": task,
        "env_id": spec.env_id,
        "horizon": spec.horizon,
        "seed": int(seed),
        "version": sb3_genrl.__version__,
        "mujoco": package_versions()["mujoco"],
        "episodes": int(episodes),
        "drawn": int(drawn),
        "goal": "reached (hindsight: each demonstration's goal is the point it reached)",
        **spec.demonstration_recipe,
        **details,
        "seconds": round(time.perf_counter() - began, 1),
    }
    return write_dataset(
        out_dir,
        arrays,
        dataset_id=f"genrl/{task}-v0",
        observation_space=observation_space,
        action_space=action_space,
        genrl=genrl,
        description=f"{episodes} perturbed scripted demonstrations of {spec.env_id} (sb3-genrl)",
        extra_files=lambda tmp: coverage_report(arrays["reached"][:, :2], spec, tmp, final_dir=out_dir),
    )


def _valid_episodes(
    spec: TaskSpec, env: ArmTaskEnv, episodes: int, seed: int, n_threads: int, chunk: int, progress_bar: bool
) -> tuple[dict[str, np.ndarray], int]:
    """Draw and simulate trajectories in chunks until ``episodes`` are valid (see :func:`make_demonstrations`).

    :return: the valid episodes' ``actions``, ``joints``, ``reached`` and ``sampled_goals``, and the number drawn
    """
    home = env.home_qpos()
    kept: dict[str, list[np.ndarray]] = {"actions": [], "joints": [], "reached": [], "sampled_goals": []}
    count = drawn = 0
    with tqdm(total=episodes, disable=not progress_bar, unit="episode", desc=f"{spec.name} demonstrations") as bar:
        while count < episodes:
            if drawn >= 5000 and count == 0:
                raise RuntimeError(f"none of the first {drawn} {spec.name} trajectories was valid")
            size = min(chunk, int(1.1 * (episodes - count)) + 4)
            rngs = [np.random.default_rng([seed, k]) for k in range(drawn, drawn + size)]
            actions = np.concatenate(
                [sample_trajectories(spec, 1, r, home=home, max_joint_delta=env.max_joint_delta) for r in rngs]
            )
            goals = np.stack([env.sample_goal(r) for r in rngs])
            _, infos, joints = env.play_trajectories(actions, goals, n_threads=n_threads, return_joint_states=True)
            drawn += size
            valid = np.flatnonzero([is_valid(spec, info) for info in infos])[: episodes - count]
            kept["actions"].append(actions[valid])
            kept["joints"].append(joints[valid])
            kept["reached"].append(np.array([infos[i]["reached"] for i in valid]).reshape(-1, 2))
            kept["sampled_goals"].append(goals[valid])
            count += len(valid)
            bar.update(len(valid))
    return {key: np.concatenate(value) for key, value in kept.items()}, drawn


def _episode_arrays(env: ArmTaskEnv, kept: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The stored arrays: observations with the reached point as goal, sparse rewards, terminal flags."""
    n, horizon = len(kept["actions"]), env.horizon
    goal = np.repeat(kept["reached"][:, None, :], horizon + 1, axis=1)
    observations = np.concatenate([goal, kept["joints"]], axis=2).astype(np.float32)
    rewards = np.zeros((n, horizon))
    rewards[:, -1] = -0.0  # minus the distance between the reached point and the goal, which is that point
    terminations = np.zeros((n, horizon), dtype=bool)
    terminations[:, -1] = True
    return {
        "observations": observations,
        "actions": kept["actions"].astype(np.float32),
        "rewards": rewards,
        "terminations": terminations,
        "truncations": np.zeros((n, horizon), dtype=bool),
        "reached": kept["reached"].astype(np.float64),
        "sampled_goals": kept["sampled_goals"].astype(np.float64),
    }
