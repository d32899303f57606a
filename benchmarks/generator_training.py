"""Training speed of the generators (epochs per second) at the paper's data size.

Paper section 6.1.2 / appendix B: about 40K demonstrations of 69 time steps x 7 joints (hockey), batch size 256.
The data are the synthetic two-factor family (the speed does not depend on the values).

    python -m benchmarks.generator_training                   # 40000 trajectories, 3 epochs per model
    python -m benchmarks.generator_training --n 4000 --epochs 5 --threads 1 --out /tmp/generator_training.json
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import torch
from sb3_genrl.envs import TASKS

from sb3_genrl import __version__
from sb3_genrl.checks import COUNT, JSON_OUT, SEED, check_device, option
from sb3_genrl.generative import make_generator
from sb3_genrl.generative.defaults import BATCH_SIZE, N_DEMONSTRATIONS, N_JOINTS
from sb3_genrl.generative.synthetic import sine_ramp_trajectories
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_write_json

DEFAULT_OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "generator_training.json")
MODELS = {"vae": "VAE6", "gan": "GAN5"}  # N_alpha = 3, the paper's best hockey models


def benchmark(n: int, horizon: int, epochs: int, batch_size: int, device: str, seed: int) -> list[dict[str, object]]:
    trajectories, _ = sine_ramp_trajectories(n, horizon, N_JOINTS, rng=seed)
    rows = []
    for kind, preset in MODELS.items():
        generator = make_generator(preset, horizon=horizon, action_dim=N_JOINTS, device=device)
        start = time.perf_counter()
        # One model-selection evaluation (at the last epoch), as in a run with a large eval_every.
        generator.fit(
            trajectories, epochs=epochs, batch_size=batch_size, seed=seed, eval_every=epochs, progress_bar=False, device=device
        )
        seconds = time.perf_counter() - start
        rows.append(
            {
                "model": kind,
                "preset": preset,
                "n": n,
                "horizon": horizon,
                "action_dim": N_JOINTS,
                "epochs": epochs,
                "batch_size": batch_size,
                "seconds": seconds,
                "epochs_per_second": epochs / seconds,
                "device": str(generator.device),
            }
        )
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=COUNT, default=N_DEMONSTRATIONS, help="number of trajectories (paper: ~40000)")
    parser.add_argument("--horizon", type=COUNT, default=TASKS["hockey"].horizon, help="time steps (hockey: 69)")
    parser.add_argument("--epochs", type=COUNT, default=3, help="epochs timed per model")
    parser.add_argument("--batch-size", type=COUNT, default=BATCH_SIZE)
    parser.add_argument("--device", type=option(check_device), default="auto")
    parser.add_argument("--seed", type=SEED, default=0)
    parser.add_argument("--threads", type=COUNT, default=None, help="torch CPU threads (default: torch's choice)")
    parser.add_argument("--out", type=JSON_OUT, default=DEFAULT_OUT, help="JSON file for the results")
    args = parser.parse_args(argv)
    if args.threads is not None:
        torch.set_num_threads(args.threads)

    rows = benchmark(args.n, args.horizon, args.epochs, args.batch_size, args.device, args.seed)
    print(f"{'model':<6} {'N':>7} {'T x M':>7} {'epochs':>6} {'seconds':>9} {'epochs/s':>9} {'s/epoch':>8}  device")
    for row in rows:
        print(
            f"{row['model']:<6} {row['n']:>7} {row['horizon'] * row['action_dim']:>7} {row['epochs']:>6} "
            f"{row['seconds']:>9.2f} {row['epochs_per_second']:>9.3f} {1 / row['epochs_per_second']:>8.2f}  {row['device']}"
        )
    paper_hours = {row["model"]: 5000 / row["epochs_per_second"] / 3600 for row in rows}
    print("5000 paper epochs would take " + ", ".join(f"{model}: {hours:.1f} h" for model, hours in paper_hours.items()))
    environment = {
        "sb3_genrl": __version__,
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "cuda": torch.cuda.get_device_name() if torch.cuda.is_available() else None,
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
    }
    atomic_write_json(args.out, provenance() | {"environment": environment, "results": rows})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
