"""The demonstration generator (paper section 6.1.4): a scripted expert perturbed by random joint-velocity changes.

The paper recorded a few kinesthetic demonstrations and made 40K episodes from them with random changes of the
joint velocities of different strengths and orientations. Here the expert is a family of smooth base motions
(:func:`sb3_genrl.envs.scripted.scripted_hit` for hockey, :func:`throw_motion` for basketball) with random
parameters (strength, direction or yaw; for basketball also timing), and the perturbation (:func:`perturbation`)
adds to its per-step joint position deltas (joint velocities times the control step) a few raised-cosine velocity
bumps, each on a random joint, at a random time, of random width, sign and size, the sizes scaled by one random
level per episode. Trajectories outside the action box or the joint ranges are redrawn before simulation (nothing
relies on the env's clipping); after simulation only valid episodes are kept: stable, no clipping, for hockey no
stick-table contact, for basketball a ball that comes down through the rim's height.

Every stored demonstration is a successful one: its goal is the point it reached (hindsight relabelling; the
randomly drawn goal it was simulated with is kept as ``sampled_goals``), so its terminal reward is ``-0.0``.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from sb3_genrl.envs import TASK_IDS
from sb3_genrl.envs.arm import JOINT_RANGE
from sb3_genrl.envs.base import ArmTaskEnv, default_threads
from sb3_genrl.envs.basketball import BASKETBALL_HORIZON, BasketballEnv
from sb3_genrl.envs.hockey import HOCKEY_GOAL_HIGH, HOCKEY_GOAL_LOW, HockeyEnv
from sb3_genrl.envs.scripted import bump, scripted_hit
from tqdm.auto import tqdm

# Perturbation sizes per joint (rad moved by one bump at level 1). They are small next to the base motions'
# strength and direction, so the demonstrations vary mainly along the task's factors (as a few demonstrations
# with changed joint velocities do) and a low-dimensional generator can capture them; the shoulder and elbow
# (which lower the hockey blade onto the table) get the smallest.
HOCKEY_PERTURBATION = np.array([0.04, 0.02, 0.04, 0.02, 0.05, 0.04, 0.05])
BASKETBALL_PERTURBATION = np.array([0.06, 0.04, 0.06, 0.04, 0.06, 0.04, 0.06])
# Control step at which the hit or throw starts. Hockey hits all start at one step: timing changes nothing in the
# outcome, and whole-step shifts split the demonstrations into one cluster per start step, which a 2-D generator then
# lays out as separate patches of its latent space (each patch covering part of the goal region), so the latent
# action that reaches a goal jumps between patches. Basketball throws keep a narrow window.
HOCKEY_SWING_START = 25
BASKETBALL_THROW_START = (28, 35)
# Hockey aims: a target drawn uniformly in the goal region widened by HOCKEY_AIM_MARGIN (m) on each side, hit from
# the puck's start at HOCKEY_PUCK_X with direction = the target's bearing and a strength for its distance, read
# off the measured distance (m) -> strength curve of scripted_hit.
HOCKEY_AIM_MARGIN = 0.08
HOCKEY_PUCK_X = 0.36
HOCKEY_DISTANCE_TO_STRENGTH = (np.array([0.19, 0.256, 0.301, 0.362, 0.43, 0.49, 0.549, 0.612, 0.676, 0.765, 0.84, 0.92,
                                         0.998, 1.079, 1.165, 1.252]),
                               np.array([0.6, 0.7, 0.75, 0.8, 0.9, 0.95, 1.0, 1.05, 1.1, 1.15, 1.25, 1.3, 1.35, 1.4, 1.45,
                                         1.5]))
BASKETBALL_YAW = np.pi / 2 + 0.15  # rad, either side
BASKETBALL_FAMILIES = (0.35, 0.45, 0.2)  # shares of shoulder-led long, elbow-led long and other throws
ACTION_MARGIN = 0.95  # trajectories use at most this share of the action box
JOINT_MARGIN = 0.05  # rad kept from each joint limit


def make_env(task: str, **kwargs: Any) -> ArmTaskEnv:
    """The task's env (unwrapped) by short name, ``"hockey"`` or ``"basketball"``, with constructor ``kwargs``."""
    if task == "hockey":
        return HockeyEnv(**kwargs)
    if task == "basketball":
        return BasketballEnv(**kwargs)
    raise ValueError(f"unknown task {task!r}; expected one of {sorted(TASK_IDS)}")


def throw_motion(*, yaw: float = 0.0, shoulder: float = 0.7, elbow: float = 0.3, wrist: float = 0.15,
                 duration: int = 4, throw_start: int = 30) -> np.ndarray:
    """A basketball throw with separate joint amplitudes: turn the base slowly by ``yaw``, then swing fast.

    Short swings (``duration`` 4) led by the shoulder throw far (up to about 9 m); slower swings and strong elbow
    or wrist motion lob the ball short.

    :param yaw: base rotation (rad), positive throws to the robot's left (positive y); spread over 18 steps so the
        ball stays in the cup
    :param shoulder: shoulder pitch travel of the swing (rad)
    :param elbow: elbow travel (rad)
    :param wrist: wrist pitch travel (rad)
    :param duration: control steps of the swing
    :param throw_start: control step at which the swing starts
    :return: ``(78, 7)`` joint position deltas
    """
    trajectory = np.zeros((BASKETBALL_HORIZON, 7))
    trajectory[:, 0] = bump(BASKETBALL_HORIZON, 1, 18, yaw)
    for joint, total in zip((1, 3, 5), (shoulder, elbow, wrist), strict=True):
        trajectory[:, joint] = bump(BASKETBALL_HORIZON, throw_start, duration, total)
    return trajectory


def perturbation(horizon: int, rng: np.random.Generator, scales: np.ndarray, *, max_bumps: int = 4,
                 durations: tuple[int, int] = (6, 30)) -> np.ndarray:
    """Random smooth joint-velocity changes, as per-step joint position deltas.

    :param horizon: control steps T
    :param rng: the random generator
    :param scales: ``(7,)`` largest joint travel (rad) of one bump per joint
    :param max_bumps: bumps drawn per trajectory, uniformly in ``1..max_bumps``
    :param durations: smallest and largest bump width (control steps)
    :return: ``(T, 7)`` deltas; each bump has a random joint, start, width and a travel uniform in
        ``[-level, level] * scales[joint]`` with one ``level ~ U(0, 1)`` per trajectory
    """
    out = np.zeros((horizon, 7))
    level = rng.uniform(0.0, 1.0)
    for _ in range(int(rng.integers(1, max_bumps + 1))):
        joint = int(rng.integers(7))
        duration = int(rng.integers(durations[0], durations[1] + 1))
        start = int(rng.integers(0, horizon - durations[0]))
        out[:, joint] += bump(horizon, start, duration, level * scales[joint] * rng.uniform(-1.0, 1.0))
    return out


def _hockey_base(rng: np.random.Generator) -> np.ndarray:
    target = rng.uniform(HOCKEY_GOAL_LOW - HOCKEY_AIM_MARGIN, HOCKEY_GOAL_HIGH + HOCKEY_AIM_MARGIN)
    offset = target - np.array([HOCKEY_PUCK_X, 0.0])
    strength = np.interp(np.linalg.norm(offset), *HOCKEY_DISTANCE_TO_STRENGTH) * rng.uniform(0.95, 1.05)
    return scripted_hit(strength=strength, direction=float(np.arctan2(-offset[1], offset[0])),
                        swing_start=HOCKEY_SWING_START)


def _basketball_base(rng: np.random.Generator) -> np.ndarray:
    yaw = rng.uniform(-BASKETBALL_YAW, BASKETBALL_YAW)
    throw_start = int(rng.integers(*BASKETBALL_THROW_START))
    family = rng.choice(3, p=BASKETBALL_FAMILIES)
    if family == 0:  # long throws led by the shoulder (they fall short beyond about 1.1 rad of yaw)
        return throw_motion(yaw=yaw, shoulder=rng.uniform(0.55, 1.05), elbow=rng.uniform(0.1, 0.5),
                            wrist=rng.uniform(0.02, 0.3), duration=4, throw_start=throw_start)
    if family == 1:  # long throws led by the elbow (they reach 7-8 m at every yaw)
        return throw_motion(yaw=yaw, shoulder=rng.uniform(0.35, 0.8), elbow=rng.uniform(0.85, 1.1),
                            wrist=rng.uniform(0.02, 0.3), duration=4, throw_start=throw_start)
    strength = rng.uniform(0.2, 1.4)  # everything else: slower swings of every strength
    return throw_motion(yaw=yaw, shoulder=strength * rng.uniform(0.8, 1.3), elbow=strength * rng.uniform(0.3, 1.2),
                        wrist=strength * rng.uniform(0.2, 0.6), duration=int(rng.integers(4, 10)), throw_start=throw_start)


_TASKS = {"hockey": (_hockey_base, HOCKEY_PERTURBATION), "basketball": (_basketball_base, BASKETBALL_PERTURBATION)}


def within_limits(trajectories: np.ndarray, home: np.ndarray, max_joint_delta: float = 0.5) -> np.ndarray:
    """Per trajectory: whether every delta is inside the action box and every command inside the joint ranges,
    each with a margin (:data:`ACTION_MARGIN`, :data:`JOINT_MARGIN`)."""
    in_box = np.abs(trajectories).max(axis=(1, 2)) <= ACTION_MARGIN * max_joint_delta
    commands = home + np.cumsum(trajectories, axis=1)
    in_range = np.all((commands >= JOINT_RANGE[:, 0] + JOINT_MARGIN) & (commands <= JOINT_RANGE[:, 1] - JOINT_MARGIN),
                      axis=(1, 2))
    return in_box & in_range


def sample_trajectories(task: str, n: int, rng: np.random.Generator, *, home: np.ndarray | None = None,
                        max_joint_delta: float = 0.5) -> np.ndarray:
    """Draw ``n`` perturbed expert trajectories (before simulation; see the module docstring).

    :param task: ``"hockey"`` or ``"basketball"``
    :param n: number of trajectories
    :param rng: the random generator (all draws come from it)
    :param home: the task's home pose (7,) for the joint-range check; made from the task's env when None
    :param max_joint_delta: the action bound (rad per step)
    :return: ``(n, T, 7)`` float32 joint position deltas, all inside the action box and joint ranges
    """
    if task not in _TASKS:
        raise ValueError(f"unknown task {task!r}; expected one of {sorted(_TASKS)}")
    if n < 0:
        raise ValueError(f"n must be non-negative, got {n}")
    base, scales = _TASKS[task]
    if home is None:
        home = make_env(task).home_qpos()
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


def is_valid(task: str, info: dict[str, Any]) -> bool:
    """Whether a simulated episode may be a demonstration: stable, unclipped, and for hockey without stick-table
    contact, for basketball with the ball coming down through the rim's height."""
    if info.get("unstable") or info.get("joint_limit_clipped"):
        return False
    if task == "hockey":
        return info.get("table_contacts", 1) == 0
    return info.get("crossings", 0) > 0


def make_demonstrations(task: str, episodes: int, out_dir: str | os.PathLike[str], *, seed: int = 0,
                        n_threads: int | None = None, progress_bar: bool = True, chunk: int = 256) -> Path:
    """Generate ``episodes`` valid demonstrations of ``task`` and write them as a Minari dataset in ``out_dir``.

    Trajectory ``k`` (and its sampled goal) is drawn from its own generator ``np.random.default_rng([seed, k])``;
    trajectories are simulated in chunks until enough are valid and the first ``episodes`` valid ones are kept. So
    the result depends on ``seed`` only (not on ``n_threads`` or ``chunk``), and a smaller set with the same seed
    is a prefix of a larger one. The dataset directory is written
    atomically (see :func:`sb3_genrl.data.write_dataset`), with a coverage report beside its ``data`` folder.

    :param task: ``"hockey"`` or ``"basketball"``
    :param episodes: number of demonstrations (paper: 40000)
    :param out_dir: the dataset directory to create (must not exist or be empty)
    :param seed: seed of every random draw
    :param n_threads: simulation threads (default: the available cores)
    :param progress_bar: show a tqdm progress bar
    :param chunk: trajectories drawn and simulated per round
    :return: the dataset directory
    """
    from sb3_genrl.envs.coverage import coverage_report

    import sb3_genrl
    from sb3_genrl.data import write_dataset

    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    out_dir = Path(out_dir)
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise ValueError(f"{str(out_dir)!r} already exists and is not an empty directory; choose another output path")
    env = make_env(task)
    n_threads = default_threads() if n_threads is None else int(n_threads)
    home = env.home_qpos()
    kept: dict[str, list[np.ndarray]] = {"actions": [], "joints": [], "reached": [], "sampled_goals": []}
    count = drawn = 0
    began = time.perf_counter()
    with tqdm(total=episodes, disable=not progress_bar, unit="episode", desc=f"{task} demonstrations") as bar:
        while count < episodes:
            if drawn >= 5000 and count == 0:
                raise RuntimeError(f"none of the first {drawn} {task} trajectories was valid")
            size = min(chunk, int(1.1 * (episodes - count)) + 4)
            rngs = [np.random.default_rng([seed, k]) for k in range(drawn, drawn + size)]
            actions = np.concatenate([sample_trajectories(task, 1, r, home=home, max_joint_delta=env.max_joint_delta)
                                      for r in rngs])
            goals = np.stack([env.sample_goal(r) for r in rngs])
            _, infos, joints = env.play_trajectories(actions, goals, n_threads=n_threads, return_joint_states=True)
            drawn += size
            valid = np.flatnonzero([is_valid(task, info) for info in infos])[: episodes - count]
            reached = np.array([infos[i]["reached"] for i in valid]).reshape(-1, 2)
            kept["actions"].append(actions[valid])
            kept["joints"].append(joints[valid])
            kept["reached"].append(reached)
            kept["sampled_goals"].append(goals[valid])
            count += len(valid)
            bar.update(len(valid))
    arrays = _episode_arrays(env, {key: np.concatenate(value) for key, value in kept.items()})
    genrl = {"task": task, "env_id": TASK_IDS[task], "horizon": env.horizon, "seed": int(seed),
             "version": sb3_genrl.__version__, "episodes": int(episodes), "drawn": int(drawn),
             "goal": "reached (hindsight: each demonstration's goal is the point it reached)",
             "observation": "goal xy, 7 joint positions, 7 joint velocities", "max_joint_delta": env.max_joint_delta,
             "seconds": round(time.perf_counter() - began, 1)}
    path = write_dataset(out_dir, arrays, dataset_id=f"genrl/{task}-v0", observation_space=env.observation_space,
                         action_space=env.action_space, genrl=genrl,
                         description=f"{episodes} perturbed scripted demonstrations of {TASK_IDS[task]} (sb3-genrl)")
    coverage_report(arrays["reached"], task, path)
    return path


def _episode_arrays(env: ArmTaskEnv, kept: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The stored arrays: observations with the reached point as goal, sparse rewards, terminal flags."""
    n, horizon = len(kept["actions"]), env.horizon
    goal = np.repeat(kept["reached"][:, None, :], horizon + 1, axis=1)
    observations = np.concatenate([goal, kept["joints"]], axis=2).astype(np.float32)
    rewards = np.zeros((n, horizon))
    rewards[:, -1] = -0.0  # minus the distance between the reached point and the goal, which is that point
    terminations = np.zeros((n, horizon), dtype=bool)
    terminations[:, -1] = True
    return {"observations": observations, "actions": kept["actions"].astype(np.float32), "rewards": rewards,
            "terminations": terminations, "truncations": np.zeros((n, horizon), dtype=bool),
            "reached": kept["reached"].astype(np.float64), "sampled_goals": kept["sampled_goals"].astype(np.float64)}
