"""GenRL on the hockey task, step by step: demonstrations -> beta-VAE -> GenRL policy -> learning curve.

The same workflow as ``genrl quickstart``, written out with the library's functions so that each step can be changed.
About five minutes on a 2-core CPU with the defaults below.

    python examples/quickstart.py --out hockey_example
    python examples/quickstart.py --out hockey_small --demo-episodes 1000 --epochs 60 --episodes 640   # about a minute

Writes ``demonstrations/`` (a Minari dataset), ``vae.pt``, ``policy/`` (the model, ``learning_curve.csv`` and
``learning_curve.png``, TensorBoard logs) and prints the trained policy's mean final distance to new goals.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np
from sb3_genrl.envs.demonstrations import make_demonstrations

from sb3_genrl import GenRL  # importing sb3_genrl registers GenRL/Hockey-v0 with Gymnasium
from sb3_genrl.generative import train_generator
from sb3_genrl.hyperparams import load_genrl_settings
from sb3_genrl.run import train_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="hockey_example", help="output folder")
    parser.add_argument("--demo-episodes", type=int, default=2000, help="demonstrations to generate (the quickstart's)")
    parser.add_argument("--epochs", type=int, default=300, help="beta-VAE training epochs")
    parser.add_argument("--episodes", type=int, default=3000, help="GenRL episodes (one episode = one trajectory)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    out = Path(args.out)

    # 1. Demonstrations: the scripted expert's hits with small perturbations, stored as a Minari dataset.
    dataset = out / "demonstrations"
    if not dataset.exists():
        make_demonstrations("hockey", args.demo_episodes, dataset, seed=args.seed, progress_bar=True)

    # 2. Generator: a beta-VAE with a 2-D latent space (paper table 1, VAE1: N_alpha = 2, beta = 0.01) trained on the
    #    demonstrations' action trajectories (69 steps x 7 joint position changes).
    vae = train_generator(dataset, preset="VAE1", epochs=args.epochs, seed=args.seed, out=out / "vae.pt", progress_bar=True)
    print(f"beta-VAE: best checkpoint at epoch {vae.best_epoch} of {args.epochs}")

    # 3. GenRL: a policy from the goal to a latent action, trained with the paper's EM algorithm. train_policy wraps
    #    the task in LatentActionWrapper, logs to TensorBoard and writes the learning curve as training goes; the
    #    lower-level equivalent is GenRL(gym.make("GenRL/Hockey-v0"), vae, n_steps=16, ...).learn(args.episodes).
    #    Hockey's own settings, as genrl quickstart uses them (hyperparams/genrl.yml, GenRL/Hockey-v0): 16 episodes per
    #    iteration, and each hit also relabelled with where the puck came to rest, those of the last 120 iterations
    #    kept, and the policy's mean (64 x 64 x 64) fitted to them by 512 Adam steps after each iteration
    #    (hindsight_kwargs={"history": 120, "regression_steps": 512}).
    _, batch_episodes, genrl_kwargs = load_genrl_settings("GenRL/Hockey-v0")
    result = train_policy(
        "hockey",
        str(out / "vae.pt"),
        episodes=args.episodes,
        seed=args.seed,
        out_dir=out / "policy",
        batch_episodes=batch_episodes,
        progress_bar=True,
        **genrl_kwargs,
    )
    print(f"GenRL: {result['episodes']} episodes, learning curve in {result['png_path']}")

    # 4. The trained policy, deterministic, on 100 goals it has not seen: play the decoded trajectories.
    model = GenRL.load(result["model_path"])
    env = gym.make("GenRL/Hockey-v0").unwrapped
    rng = np.random.default_rng(args.seed + 1)
    goals = np.array([env.sample_goal(rng) for _ in range(100)], dtype=np.float32)
    latents, _ = model.predict(goals, deterministic=True)
    rewards, infos = env.play_trajectories(model.generator.decode(latents), goals)
    contacts = sum(info["table_contacts"] for info in infos)
    print(
        f"mean final distance to 100 new goals: {-rewards.mean() * 100:.1f} cm "
        f"(median {-np.median(rewards) * 100:.1f} cm; stick-table contacts: {contacts})"
    )


if __name__ == "__main__":
    main()
