"""Train a beta-VAE on demonstrations and plot generated against demonstrated joint trajectories (paper appendix C).

    python examples/train_vae_on_demos.py path/to/minari/dataset --preset VAE6 --epochs 200
    python examples/train_vae_on_demos.py --synthetic --epochs 40     # no dataset needed

The figure has one subplot per joint with a few held-out demonstrations (solid) and a few generated trajectories
(dashed); the model is saved next to it.
"""

from __future__ import annotations

import argparse
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from sb3_genrl.generative import make_generator  # noqa: E402
from sb3_genrl.generative.synthetic import sine_ramp_trajectories  # noqa: E402


def load_demonstrations(args: argparse.Namespace) -> np.ndarray:
    if args.synthetic:
        trajectories, _ = sine_ramp_trajectories(2000, 30, 3, rng=args.seed)
        return trajectories
    if args.dataset is None:
        raise SystemExit("give a dataset path or --synthetic")
    from sb3_genrl.data import load_actions

    return np.asarray(load_actions(args.dataset))


def plot(demonstrations: np.ndarray, generated: np.ndarray, path: str) -> None:
    n_joints = demonstrations.shape[2]
    columns = min(n_joints, 4)
    rows = int(np.ceil(n_joints / columns))
    figure, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 2.6 * rows), squeeze=False, sharex=True)
    time_steps = np.arange(demonstrations.shape[1])
    for joint, axis in enumerate(axes.flat):
        if joint >= n_joints:
            axis.axis("off")
            continue
        for index, trajectory in enumerate(demonstrations):
            axis.plot(time_steps, trajectory[:, joint], color="C0", alpha=0.7, label="test" if index == 0 else None)
        for index, trajectory in enumerate(generated):
            axis.plot(
                time_steps,
                trajectory[:, joint],
                color="C1",
                linestyle="--",
                alpha=0.8,
                label="generated" if index == 0 else None,
            )
        axis.set_title(f"joint {joint + 1}")
        axis.set_xlabel("time step")
    axes.flat[0].set_ylabel("action")
    axes.flat[0].legend(loc="best", fontsize="small")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", nargs="?", help="Minari dataset directory")
    parser.add_argument("--synthetic", action="store_true", help="use the synthetic sine/ramp family instead")
    parser.add_argument("--preset", default="VAE6", help="paper table 1 model (default VAE6: N_alpha=3, beta=0.001)")
    parser.add_argument("--epochs", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-plotted", type=int, default=4, help="test and generated trajectories per subplot")
    parser.add_argument("--out-dir", default="runs/train_vae_on_demos", help="folder for the model and the figure")
    args = parser.parse_args()

    trajectories = load_demonstrations(args)
    rng = np.random.default_rng(args.seed)
    test_mask = np.zeros(len(trajectories), dtype=bool)
    test_mask[rng.choice(len(trajectories), size=max(args.n_plotted, len(trajectories) // 10), replace=False)] = True
    vae = make_generator(args.preset, horizon=trajectories.shape[1], action_dim=trajectories.shape[2])
    vae.fit(trajectories[~test_mask], epochs=args.epochs, seed=args.seed)

    os.makedirs(args.out_dir, exist_ok=True)
    model_path = os.path.join(args.out_dir, f"{args.preset.lower()}.pt")
    figure_path = os.path.join(args.out_dir, f"{args.preset.lower()}_trajectories.png")
    vae.save(model_path)
    generated = vae.decode(vae.sample_prior(args.n_plotted, rng))
    plot(trajectories[test_mask][: args.n_plotted], generated, figure_path)
    print(f"best epoch {vae.best_epoch}; saved {model_path} and {figure_path}")


if __name__ == "__main__":
    main()
