"""One generator's share of the study: train it, evaluate it, train GenRL with it over seeds.

Every stage writes its result file when it completes and is skipped when that file exists, so an interrupted study
resumes where it stopped. The study's runner checks and records each stage's settings before any job starts
(:mod:`sb3_genrl.run.stages`); a job also ties its evaluation and policies to the generator file they used (its
fingerprint) and refuses to reuse them for another. The job is a plain function of plain arguments, so a process
pool or Ray can run it.
"""

from __future__ import annotations

import json
import math
import pathlib
import time
from typing import Any

import numpy as np
import torch

from sb3_genrl.baselines.train import train_baseline
from sb3_genrl.curves import MONITOR_FILE, read_curve, read_monitor
from sb3_genrl.data import load_actions
from sb3_genrl.data.fingerprints import file_fingerprint
from sb3_genrl.generative import PRESETS, load, train_generator
from sb3_genrl.metrics import MEASURES, evaluate_generator, real_subset
from sb3_genrl.metrics.prior_rollout import PRIOR_ROLLOUT_SEED  # the prior rollout's goals (not the evaluations')
from sb3_genrl.run import train_policy
from sb3_genrl.run.stages import STAGE_FILE, check_and_record, read_settings, refuse_conflicts, settings_conflicts
from sb3_genrl.study.quickstart import task_settings
from sb3_genrl.study.report import SCORECARD_MEASURES
from sb3_genrl.utils import atomic_write_json

# Fixed settings of the study's stages (recorded with each stage, see sb3_genrl.study.runner).
GENERATOR_SEED = 0
# Every model is evaluated with seed 0: the real subset for precision/recall is drawn once from it, the same for every
# model (paper 6.1.2: a fixed, randomly chosen set of training trajectories), and so are the prior samples and DwPR.
EVALUATION_SEED = 0
K = 3  # neighbourhood size of precision/recall and DwPR (paper: 3)
INTERVENTIONS = 5  # DwPR interventions per latent dimension (paper: 5)


def generator_job(
    task: str, name: str, scale: dict[str, Any], dataset: str, task_dir: str, device: str = "auto", torch_threads: int = 1
) -> dict[str, Any]:
    """Train generator ``name`` (a paper table 1 preset), evaluate it and train GenRL with ``scale["seeds"]`` seeds.

    :param task: a task name from :data:`sb3_genrl.envs.TASKS`
    :param name: ``VAE1`` ... ``VAE9``, ``GAN1`` ... ``GAN9``
    :param scale: a :class:`~sb3_genrl.study.scales.StudyScale` as a dict
    :param dataset: the task's demonstration dataset
    :param task_dir: the task's study folder (``generators/``, ``evaluation/``, ``policies/`` are written in it)
    :param device: torch device
    :param torch_threads: torch threads of this job (one per worker process keeps the cores busy without contention)
    :return: the generator's row: preset values, measures (the paper's, density, coverage, the prior rollout's),
        the selection error after each evaluation of its training, GenRL's best rewards per seed (``rewards``, their
        best ``score``), the best within the first half of the budget (``half_rewards``, ``half_score``) and the final
        iteration's (``final_rewards``, their mean ``final``)
    """
    torch.set_num_threads(torch_threads)
    root = pathlib.Path(task_dir)
    for folder in ("generators", "evaluation", "policies"):
        (root / folder).mkdir(parents=True, exist_ok=True)

    # Generator (paper 6.1.2, appendix B): trained on the demonstrations' action trajectories.
    model_path = root / "generators" / f"{name}.pt"
    if not model_path.exists():  # the file is written atomically: it exists only once training is complete
        start = time.process_time()
        train_generator(
            dataset,
            preset=name,
            epochs=scale["generator_epochs"],
            eval_every=scale["eval_every"],
            seed=GENERATOR_SEED,
            out=model_path,
            device=device,
        )
        atomic_write_json(model_path.with_suffix(".time.json"), {"cpu_seconds": time.process_time() - start})
    generator = load(model_path, device=device)
    fingerprint = file_fingerprint(model_path)

    evaluation = _evaluation(task, generator, name, fingerprint, scale, dataset, root, device)

    # GenRL (paper 6.1.3): one policy per seed, all from this generator file.
    policies = root / "policies" / name
    check_and_record(
        policies / STAGE_FILE, {"generator": fingerprint}, folder=root, output_exists=any(policies.glob("seed*/summary.json"))
    )
    runs = [_policy_rewards(task, model_path, seed, scale, policies / f"seed{seed}", device) for seed in range(scale["seeds"])]
    rewards, half, final = ([run[key] for run in runs] for key in ("best", "half", "final"))
    cpu_seconds = {
        "generator": _recorded_seconds(model_path.with_suffix(".time.json")),
        "evaluation": evaluation.get("cpu_seconds", math.nan),
        "genrl": sum(run["cpu_seconds"] for run in runs),
    }

    spec = PRESETS[name]
    return {
        "model": name,
        "type": "VAE" if name.startswith("VAE") else "GAN",
        "latent_dim": spec["latent_dim"],
        "beta": spec.get("beta"),
        "info_weight": spec.get("info_weight"),
        **{key: evaluation[key] for key in (*MEASURES, *SCORECARD_MEASURES)},
        "prior_q25": evaluation["prior_q25"],
        "prior_q75": evaluation["prior_q75"],
        "best_epoch": generator.best_epoch,
        "selection": [[record["epoch"], record["selection_mse"]] for record in generator.history],
        "rewards": rewards,
        "score": float(np.max(rewards)),
        "half_rewards": half,
        "half_score": float(np.max(half)),
        "final_rewards": final,
        "final": float(np.mean(final)),
        "cpu_seconds": cpu_seconds,
    }


def _recorded_seconds(path: pathlib.Path) -> float:
    """The CPU seconds a stage recorded (nan when it has no record: made by an older version)."""
    return float(json.loads(path.read_text())["cpu_seconds"]) if path.is_file() else math.nan


def _evaluation(
    task: str,
    generator: Any,
    name: str,
    fingerprint: str,
    scale: dict[str, Any],
    dataset: str,
    root: pathlib.Path,
    device: str,
) -> dict[str, Any]:
    """Precision/recall against the fixed real subset and DwPR (paper 5.2), density, coverage and the prior rollout,
    or the stored result of this file."""
    path = root / "evaluation" / f"{name}.json"
    stored = read_settings(path)
    if stored is not None:
        refuse_conflicts(root, settings_conflicts(path, stored, {"generator": fingerprint}))
        return stored
    start = time.process_time()
    real = real_subset(load_actions(dataset), scale["pr_samples"], EVALUATION_SEED)
    result = evaluate_generator(
        generator,
        real,
        n=scale["pr_samples"],
        k=K,
        dwpr_n=scale["dwpr_samples"],
        interventions=INTERVENTIONS,
        seed=EVALUATION_SEED,
        name=name,
        device=device,
        task=task,
        contexts=scale["prior_contexts"],
        draws=scale["prior_draws"],
        prior_seed=PRIOR_ROLLOUT_SEED,
    )
    evaluation = {**result.details(), "generator": fingerprint, "cpu_seconds": time.process_time() - start}
    evaluation.pop("prior_best")  # per goal: not needed by the report
    atomic_write_json(path, evaluation)
    return evaluation


def task_genrl_kwargs(task: str) -> dict[str, Any]:
    """The task's own GenRL settings (its entry in ``hyperparams/genrl.yml``, see
    :func:`~sb3_genrl.study.quickstart.task_settings`), used by every GenRL run of the study; the scale sets the
    episodes and the episodes per iteration."""
    return task_settings(task)[2]


def _policy_rewards(
    task: str, model_path: pathlib.Path, seed: int, scale: dict[str, Any], run_dir: pathlib.Path, device: str
) -> dict[str, float]:
    """One GenRL run's best iteration mean reward, the best within the first half of its budget (from its learning
    curve), its final iteration's and its CPU seconds (its Monitor file's, the process that played and learned)."""
    if not (run_dir / "summary.json").exists():
        train_policy(
            task,
            str(model_path),
            episodes=scale["policy_episodes"],
            seed=seed,
            out_dir=run_dir,
            batch_episodes=scale["batch_episodes"],
            n_envs=1,  # one env per job: the study runs its jobs side by side on the cores
            device=device,
            **task_genrl_kwargs(task),
        )
    summary = json.loads((run_dir / "summary.json").read_text())
    return {
        "best": float(summary["best_mean_reward"]),
        "final": float(summary["final_mean_reward"]),
        "half": half_budget_best(read_curve(run_dir / "learning_curve.csv"), scale["policy_episodes"]),
        "cpu_seconds": float(read_monitor(run_dir / MONITOR_FILE)["cpu_seconds"][-1]),
    }


def half_budget_best(curve: dict[str, np.ndarray], episodes: int) -> float:
    """The best iteration mean reward of a learning curve among the iterations that end within ``episodes / 2``
    episodes (the first iteration's when even that ends later)."""
    within = curve["episodes"] <= episodes / 2
    return float(np.max(curve["mean_reward"][within]) if within.any() else curve["mean_reward"][0])


def baseline_job(
    algorithm: str,
    task: str,
    seed: int,
    episodes: int,
    dataset: str,
    demo_episodes: int,
    run_dir: str,
    device: str = "auto",
    torch_threads: int = 1,
    generator: str | None = None,
    bc_eval_goals: int = 100,
) -> str:
    """One run of the comparison: a feedback baseline on the demonstrations (PPO with behaviour cloning, SAC with and
    without them in its buffer, SAC + HER) or a stock algorithm on the latent space of ``generator``
    (``latent-ppo``, ``latent-sac``, ``latent-trpo``); skipped when already done."""
    torch.set_num_threads(torch_threads)
    if not (pathlib.Path(run_dir) / "summary.json").exists():
        latent = algorithm.startswith("latent-")
        train_baseline(
            algorithm,
            task,
            episodes=episodes,
            out_dir=run_dir,
            seed=seed,
            demos=None if latent else dataset,
            demo_episodes=None if latent else demo_episodes,
            generator=generator if latent else None,
            eval_goals=bc_eval_goals,
            device=device,
            n_envs=1 if latent else None,  # the study plays its jobs side by side, one core each
        )
    return run_dir
