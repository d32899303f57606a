"""The ``genrl`` command line. Each command parses its arguments and calls one library function."""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="genrl", description="GenRL for Stable-Baselines3: tasks, demonstrations, "
                                     "generators, evaluation, policies, baselines and the paper's study.")
    sub = parser.add_subparsers(dest="command", required=True)
    # Each command adds its own parser here (one function per command, defined below).

    play = sub.add_parser("play", help="play the scripted hit and throw, render them and write a short report")
    play.add_argument("--out", required=True, help="output directory (report.md, GIFs, frame strips)")
    play.set_defaults(func=_play_command)

    train_policy = sub.add_parser("train-policy", help="train a GenRL policy over a generator's latent space (Algorithm 1)")
    train_policy.add_argument("--task", required=True, help="hockey, basketball or a registered Gymnasium id")
    train_policy.add_argument("--generator", required=True, help="file of a trained generator")
    train_policy.add_argument("--episodes", type=int, required=True, help="episodes (trajectories played) in total")
    train_policy.add_argument("--seed", type=int, default=0, help="random seed")
    train_policy.add_argument("--out", required=True, help="output directory (model, learning curve, TensorBoard logs)")
    train_policy.add_argument("--e-step", choices=("trpo", "kl_penalty"), default="trpo", help="E-step variant")
    train_policy.add_argument("--batch-episodes", type=int, default=64, help="episodes per EM iteration N (default 64)")
    train_policy.add_argument("--device", default="auto", help="torch device (default: auto)")
    train_policy.add_argument("--no-progress-bar", action="store_true", help="hide the progress bar")
    train_policy.set_defaults(func=_train_policy_command)

    train_generator = sub.add_parser("train-generator", help="train a beta-VAE or InfoGAN on demonstration trajectories")
    train_generator.add_argument("--data", required=True, help="Minari dataset directory or .npy/.npz (N, T, M) array")
    train_generator.add_argument("--model", choices=("vae", "gan"), default=None, help="model kind (default: vae)")
    train_generator.add_argument("--preset", default=None, help="paper table 1 model: VAE1..VAE9 or GAN1..GAN9")
    train_generator.add_argument("--latent-dim", type=int, default=None, help="latent dimension N_alpha")
    train_generator.add_argument("--beta", type=float, default=None, help="KL weight of the beta-VAE")
    train_generator.add_argument("--info-weight", type=float, default=None, help="information weight lambda of InfoGAN")
    train_generator.add_argument("--epochs", type=int, default=5000, help="training epochs (paper: 5000)")
    train_generator.add_argument("--batch-size", type=int, default=256, help="minibatch size (paper: 256)")
    train_generator.add_argument("--lr", type=float, default=2e-4, help="Adam learning rate (paper: 2e-4)")
    train_generator.add_argument("--seed", type=int, default=0, help="training seed")
    train_generator.add_argument("--eval-every", type=int, default=10, help="epochs between model-selection evaluations")
    train_generator.add_argument("--device", default="auto", help="torch device (default: auto)")
    train_generator.add_argument("--tensorboard-log", default=None, help="TensorBoard log directory")
    train_generator.add_argument("--no-progress-bar", action="store_true", help="hide the progress bar")
    train_generator.add_argument("--out", required=True, help="file to write the trained generator to")
    train_generator.set_defaults(func=_train_generator_command)
    return parser


def _play_command(args: argparse.Namespace) -> int:
    from sb3_genrl.envs.showcase import play_scripted

    print(f"wrote {play_scripted(args.out)}")
    return 0


def _train_generator_command(args: argparse.Namespace) -> int:
    from sb3_genrl.generative import train_generator

    generator = train_generator(args.data, model=args.model, preset=args.preset, latent_dim=args.latent_dim,
                                beta=args.beta, info_weight=args.info_weight, epochs=args.epochs,
                                batch_size=args.batch_size, lr=args.lr, seed=args.seed, eval_every=args.eval_every,
                                out=args.out, tensorboard_log=args.tensorboard_log,
                                progress_bar=not args.no_progress_bar, device=args.device)
    best = next((entry for entry in generator.history if entry["epoch"] == generator.best_epoch), {})
    print(f"{type(generator).__name__} (T={generator.horizon}, M={generator.action_dim}, N_alpha={generator.latent_dim})"
          f" best epoch {generator.best_epoch}, selection MSE {best.get('selection_mse', float('nan')):.6g}"
          f" -> {args.out}")
    return 0


def _train_policy_command(args: argparse.Namespace) -> int:
    from sb3_genrl.genrl import train_policy

    result = train_policy(args.task, args.generator, episodes=args.episodes, seed=args.seed, out_dir=args.out,
                          e_step=args.e_step, batch_episodes=args.batch_episodes, device=args.device,
                          progress_bar=not args.no_progress_bar)
    print(f"GenRL on {args.task}: {result['episodes']} episodes, {result['iterations']} iterations, mean reward "
          f"final {result['final_mean_reward']:.4g}, best {result['best_mean_reward']:.4g} -> {result['model_path']}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError) as error:
        print(f"genrl {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
