"""One generator's share of the study: train it, evaluate it, train GenRL with it over seeds.

Every stage writes its result file when it completes and is skipped when that file exists, so an interrupted study
resumes where it stopped. The job is a plain function of plain arguments, so a process pool or Ray can run it.
"""

from __future__ import annotations

import json
import os
import pathlib
from typing import Any

import numpy as np

PR_SEED = 0  # the real subset for precision/recall is drawn once, the same for every model (paper 6.1.2)


def _write_json(path: pathlib.Path, value: dict) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(value, indent=2))
    os.replace(tmp, path)


def generator_job(task: str, name: str, scale: dict[str, Any], dataset: str, task_dir: str, device: str = "auto",
                  torch_threads: int = 1) -> dict[str, Any]:
    """Train generator ``name`` (a paper table 1 preset), evaluate it and train GenRL with ``scale["seeds"]`` seeds.

    :param task: a task name from :data:`sb3_genrl.envs.TASKS`
    :param name: ``VAE1`` ... ``VAE9``, ``GAN1`` ... ``GAN9``
    :param scale: a :class:`~sb3_genrl.study.scales.StudyScale` as a dict
    :param dataset: the task's demonstration dataset
    :param task_dir: the task's study folder (``generators/``, ``evaluation/``, ``policies/`` are written in it)
    :param device: torch device
    :param torch_threads: torch threads of this job (one per worker process keeps the cores busy without contention)
    :return: the generator's row: preset values, measures and GenRL rewards per seed
    """
    import torch

    from sb3_genrl.data import load_actions
    from sb3_genrl.generative import PRESETS, load, train_generator
    from sb3_genrl.genrl import train_policy
    from sb3_genrl.metrics import dwpr, precision_recall

    torch.set_num_threads(torch_threads)
    root = pathlib.Path(task_dir)
    for folder in ("generators", "evaluation", "policies"):
        (root / folder).mkdir(parents=True, exist_ok=True)

    # Generator (paper 6.1.2, appendix B): trained on the demonstrations' action trajectories.
    model_path = root / "generators" / f"{name}.pt"
    if not model_path.exists():
        tmp = model_path.with_suffix(".pt.tmp")
        train_generator(dataset, preset=name, epochs=scale["generator_epochs"], eval_every=scale["eval_every"],
                        seed=0, out=tmp, device=device)
        os.replace(tmp, model_path)
    generator = load(model_path, device=device)

    # Evaluation (paper 5.2): precision/recall against a fixed real subset, and DwPR.
    evaluation_path = root / "evaluation" / f"{name}.json"
    if not evaluation_path.exists():
        real = load_actions(dataset)
        pick = np.random.default_rng(PR_SEED).permutation(len(real))[: scale["pr_samples"]]
        generated = generator.decode(generator.sample_prior(len(pick), np.random.default_rng(1)))
        pr = precision_recall(real[pick], generated, k=3, device=device)
        disentanglement = dwpr(generator, n=scale["dwpr_samples"], interventions=5, k=3, seed=0, device=device)
        _write_json(evaluation_path, {
            "precision": pr.precision, "recall": pr.recall, "delta_1": disentanglement.delta_1,
            "delta_2": disentanglement.delta_2, "mean_delta": disentanglement.mean_delta,
            "delta": disentanglement.delta.tolist(), "dwpr_precision": disentanglement.precision.tolist(),
            "dwpr_recall": disentanglement.recall.tolist(),
            "intervention_values": disentanglement.intervention_values.tolist()})
    evaluation = json.loads(evaluation_path.read_text())

    # GenRL (paper 6.1.3): one policy per seed.
    rewards = []
    for seed in range(scale["seeds"]):
        run_dir = root / "policies" / name / f"seed{seed}"
        if not (run_dir / "summary.json").exists():
            train_policy(task, str(model_path), episodes=scale["policy_episodes"], seed=seed, out_dir=run_dir,
                         batch_episodes=scale["batch_episodes"], device=device)
        rewards.append(json.loads((run_dir / "summary.json").read_text())["best_mean_reward"])

    spec = PRESETS[name]
    return {"model": name, "type": "VAE" if name.startswith("VAE") else "GAN", "latent_dim": spec["latent_dim"],
            "beta": spec.get("beta"), "info_weight": spec.get("info_weight"), **{
                key: evaluation[key] for key in ("precision", "recall", "delta_1", "delta_2", "mean_delta")},
            "rewards": rewards, "score": float(np.max(rewards))}


def baseline_job(algorithm: str, task: str, seed: int, episodes: int, dataset: str, demo_episodes: int, run_dir: str,
                 device: str = "auto", torch_threads: int = 1, generator: str | None = None) -> str:
    """One run of the comparison: PPO (behaviour cloning), SAC (prefilled), or a stock algorithm on the latent
    space of ``generator`` (``latent-ppo``, ``latent-sac``, ``latent-trpo``); skipped when already done."""
    import torch

    from sb3_genrl.baselines.train import train_baseline

    torch.set_num_threads(torch_threads)
    if not (pathlib.Path(run_dir) / "summary.json").exists():
        latent = algorithm.startswith("latent-")
        train_baseline(algorithm, task, episodes=episodes, out_dir=run_dir, seed=seed,
                       demos=None if latent else dataset, demo_episodes=None if latent else demo_episodes,
                       generator=generator if latent else None, device=device)
    return run_dir
