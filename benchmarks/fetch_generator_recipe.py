"""The Fetch generator recipe's path term: VAE-FETCH trained with other ``path_weight`` values (BetaVAE's weight of
the error of the trajectory's running sum, the end-effector's path), each scored by the Fetch benchmark's two
generator measures: its reconstructions of 200 new demonstrations (seed 1) that reach their aims, and the success on
200 tuning initial states (TUNING_GOAL_SEED) of GenRL's policy mean fitted to the demonstrations (the entry's
DemonstrationCallback fit, policy seed 0). Each row is appended to ``--out`` as it finishes; rows already there are
kept and not measured again.

    python -m benchmarks.fetch_generator_recipe --task fetch-push --weights 0 1 4 16 --seeds 3
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

import torch
from sb3_genrl.envs.demonstrations.fetch import reconstruction_success

from benchmarks.fetch_seed import fitted_mean_success
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED
from sb3_genrl.data import load_actions
from sb3_genrl.generative.presets import resolve_generator_spec
from sb3_genrl.generative.vae import BetaVAE
from sb3_genrl.hyperparams import TUNING_GOAL_SEED
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_write_json

RECONSTRUCTION_SEED = 1  # as benchmarks/fetch.py: demonstrations the generator was not trained on


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True, choices=("fetch-reach", "fetch-push", "fetch-pick-and-place", "fetch-slide"))
    parser.add_argument("--data", type=EXISTING, default=None, help="demonstrations (default runs/fetch/TASK/demonstrations)")
    parser.add_argument("--weights", type=float, nargs="+", default=[0.0, 1.0, 4.0])
    parser.add_argument("--seeds", type=SEED, nargs="+", default=[3])
    parser.add_argument("--epochs", type=COUNT, default=300)
    parser.add_argument("--states", type=COUNT, default=200)
    parser.add_argument("--out", type=JSON_OUT, default="runs/fetch_generator_recipe.json")
    args = parser.parse_args(argv)
    data = args.data or os.path.join("runs", "fetch", args.task, "demonstrations")
    EXISTING(data)
    torch.set_num_threads(1)
    result = {"benchmark": "fetch_generator_recipe", "rows": []}
    if os.path.exists(args.out):
        with open(args.out) as file:
            result = json.load(file)
    recipe = {key: value for key, value in resolve_generator_spec("VAE-FETCH").items() if key != "path_weight"}
    actions = load_actions(data)
    for weight in args.weights:
        for seed in args.seeds:
            key = {"task": args.task, "path_weight": weight, "seed": seed, "epochs": args.epochs, "states": args.states}
            if any(all(row.get(k) == v for k, v in key.items()) for row in result["rows"]):
                continue
            start = time.perf_counter()
            vae = BetaVAE(
                actions.shape[1], actions.shape[2], recipe["latent_dim"], beta=recipe["beta"], path_weight=weight, device="cpu"
            ).fit(actions, epochs=args.epochs, seed=seed, progress_bar=False)
            with tempfile.TemporaryDirectory() as work:
                path = os.path.join(work, "vae.pt")
                vae.save(path)
                fit = fitted_mean_success(args.task, path, data, args.states, TUNING_GOAL_SEED)
            recon = reconstruction_success(vae, args.task, 200, RECONSTRUCTION_SEED)
            row = key | {
                "reconstructions_reach_aims": recon["success_rate"],
                "median_miss_m": recon["median_miss_m"],
                "fitted_mean_tuning_success": fit,
                "seconds": time.perf_counter() - start,
            }
            result["rows"].append(row)
            atomic_write_json(args.out, provenance() | result)
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
