"""The quickstart: demonstrations -> a beta-VAE -> its evaluation -> a GenRL policy -> a short report with plots."""

from __future__ import annotations

import json
import os
import pathlib
import time
from collections.abc import Callable
from typing import Any

# Paper table 1's VAE1 (N_alpha = 2, beta = 0.01). Of the 2-D VAEs, its stronger prior term lays the hockey
# demonstrations out as one unfolded sheet (shot distance along one latent axis, direction along the other); with
# beta = 0.001 (VAE3) the sheet often folds over itself, and GenRL's Gaussian policy then stalls at the fold.
QUICKSTART_PRESET = "VAE1"


def quickstart(out_dir: str | os.PathLike, *, task: str, demo_episodes: int = 4000, epochs: int = 300,
               policy_episodes: int = 3000, pr_samples: int = 1000, dwpr_samples: int = 500, seed: int = 0,
               video: bool = True, device: str = "auto", log: Callable[[str], None] | None = None) -> pathlib.Path:
    """Run the whole GenRL workflow at a small size and write ``report.md`` in ``out_dir``.

    Each stage is skipped when its output exists, so a rerun resumes. Defaults take about four minutes on a 2-core CPU.

    :param out_dir: output folder (a rerun resumes it)
    :param task: a task name from :data:`sb3_genrl.envs.TASKS`
    :param demo_episodes: demonstrations to generate
    :param epochs: beta-VAE training epochs (:data:`QUICKSTART_PRESET` of paper table 1)
    :param policy_episodes: GenRL episodes
    :param pr_samples: samples per set for precision and recall
    :param dwpr_samples: samples per intervention for DwPR
    :param video: also render the trained policy (a GIF and a strip of frames)
    :return: the report's path
    """
    import torch

    from sb3_genrl.envs.demonstrations import make_demonstrations
    from sb3_genrl.generative import load, train_generator
    from sb3_genrl.genrl import GenRL, evaluate_on_goals, train_policy
    from sb3_genrl.metrics import evaluate_generators

    # The models are small: one torch thread is as fast as several and leaves the other cores to MuJoCo.
    torch.set_num_threads(1)
    log = log or (lambda _line: None)
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}

    def stage(name: str, done: bool, work: Callable[[], Any]) -> None:
        start = time.perf_counter()
        if not done:
            work()
        timings[name] = time.perf_counter() - start
        log(f"{name}: {'done' if not done else 'already there'} ({timings[name]:.0f} s)")

    dataset = out / "demonstrations"
    stage("demonstrations", dataset.exists(),
          lambda: make_demonstrations(task, demo_episodes, dataset, seed=seed, progress_bar=True))
    model_path = out / "vae.pt"
    stage("generator", model_path.exists(),
          lambda: train_generator(dataset, preset=QUICKSTART_PRESET, epochs=epochs, eval_every=10, seed=seed, out=model_path,
                                  progress_bar=True, device=device, tensorboard_log=str(out / "tensorboard")))
    evaluation = out / "evaluation"
    stage("evaluation", (evaluation / "results.json").exists(),
          lambda: evaluate_generators({QUICKSTART_PRESET: model_path}, dataset, n=pr_samples, dwpr_n=dwpr_samples, seed=seed,
                                      out_dir=evaluation, device=device))
    policy = out / "policy"
    stage("policy", (policy / "summary.json").exists(),
          lambda: train_policy(task, str(model_path), episodes=policy_episodes, seed=seed, out_dir=policy,
                               device=device, progress_bar=True))
    if video:
        from sb3_genrl.video import record_video

        stage("video", (out / "policy.gif").exists(),
              lambda: record_video(task, out / "policy.gif", policy=policy, goals=4, seed=seed + 1, width=320,
                                   height=240, fps=20))
    summary = json.loads((policy / "summary.json").read_text())
    measures = json.loads((evaluation / "results.json").read_text())
    _, rewards, _ = evaluate_on_goals(GenRL.load(policy / "genrl_policy.zip", device="cpu"), task, goals=100,
                                      seed=seed + 12345)
    final_distance = float(-rewards.mean())
    coverage = json.loads(next(dataset.glob("**/coverage.json")).read_text()) if any(dataset.glob("**/coverage.json")) \
        else {}
    generator = load(model_path, device="cpu")
    lines = [f"# GenRL quickstart: {task}", "",
             f"1. **Demonstrations**: {demo_episodes} valid episodes from the scripted expert and its perturbations"
             + (f" (goal-region coverage {coverage['coverage']:.1%})" if "coverage" in coverage else "") + ".",
             f"2. **Generator**: beta-VAE (preset {QUICKSTART_PRESET}: N_alpha = {generator.latent_dim}, "
             f"beta = {generator.beta}), {epochs} epochs, "
             f"best checkpoint at epoch {generator.best_epoch}.",
             f"3. **Evaluation**: {_measure_line(measures)}.",
             f"4. **GenRL**: {summary['episodes']} episodes; best iteration mean reward {summary['best_mean_reward']:.3f},"
             f" final {summary['final_mean_reward']:.3f}; the trained policy's own mean distance to 100 new goals "
             f"(deterministic): **{final_distance * 100:.1f} cm**.", "",
             "![learning curve](policy/learning_curve.png)", "",
             "![precision and recall](evaluation/precision_recall.png)", ""]
    if video:
        lines += ["![policy](policy.gif)", "", "![policy frames](policy_strip.png)", ""]
    lines += ["Stage times (s): " + ", ".join(f"{k} {v:.0f}" for k, v in timings.items()), ""]
    report = out / "report.md"
    report.write_text("\n".join(lines))
    return report


def _measure_line(measures: list[dict[str, Any]]) -> str:
    row = measures[0]
    return ", ".join(f"{key} {row[key]:.3f}" for key in ("precision", "recall", "delta_1", "delta_2", "mean_delta")
                     if key in row)
