"""The CPU time of each stage of the ``small`` study on one task, and an InfoGAN's precision after more epochs.

What ``docs/guide/study.md`` estimates the study's time from: 4000 demonstrations, 30 epochs of VAE1 and of GAN2,
one evaluation (precision/recall on 2000, DwPR 1000 x 5), 256 GenRL episodes with the task's settings, then GAN2
trained 500 and 1500 epochs and evaluated (precision after 150 epochs was 0.014 on basketball). One torch thread,
one simulation thread. Each entry is written as it completes and a rerun skips the entries already there.

    python -m benchmarks.study_stage_times basketball runs/stage_times   # then copy runs/stage_times/basketball/times.json
"""

from __future__ import annotations

import json
import pathlib
import sys
import time

import torch
from sb3_genrl.envs.demonstrations import make_demonstrations

from sb3_genrl.data import load_actions
from sb3_genrl.generative import load, train_generator
from sb3_genrl.metrics import evaluate_generator, real_subset
from sb3_genrl.provenance import provenance
from sb3_genrl.run import train_policy
from sb3_genrl.study.quickstart import task_settings
from sb3_genrl.utils import atomic_write_json


def main() -> None:
    torch.set_num_threads(1)
    task, out = sys.argv[1], pathlib.Path(sys.argv[2]) / sys.argv[1]
    out.mkdir(parents=True, exist_ok=True)
    res_path = out / "times.json"
    res = json.loads(res_path.read_text()) if res_path.exists() else {}

    def timed(key, fn):
        if key in res:
            return
        w, c = time.perf_counter(), time.process_time()
        extra = fn()
        res[key] = {"wall_s": time.perf_counter() - w, "cpu_s": time.process_time() - c, **(extra or {})}
        atomic_write_json(res_path, res | provenance())
        print(key, res[key], flush=True)

    demos = out / "demonstrations"
    timed("demos_4000", lambda: make_demonstrations(task, 4000, demos, seed=0, progress_bar=False, n_threads=1) and None)
    for name, epochs in (("VAE1", 30), ("GAN2", 30)):

        def short(name=name, epochs=epochs):
            train_generator(
                str(demos), preset=name, epochs=epochs, eval_every=10, seed=0, out=out / f"{name}_{epochs}.pt", device="cpu"
            )

        timed(f"{name}_{epochs}ep", short)
    real = real_subset(load_actions(demos), 2000, 0)

    def evaluate(path):
        r = evaluate_generator(load(path, device="cpu"), real, n=2000, k=3, dwpr_n=1000, interventions=5, seed=0, device="cpu")
        return {k: float(v) for k, v in r.row().items() if k != "model"}

    timed("evaluate_VAE1", lambda: evaluate(out / "VAE1_30.pt"))
    _, batch, kwargs = task_settings(task)

    def policy():
        train_policy(
            task,
            str(out / "VAE1_30.pt"),
            episodes=256,
            seed=0,
            out_dir=out / "policy",
            batch_episodes=batch,
            n_envs=1,  # as the study's jobs play
            device="cpu",
            **kwargs,
        )
        return {"episodes": 256, "batch": batch}

    timed("genrl_256", policy)
    for name, epochs in (("GAN2", 500), ("GAN2", 1500)):

        def gan(name=name, epochs=epochs):
            path = out / f"{name}_{epochs}.pt"
            train_generator(str(demos), preset=name, epochs=epochs, eval_every=50, seed=0, out=path, device="cpu")
            generator = load(path, device="cpu")
            return {
                **evaluate(path),
                "best_epoch": generator.best_epoch,
                "selection_mse": [h["selection_mse"] for h in generator.history],
            }

        timed(f"{name}_{epochs}ep", gan)


if __name__ == "__main__":
    main()
