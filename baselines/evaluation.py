"""What a trained baseline (or GenRL) policy does on the held-out goals, and what its training logs say of its
stability: the final evaluation and the health check of :func:`sb3_genrl.baselines.train.train_baseline`'s runs."""

from __future__ import annotations

import csv
import os
import pathlib
import re
from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.baselines import BASELINES, FEEDBACK_BASELINES, LATENT_BASELINES
from sb3_genrl.baselines.feedback import evaluate_feedback_policy, held_out_goals
from sb3_genrl.baselines.hyperparameters import algorithm_class
from sb3_genrl.envs import get_task
from stable_baselines3 import SAC

from sb3_genrl.checks import check_input_path, check_positive_int, check_seed
from sb3_genrl.genrl import GenRL
from sb3_genrl.hyperparams import EVAL_GOAL_SEED

EVAL_GOALS = 100  # held-out goals of every final evaluation (seed EVAL_GOAL_SEED, never used for tuning)


UNMOVED = 0.01  # m: an object whose (x, y) ends this close to its start was not moved


def evaluate_trained(
    algorithm: str, model: Any, task: str, *, generator: Any = None, goals: int = EVAL_GOALS, seed: int = EVAL_GOAL_SEED
) -> dict[str, Any]:
    """A trained policy's deterministic result on held-out goals, the same goals for every method.

    The feedback baselines play closed loop (:func:`~sb3_genrl.baselines.feedback.evaluate_feedback_policy`; SAC + HER
    on the goal-conditioned task); GenRL and the latent-space baselines play the trajectory decoded from their
    deterministic latent action for each goal, clipped to the model's latent action box as in training.

    :param algorithm: ``genrl`` or one of :data:`BASELINES`
    :param model: the trained model (e.g. :func:`load_trained`'s)
    :param task: the task it was trained on
    :param generator: the generator of GenRL and the latent-space baselines
    :param goals: number of held-out goals (see :func:`~sb3_genrl.baselines.feedback.held_out_goals`)
    :param seed: seed of the goals
    :return: the mean, median and 90th percentile of the final distance (minus the reward, m), the table contacts
        per episode (``None`` on a task without a table), how many of the episodes' simulations went unstable
        (those score the task's worst reward) and ``object_unmoved``: how many episodes left the puck or ball's
        (x, y) within :data:`UNMOVED` of where it rests at the start (its ``reached`` point; a policy that never
        hits the puck scores the distance of the arm holding still)
    """
    check_positive_int(goals, "goals")
    check_seed(seed)
    if algorithm not in FEEDBACK_BASELINES and algorithm != "genrl" and algorithm not in LATENT_BASELINES:
        raise ValueError(f"unknown method {algorithm!r}; expected 'genrl' or one of {BASELINES}")
    if algorithm not in FEEDBACK_BASELINES and generator is None:
        raise ValueError(f"{algorithm} needs its generator (generator=...)")
    env = gym.make(get_task(task).env_id).unwrapped  # the task's open-loop fast path, and its object's start
    try:
        start = env.initial_state_object_xy()
        if algorithm in FEEDBACK_BASELINES:
            played = evaluate_feedback_policy(model, task, goals=goals, seed=seed, goal_conditioned=algorithm == "sac-her")
            rewards, infos = played["rewards"], played["infos"]
        else:
            goal_array = held_out_goals(task, goals, seed)
            latents, _ = model.predict(goal_array, deterministic=True)
            latents = np.clip(latents, model.action_space.low, model.action_space.high)  # the box it was trained in
            rewards, infos = env.play_trajectories(np.asarray(generator.decode(latents)), goal_array)
    finally:
        env.close()
    distances = -np.asarray(rewards, dtype=float)
    unmoved = sum(bool(np.linalg.norm(np.asarray(info["reached"]) - start) < UNMOVED) for info in infos if "reached" in info)
    contacts = [info["table_contacts"] for info in infos if "table_contacts" in info]
    return {
        "goals": goals,
        "goal_seed": seed,
        "mean_distance": float(distances.mean()),
        "median_distance": float(np.median(distances)),
        "p90_distance": float(np.percentile(distances, 90)),
        "table_contacts": float(np.mean(contacts)) if len(contacts) == len(infos) else None,
        "unstable": sum(bool(info.get("unstable", False)) for info in infos),
        "object_unmoved": unmoved,
    }


def load_trained(algorithm: str, path: str | os.PathLike, task: str, *, generator: Any = None, device: str = "cpu") -> Any:
    """Load the model a run of ``algorithm`` on ``task`` saved (``{algorithm}_policy.zip``; GenRL's
    ``genrl_policy.zip`` needs its generator, SAC + HER's the goal-conditioned task, as SB3 loads its buffer class)."""
    check_input_path(path, "path")
    if algorithm == "genrl":
        return GenRL.load(path, device=device, generator=generator)
    if algorithm == "sac-her":
        return SAC.load(path, env=gym.make(get_task(task).goal_env_id), device=device)
    return algorithm_class(algorithm).load(path, device=device)


DIVERGED = 1000.0  # a critic loss this many times its early median counts as diverged
PPO_KL_LIMIT = 1.0  # a median approximate KL per PPO update above this: far outside the trust region clipping assumes


def training_health(out_dir: str | os.PathLike) -> dict[str, Any]:
    """What SB3's logger recorded of a run's stability (``logs/progress.csv`` and, for a resumed run, the
    ``progress.until_episode_K.csv`` before it): the critic's loss early (median of the first 10 records) and at its
    worst, the entropy coefficient (SAC), PPO's approximate KL per update and its clip fraction, and ``warnings``:
    a critic loss above :data:`DIVERGED` times its early median (the critic diverged) or a median approximate KL
    above :data:`PPO_KL_LIMIT` (each update moves the policy far beyond the trust region).

    :param out_dir: the run folder
    """
    logs = pathlib.Path(out_dir) / "logs"
    earlier = sorted(
        logs.glob("progress.until_episode_*.csv"), key=lambda path: int(re.search(r"_(\d+)\.csv$", path.name).group(1))
    )
    columns: dict[str, list[float]] = {
        key: [] for key in ("train/critic_loss", "train/ent_coef", "train/approx_kl", "train/clip_fraction")
    }
    for path in [*earlier, logs / "progress.csv"]:
        if not path.is_file():
            continue
        with open(path, newline="") as file:
            for row in csv.DictReader(file):
                for key, values in columns.items():
                    if row.get(key):
                        values.append(float(row[key]))
    health: dict[str, Any] = {"warnings": []}
    critic, ent_coef = columns["train/critic_loss"], columns["train/ent_coef"]
    kl, clip = columns["train/approx_kl"], columns["train/clip_fraction"]
    if critic:
        early, worst = float(np.median(critic[:10])), float(np.max(critic))
        health |= {"critic_loss_early": early, "critic_loss_max": worst}
        if worst > DIVERGED * max(early, 1e-12):
            health["warnings"].append(f"the critic's loss rose from {early:.3g} to {worst:.3g}: the critic diverged")
    if ent_coef:
        health |= {"ent_coef_first": ent_coef[0], "ent_coef_max": float(np.max(ent_coef)), "ent_coef_last": ent_coef[-1]}
    if kl:
        health |= {
            "approx_kl_median": float(np.median(kl)),
            "approx_kl_max": float(np.max(kl)),
            "clip_fraction_median": float(np.median(clip)) if clip else None,
        }
        if health["approx_kl_median"] > PPO_KL_LIMIT:
            health["warnings"].append(
                f"PPO's median approximate KL per update is {health['approx_kl_median']:.3g}: "
                "each update moves the policy far beyond its trust region (see target_kl)"
            )
    return health
