"""The ``genrl`` command line. Each command parses its arguments and calls one library function."""

from __future__ import annotations

import argparse
import json
import sys


def build_parser() -> argparse.ArgumentParser:
    from sb3_genrl.envs import DEFAULT_TASK, TASKS

    tasks = tuple(TASKS)  # the registered tasks' short names
    parser = argparse.ArgumentParser(prog="genrl", description="GenRL for Stable-Baselines3: tasks, demonstrations, "
                                     "generators, evaluation, policies, baselines and the paper's study.")
    sub = parser.add_subparsers(dest="command", required=True)
    # Each command adds its own parser here (one function per command, defined below).

    demos = sub.add_parser("demos", help="generate a task's demonstrations as a Minari dataset, with a coverage report")
    demos.add_argument("--task", required=True, choices=tasks, help="task")
    demos.add_argument("--episodes", type=int, default=40000, help="valid demonstrations to keep (paper: 40000)")
    demos.add_argument("--out", required=True, help="dataset directory to create (must not exist or be empty)")
    demos.add_argument("--seed", type=int, default=0, help="seed of every random draw")
    demos.add_argument("--threads", type=int, default=None, help="simulation threads (default: available cores)")
    demos.add_argument("--no-progress-bar", action="store_true", help="hide the progress bar")
    demos.set_defaults(func=_demos_command)

    evaluate = sub.add_parser("evaluate", help="precision/recall and DwPR of trained generators (paper section 5.2)")
    evaluate.add_argument("models", nargs="+", metavar="MODEL_FILE", help="trained generator files")
    evaluate.add_argument("--data", required=True, help="real trajectories: dataset path or .npy (N, T, M) array")
    evaluate.add_argument("--out", required=True, help="output directory (results.csv/.md/.json, scatter plots)")
    evaluate.add_argument("--n", type=int, default=15000, help="real and generated samples (paper: 15000)")
    evaluate.add_argument("--dwpr-n", type=int, default=10000, help="DwPR samples per intervention (paper: 10000)")
    evaluate.add_argument("--interventions", type=int, default=5, help="DwPR interventions per dimension (paper: 5)")
    evaluate.add_argument("--k", type=int, default=3, help="neighbourhood size (paper: 3)")
    evaluate.add_argument("--seed", type=int, default=0, help="random seed")
    evaluate.add_argument("--device", default="auto", help="torch device (default: auto)")
    evaluate.set_defaults(func=_evaluate_command)

    play = sub.add_parser("play", help="play the scripted hit and throw, render them and write a short report")
    play.add_argument("--out", required=True, help="output directory (report.md, GIFs, frame strips)")
    play.set_defaults(func=_play_command)

    quick = sub.add_parser("quickstart", help="demonstrations -> VAE -> evaluation -> GenRL policy -> report, in minutes")
    quick.add_argument("--out", required=True, help="output folder (a rerun resumes it)")
    quick.add_argument("--task", choices=tasks, default=DEFAULT_TASK, help=f"task (default: {DEFAULT_TASK})")
    quick.add_argument("--demos", type=int, default=4000, help="demonstrations to generate")
    quick.add_argument("--epochs", type=int, default=300, help="beta-VAE training epochs")
    quick.add_argument("--episodes", type=int, default=3000, help="GenRL episodes")
    quick.add_argument("--seed", type=int, default=0, help="random seed")
    quick.add_argument("--no-video", action="store_true", help="skip rendering the policy")
    quick.add_argument("--device", default="auto", help="torch device (default: auto)")
    quick.set_defaults(func=_quickstart_command)

    study = sub.add_parser("study", help="the paper's experiments at a scale, with tables, plots and report.md")
    study.add_argument("--task", choices=(*tasks, "all"), default="all")
    study.add_argument("--scale", choices=("smoke", "small", "paper"), default="small")
    study.add_argument("--out", required=True, help="study folder (a rerun resumes it)")
    study.add_argument("--executor", choices=("local", "ray"), default="local", help="worker processes or Ray tasks")
    study.add_argument("--address", default=None, help="Ray cluster address (ray executor)")
    study.add_argument("--workers", type=int, default=None, help="local worker processes (default: the cores)")
    study.add_argument("--models", nargs="+", default=None, help="a subset of VAE1..VAE9 GAN1..GAN9 (default all)")
    study.add_argument("--device", default="auto", help="torch device (default: auto)")
    study.set_defaults(func=_study_command)

    video = sub.add_parser("video", help="render a GenRL policy (or a generator's random trajectories) to MP4 or GIF")
    video.add_argument("--task", required=True, choices=tasks)
    source = video.add_mutually_exclusive_group(required=True)
    source.add_argument("--policy", help="a GenRL run folder or model zip")
    source.add_argument("--generator", help="a generator file (random latent actions)")
    video.add_argument("--goals", type=int, default=6, help="episodes (goals) to show")
    video.add_argument("--seed", type=int, default=0, help="seed of the goals (and of the latent actions)")
    video.add_argument("--out", required=True, help="output file, .mp4 or .gif")
    video.set_defaults(func=_video_command)

    baseline = sub.add_parser("baseline", help="train PPO (BC), SAC (prefilled) or a stock algorithm on the latent space")
    baseline.add_argument("algorithm", choices=("ppo", "sac", "latent-ppo", "latent-sac", "latent-trpo"))
    baseline.add_argument("--task", required=True, choices=tasks, help="task")
    baseline.add_argument("--demos", default=None, help="demonstration dataset (ppo, sac)")
    baseline.add_argument("--demo-episodes", type=int, default=None, help="use the first N demonstrations (default all)")
    baseline.add_argument("--generator", default=None, help="generator file (latent-ppo, latent-sac, latent-trpo)")
    baseline.add_argument("--episodes", type=int, required=True, help="budget of episodes")
    baseline.add_argument("--seed", type=int, default=0, help="random seed")
    baseline.add_argument("--bc-epochs", type=int, default=5, help="behaviour cloning epochs (ppo)")
    baseline.add_argument("--device", default="auto", help="torch device (default: auto)")
    baseline.add_argument("--no-progress-bar", action="store_true", help="hide the progress bar")
    baseline.add_argument("--out", required=True, help="output directory")
    baseline.set_defaults(func=_baseline_command)

    compare = sub.add_parser("compare", help="GenRL vs baselines over seeds: reward curves and table contacts")
    compare.add_argument("--task", default=None, choices=tasks, help="only runs of this task")
    compare.add_argument("--runs", nargs="+", required=True, help="run directories (several seeds per method)")
    compare.add_argument("--out", required=True, help="output directory")
    compare.set_defaults(func=_compare_command)

    train_policy = sub.add_parser("train-policy", help="train a GenRL policy over a generator's latent space (Algorithm 1)")
    train_policy.add_argument("--task", required=True, choices=tasks, help="task")
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
    train_generator.add_argument("--std-floor", type=float, default=None,
                                 help="floor of each normalisation std as a fraction of the largest (default 0.05)")
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


def _evaluate_command(args: argparse.Namespace) -> int:
    from sb3_genrl.metrics import evaluate_generators

    evaluations = evaluate_generators(args.models, args.data, n=args.n, k=args.k, dwpr_n=args.dwpr_n,
                                      interventions=args.interventions, seed=args.seed, out_dir=args.out,
                                      device=args.device)
    for evaluation in evaluations:
        row = evaluation.row()
        print(f"{row['model']}: precision {row['precision']:.3f}, recall {row['recall']:.3f}, "
              f"delta_1 {row['delta_1']:.3f}, mean delta {row['mean_delta']:.3f}")
    print(f"wrote {args.out}/results.md, results.csv, precision_recall.png, disentanglement.png")
    return 0


def _baseline_command(args: argparse.Namespace) -> int:
    from sb3_genrl.baselines.train import train_baseline

    summary = train_baseline(args.algorithm, args.task, episodes=args.episodes, out_dir=args.out, seed=args.seed,
                             demos=args.demos, demo_episodes=args.demo_episodes, generator=args.generator,
                             bc_epochs=args.bc_epochs, device=args.device, progress_bar=not args.no_progress_bar)
    if "bc_mean_reward" in summary:
        print(f"behaviour cloning alone: mean reward {summary['bc_mean_reward']:.4g}")
    print(f"{args.algorithm} on {args.task}: {summary['episodes_played']} episodes, final mean reward "
          f"{summary['final_mean_reward']:.4g}, best {summary['best_mean_reward']:.4g} -> {args.out}")
    return 0


def _compare_command(args: argparse.Namespace) -> int:
    from sb3_genrl.baselines.compare import compare_runs

    print(compare_runs(args.runs, args.out, task=args.task).read_text())
    return 0


def _study_command(args: argparse.Namespace) -> int:
    from sb3_genrl.study import MODELS, run_study

    report = run_study(args.task, args.scale, args.out, executor=args.executor, address=args.address,
                       workers=args.workers, models=tuple(args.models) if args.models else MODELS, device=args.device,
                       log=print)
    print(f"wrote {report}")
    return 0


def _video_command(args: argparse.Namespace) -> int:
    from sb3_genrl.video import record_video

    result = record_video(args.task, args.out, policy=args.policy, generator=args.generator, goals=args.goals,
                          seed=args.seed)
    print(f"wrote {result['video']} (rewards {', '.join(f'{r:.3f}' for r in result['rewards'])})")
    return 0


def _quickstart_command(args: argparse.Namespace) -> int:
    from sb3_genrl.study.quickstart import quickstart

    report = quickstart(args.out, task=args.task, demo_episodes=args.demos, epochs=args.epochs,
                        policy_episodes=args.episodes, seed=args.seed, video=not args.no_video, device=args.device,
                        log=print)
    print(f"wrote {report}")
    return 0


def _play_command(args: argparse.Namespace) -> int:
    from sb3_genrl.showcase import play_scripted

    print(f"wrote {play_scripted(args.out)}")
    return 0


def _train_generator_command(args: argparse.Namespace) -> int:
    from sb3_genrl.generative import train_generator

    generator = train_generator(args.data, model=args.model, preset=args.preset, latent_dim=args.latent_dim,
                                beta=args.beta, info_weight=args.info_weight, std_floor=args.std_floor, epochs=args.epochs,
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


def _demos_command(args: argparse.Namespace) -> int:
    import time

    from sb3_genrl.data import dataset_info
    from sb3_genrl.envs.demonstrations import make_demonstrations

    began = time.perf_counter()
    path = make_demonstrations(args.task, args.episodes, args.out, seed=args.seed, n_threads=args.threads,
                               progress_bar=not args.no_progress_bar)
    info = dataset_info(path)
    report = json.loads((path / "coverage.json").read_text())
    print(f"{info['episodes']} {info['task']} demonstrations ({info['drawn']} drawn) in {time.perf_counter() - began:.1f} s"
          f" -> {path}")
    print(f"coverage: {100 * report['coverage']:.1f}% of {report['cells']} goal-region cells of {report['cell_size']} m"
          f" ({100 * report['in_region']:.1f}% of reached points in the region) -> {report['png']}")
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
