"""The Fetch tasks' demonstrations, the open-loop success of their scripted experts, and a policy's success rate.

Gymnasium-Robotics' Fetch envs have no open-loop fast path (the mocap weld follows the gripper's own position), so
each episode is stepped through the env; the demonstrations are played in worker processes (``n_threads``), each on
its own env. Demonstration ``k`` (its reset state, aim and perturbation) is drawn from ``np.random.default_rng([seed,
k])``, so the set depends on ``seed`` only, as the arm tasks' (:func:`sb3_genrl.envs.demonstrations.make_demonstrations`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing
from math import comb
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces
from sb3_genrl.envs.demonstrations.arm import perturbation
from sb3_genrl.envs.fetch import FAMILIES, FETCH_HORIZON, GRIPPER_GAIN, PERTURBATION, STEP_METRES, is_valid
from sb3_genrl.envs.fetch_mujoco import fix_joint_helpers
from sb3_genrl.envs.registry import get_task
from sb3_genrl.envs.spec import TaskSpec
from tqdm.auto import tqdm

from sb3_genrl.wrappers import LatentActionWrapper

_ENVS: dict[str, gym.Env] = {}  # one env per task in each worker process


def _env(env_id: str) -> gym.Env:
    if env_id not in _ENVS:
        fix_joint_helpers()  # also when Gymnasium-Robotics registered its own ids first (imported before sb3_genrl)
        _ENVS[env_id] = gym.make(env_id)
    return _ENVS[env_id]


def play_expert(
    env_id: str, actions: np.ndarray | None, reset_seed: int, aim: np.ndarray | None, rng: np.random.Generator | None = None
) -> dict[str, Any]:
    """Reset the env with ``reset_seed`` and play the expert's trajectory (or ``actions``) open-loop.

    :param env_id: a Fetch id
    :param actions: the ``(50, 4)`` actions to play, or None: the expert's for ``aim`` (None: the env's own goal)
        with a perturbation drawn from ``rng`` when given
    :param reset_seed: the reset's seed
    :param aim: where the expert aims; None: the env's desired goal
    :param rng: draws the perturbation (None: none)
    :return: ``actions``, ``observations (51, 3 + obs_dim)`` (achieved goal at the end, then the observation),
        ``achieved (51, 3)``, ``infos``, ``aim``, ``aim_distance``, ``on_table``, ``is_success`` (for the env's goal)
    """
    env = _env(env_id)
    family = next(family for family in FAMILIES.values() if family.env_id == env_id)
    obs, _ = env.reset(seed=int(reset_seed))
    task = env.unwrapped
    aim = np.asarray(obs["desired_goal"] if aim is None else aim, dtype=np.float64)
    if actions is None:
        actions = family.expert(obs["observation"], aim)
        if rng is not None:
            actions = actions + perturbation(FETCH_HORIZON, rng, PERTURBATION / (STEP_METRES * GRIPPER_GAIN))
        actions = np.clip(actions, -1.0, 1.0).astype(np.float32)  # what is stored is exactly what is played
    observations, achieved, infos = [obs["observation"]], [obs["achieved_goal"]], []
    for action in actions:
        obs, _, _, _, info = env.step(action)
        observations.append(obs["observation"])
        achieved.append(obs["achieved_goal"])
        infos.append(info)
    achieved_array = np.array(achieved, dtype=np.float64)
    on_table = not task.has_object or bool(achieved_array[-1, 2] > task.height_offset - 0.02)
    return {
        "actions": np.asarray(actions, dtype=np.float32),
        "observations": np.array(observations),
        "achieved": achieved_array,
        "infos": infos,
        "aim": aim,
        "on_table": on_table,
        "aim_distance": float(np.linalg.norm(achieved_array[-1] - aim)),
        "is_success": bool(infos[-1]["is_success"]),
    }


def _demonstration(env_id: str, seed: int, k: int) -> dict[str, Any]:
    """Demonstration ``k``: a random reset state, a random aim over the goal region, the perturbed expert's play."""
    rng = np.random.default_rng([seed, k])
    reset_seed = int(rng.integers(2**31))
    family = next(family for family in FAMILIES.values() if family.env_id == env_id)
    aim = family.sample_aim(rng, _env(env_id).unwrapped)  # the env's constants: the gripper's start, the table
    return play_expert(env_id, None, reset_seed, aim, rng) | {"reset_seed": reset_seed}


def _play_chunk(env_id: str, seed: int, start: int, stop: int) -> list[dict[str, Any] | None]:
    """Demonstrations ``start..stop - 1``, each the episode's arrays when valid, else None."""
    out: list[dict[str, Any] | None] = []
    for k in range(start, stop):
        played = _demonstration(env_id, seed, k)
        if not is_valid(played):
            out.append(None)
            continue
        reached = played["achieved"][-1]
        rewards = [
            float(_env(env_id).unwrapped.compute_reward(a, reached, info))
            for a, info in zip(played["achieved"][1:], played["infos"], strict=True)
        ]
        goal = np.repeat(reached[None], FETCH_HORIZON + 1, axis=0)
        out.append(
            {
                "observations": np.concatenate([goal, played["observations"]], axis=1).astype(np.float32),
                "actions": played["actions"],
                "rewards": np.array(rewards),
                "reached": reached,
                "sampled_goals": played["aim"],
            }
        )
    return out


def make_arrays(
    spec: TaskSpec, episodes: int, seed: int, n_threads: int, progress_bar: bool, chunk: int = 64
) -> tuple[dict[str, np.ndarray], int, dict[str, Any]]:
    """``episodes`` valid demonstrations of a Fetch task (see the module docstring), as the dataset's arrays.

    :return: the arrays of :mod:`sb3_genrl.data.minari_io` (``reached`` and ``sampled_goals`` ``(N, 3)``), the number
        of trajectories drawn, and the dataset's spaces and description (``observation_space``, ``action_space``,
        ``observation``)
    """
    kept: list[dict[str, Any]] = []
    drawn = 0
    chunk = min(chunk, episodes + 4)
    pool = (
        concurrent.futures.ProcessPoolExecutor(n_threads, mp_context=multiprocessing.get_context("spawn"))
        if n_threads > 1
        else None
    )
    play = map if pool is None else pool.map
    with (
        pool or contextlib.nullcontext(),
        tqdm(total=episodes, disable=not progress_bar, unit="episode", desc=f"{spec.name} demonstrations") as bar,
    ):
        while len(kept) < episodes:
            if drawn >= 2000 and not kept:
                raise RuntimeError(f"none of the first {drawn} {spec.name} trajectories was valid")
            starts = range(drawn, drawn + chunk * n_threads, chunk)
            for played in play(_play_chunk, *zip(*[(spec.env_id, seed, s, s + chunk) for s in starts], strict=True)):
                valid = [episode for episode in played if episode is not None][: episodes - len(kept)]
                kept += valid
                bar.update(len(valid))
            drawn += chunk * n_threads
    arrays = {key: np.stack([episode[key] for episode in kept]) for key in kept[0]}
    n = len(kept)
    terminations = np.zeros((n, FETCH_HORIZON), dtype=bool)
    terminations[:, -1] = True
    arrays.update(terminations=terminations, truncations=np.zeros((n, FETCH_HORIZON), dtype=bool))
    dim = arrays["observations"].shape[-1]
    return (
        arrays,
        drawn,
        {
            "observation_space": spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32),
            "action_space": spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32),
            "observation": "reached goal (the achieved goal at the end), then the env's observation",
        },
    )


def expert_success(task: str | TaskSpec, episodes: int, seed: int) -> dict[str, float]:
    """The scripted expert, aimed at the env's own goal and unperturbed, played open-loop from ``episodes`` random
    reset states (seeds ``seed, seed + 1, ...``): its success rate and median final distance (m)."""
    spec = get_task(task)
    played = [play_expert(spec.env_id, None, seed + i, None) for i in range(episodes)]
    return {
        "episodes": episodes,
        "success_rate": float(np.mean([p["is_success"] for p in played])),
        "median_distance": float(np.median([p["aim_distance"] for p in played])),
    }


def evaluate_success(model: Any, task: str | TaskSpec, episodes: int = 100, seed: int = 0) -> dict[str, Any]:
    """A GenRL policy's deterministic latent actions played from ``episodes`` reset states (seeds ``seed, seed + 1,
    ...``) of a goal-conditioned task: the success rate (``info["is_success"]`` at the last step) and the final
    distances to the goals (m).

    :param model: a GenRL model with its generator
    :param task: a task name or Gymnasium id
    :param episodes: reset states
    :param seed: the first reset's seed
    """
    if model.generator is None:
        raise ValueError("this GenRL model has no generator: pass generator= to GenRL.load()")
    fix_joint_helpers()
    env = LatentActionWrapper(gym.make(get_task(task).env_id), model.generator)
    successes, distances = [], []
    for i in range(episodes):
        context, _ = env.reset(seed=seed + i)
        _, _, _, _, info = env.step(model.predict(context, deterministic=True)[0])
        task_env = env.unwrapped
        successes.append(float(info["is_success"]))
        distances.append(float(np.linalg.norm(task_env._get_obs()["achieved_goal"] - task_env.goal)))
    env.close()
    return {
        "episodes": episodes,
        "seed": seed,
        "success_rate": float(np.mean(successes)),
        "successes": successes,
        "distances": distances,
    }


def _replay_chunk(
    env_id: str, actions: np.ndarray, reset_seeds: list[int], aims: list[np.ndarray | None]
) -> list[tuple[bool, float]]:
    """Play each of ``actions`` open-loop from its reset seed: whether it solved the env's goal, and its distance to
    its aim (None: the env's goal)."""
    played = [play_expert(env_id, tau, seed, aim) for tau, seed, aim in zip(actions, reset_seeds, aims, strict=True)]
    return [(p["is_success"], p["aim_distance"] if p["on_table"] else np.inf) for p in played]


def _replay(
    env_id: str, actions: np.ndarray, reset_seeds: list[int], aims: list[np.ndarray | None], n_threads: int, chunk: int = 100
) -> list[tuple[bool, float]]:
    """:func:`_replay_chunk` over ``n_threads`` worker processes (1: here), in the order given."""
    parts = [
        (env_id, actions[i : i + chunk], reset_seeds[i : i + chunk], aims[i : i + chunk])
        for i in range(0, len(actions), chunk)
    ]
    if n_threads == 1:
        return [row for part in parts for row in _replay_chunk(*part)]
    with concurrent.futures.ProcessPoolExecutor(n_threads, mp_context=multiprocessing.get_context("spawn")) as pool:
        return [row for rows in pool.map(_replay_chunk, *zip(*parts, strict=True)) for row in rows]


def reconstruction_success(
    generator: Any, task: str | TaskSpec, episodes: int, seed: int, n_threads: int = 1
) -> dict[str, Any]:
    """How closely a VAE reproduces demonstrations it was not trained on: ``episodes`` new valid demonstrations (drawn
    as :func:`make_arrays` draws them, with ``seed``; give another seed than the training set's), each encoded to its
    posterior mean, decoded and replayed open-loop from its own reset state; the share that end within 5 cm of the
    demonstration's aim (object on the table) and the median miss (m)."""
    spec = get_task(task)
    demonstrations, k = [], 0
    while len(demonstrations) < episodes:
        played = _demonstration(spec.env_id, seed, k)
        k += 1
        if is_valid(played):
            demonstrations.append(played)
    actions = np.stack([d["actions"] for d in demonstrations])
    decoded = np.clip(generator.decode(generator.encode(actions)[0]), -1.0, 1.0).astype(np.float32)
    rows = _replay(
        spec.env_id, decoded, [d["reset_seed"] for d in demonstrations], [d["aim"] for d in demonstrations], n_threads
    )
    misses = np.array([distance for _, distance in rows])
    return {
        "demonstrations": episodes,
        "seed": seed,
        "drawn": k,
        "success_rate": float(np.mean(misses < 0.05)),
        "median_miss_m": float(np.median(misses)),
    }


def replay_success(
    generator: Any, task: str | TaskSpec, latents: np.ndarray, reset_seeds: list[int], n_threads: int = 1
) -> np.ndarray:
    """Whether each latent action, decoded (clipped to the action box) and played open-loop from its reset seed,
    solves the env's goal (``info["is_success"]`` of the last step)."""
    actions = np.clip(generator.decode(np.asarray(latents, dtype=np.float32)), -1.0, 1.0).astype(np.float32)
    rows = _replay(get_task(task).env_id, actions, list(reset_seeds), [None] * len(actions), n_threads)
    return np.array([success for success, _ in rows], dtype=bool)


def prior_best_success(
    generator: Any, task: str | TaskSpec, states: int, draws: int, seed: int, n_threads: int = 1
) -> dict[str, Any]:
    """The generator's own limit: for each of ``states`` initial states (reset seeds ``seed, seed + 1, ...``),
    ``draws`` latent actions from its prior, decoded and played open-loop; per state the number of draws that solve
    the env's goal (``info["is_success"]``). Returns the share of states solved by at least one draw (best of
    ``draws``), the best of 1, 10 and 100 draws (estimated from the same counts, without replacement) and the counts."""
    spec = get_task(task)
    rng = np.random.default_rng([seed, states, draws])
    actions = np.clip(generator.decode(generator.sample_prior(states * draws, rng)), -1.0, 1.0).astype(np.float32)
    rows = _replay(spec.env_id, actions, [seed + i // draws for i in range(states * draws)], [None] * len(actions), n_threads)
    solved = np.array([success for success, _ in rows], dtype=bool).reshape(states, draws).sum(axis=1)

    def best_of(k: int) -> float:  # P(at least one of k draws without replacement solves the state), mean over states
        return float(np.mean([1.0 - comb(draws - int(s), k) / comb(draws, k) for s in solved]))

    return {
        "states": states,
        "prior_draws_per_state": draws,
        "seed": seed,
        "success_rate": best_of(draws),
        "best_of": {str(k): best_of(k) for k in (1, 10, 100) if k <= draws},
        "solving_draws": solved.tolist(),
    }


def policy_neighbourhood_success(
    model: Any, task: str | TaskSpec, states: int, draws: int, seed: int, n_threads: int = 1
) -> dict[str, Any]:
    """What the generator allows near a trained GenRL policy: for each of ``states`` initial states (reset seeds
    ``seed, seed + 1, ...``), the policy's deterministic latent action and ``draws`` latent actions from the policy's
    own distribution at that state (clipped to the latent box), decoded and played open-loop. Returns the share of
    states the deterministic action solves, the share that at least one draw solves (best of ``draws``), the mean
    success of one draw (the stochastic policy's), and the counts per state. A gap between the first two says that
    solving latent actions lie within the policy's spread, so that the search, not the generator, limits it."""
    spec = get_task(task)
    fix_joint_helpers()
    env = LatentActionWrapper(gym.make(spec.env_id), model.generator)
    contexts = np.stack([env.reset(seed=seed + i)[0] for i in range(states)])
    env.close()
    rng = th.Generator().manual_seed(seed)
    with th.no_grad():
        distribution = model.policy.get_distribution(th.as_tensor(contexts, device=model.device)).distribution
        mean, std = distribution.mean.cpu(), distribution.stddev.cpu()
        drawn = (mean[:, None] + std[:, None] * th.randn((states, draws, mean.shape[1]), generator=rng)).numpy()
    # first per state: predict's action (with the moving average of the weights, where GenRL keeps one)
    alphas = np.concatenate([model.predict(contexts, deterministic=True)[0][:, None], drawn], axis=1)
    alphas = np.clip(alphas, env.action_space.low, env.action_space.high).reshape(states * (draws + 1), -1)
    alphas = alphas.astype(np.float32)
    actions = np.clip(model.generator.decode(alphas), -1.0, 1.0).astype(np.float32)
    rows = _replay(
        spec.env_id, actions, [seed + i // (draws + 1) for i in range(len(actions))], [None] * len(actions), n_threads
    )
    solved = np.array([success for success, _ in rows], dtype=bool).reshape(states, draws + 1)
    return {
        "states": states,
        "draws_per_state": draws,
        "seed": seed,
        "deterministic_success": float(solved[:, 0].mean()),
        "best_of_draws": float(solved[:, 1:].any(axis=1).mean()),
        "draw_success": float(solved[:, 1:].mean()),
        "spread": float(std.mean()),
        "deterministic_solved": solved[:, 0].astype(float).tolist(),
        "solving_draws": solved[:, 1:].sum(axis=1).tolist(),
    }
