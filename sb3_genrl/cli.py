"""The ``genrl`` command line. Each command parses its arguments, checks every value and output path before any work
(:mod:`sb3_genrl.checks`), and calls one library function that a user could call too.

One grammar for all commands: ``--task`` is a registered task (:data:`sb3_genrl.envs.TASKS`); ``--demos`` is a
demonstration dataset and ``--episodes`` / ``--demo-episodes`` are counts; ``--out`` is where the results go;
``--seed``, ``--device`` and ``--no-progress-bar`` mean the same wherever they appear.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

from sb3_genrl.checks import (
    COUNT,
    EXISTING,
    OUT_DIR,
    SEED,
    check_device,
    check_int,
    check_non_negative_float,
    check_output_dir,
    check_output_file,
    check_positive_float,
    option,
)

WORKFLOW = ("play", "demos", "train-generator", "evaluate", "train-policy", "baseline", "compare", "video", "quickstart",
            "study")
# Errors that a bad argument or path raises in the library: printed as one line, exit status 2 (as argparse does).
KNOWN_ERRORS = (ValueError, FileNotFoundError, PermissionError, FileExistsError, IsADirectoryError, NotADirectoryError)

def build_parser() -> argparse.ArgumentParser:
    """The ``genrl`` parser: one sub-parser per command, in workflow order (:data:`WORKFLOW`)."""
    from sb3_genrl import __version__

    parser = argparse.ArgumentParser(
        prog="genrl", description="GenRL for Stable-Baselines3: tasks, demonstrations, generators, evaluation, policies, "
        "baselines and the paper's study.", epilog="The commands are listed in workflow order: play the scripted "
        "motions, make demonstrations, train a generator, evaluate it, train a GenRL policy, train baselines, compare "
        "them, render a video; quickstart and study run the whole workflow. 'genrl COMMAND --help' for its options.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", title="commands (in workflow order)")
    for add in (_add_play, _add_demos, _add_train_generator, _add_evaluate, _add_train_policy, _add_baseline,
                _add_compare, _add_video, _add_quickstart, _add_study):
        add(sub)
    return parser


def _task_option(parser: argparse.ArgumentParser, *, required: bool = True, default: str | None = None,
                 extra: tuple[str, ...] = (), nargs: str | None = None) -> None:
    from sb3_genrl.envs import TASKS

    parser.add_argument("--task", required=required, default=default, choices=(*TASKS, *extra), nargs=nargs,
                        help="a registered task" + (f" (default: {default})" if default else ""))


def _seed_option(parser: argparse.ArgumentParser, text: str = "seed of every random draw") -> None:
    parser.add_argument("--seed", type=SEED, default=0, help=f"{text} (default: 0)")


def _device_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--device", type=option(check_device), default="auto",
                        help="torch device: auto, cpu, cuda, cuda:N, mps (default: auto)")


def _progress_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-progress-bar", action="store_true", help="hide the progress bar")


def _add_play(sub: argparse._SubParsersAction) -> None:
    play = sub.add_parser("play", help="play each task's scripted expert, render it and write a short report")
    play.add_argument("--out", required=True, type=OUT_DIR, help="output folder (report.md, GIFs, frame strips)")
    _task_option(play, required=False, nargs="+")
    _seed_option(play, "seed of the scripted motions")
    play.set_defaults(func=_play_command)


def _add_demos(sub: argparse._SubParsersAction) -> None:
    demos = sub.add_parser("demos", help="generate a task's demonstrations as a Minari dataset, with a coverage report")
    _task_option(demos)
    demos.add_argument("--episodes", type=COUNT, default=40000, help="valid demonstrations to keep (paper: 40000)")
    demos.add_argument("--out", required=True, type=option(_check_dataset_out),
                       help="dataset folder to create (must not exist or be empty)")
    _seed_option(demos)
    demos.add_argument("--threads", type=COUNT, default=None, help="simulation threads (default: available cores)")
    _progress_option(demos)
    demos.set_defaults(func=_demos_command)


def _check_dataset_out(path: str, name: str = "") -> Path:
    """A dataset folder to create: writable, and missing or empty (else the error says what is in the way).

    :param path: the folder
    :param name: the argument's name, for the error message
    """
    from sb3_genrl.envs.demonstrations import refuse_existing_output

    out = check_output_dir(path, name)
    refuse_existing_output(out.absolute())
    return out


def _add_train_generator(sub: argparse._SubParsersAction) -> None:
    from sb3_genrl.generative import PRESETS

    gen = sub.add_parser("train-generator", help="train a beta-VAE or InfoGAN on demonstration trajectories")
    gen.add_argument("--data", required=True, type=EXISTING, help="demonstration dataset or .npy/.npz (N, T, M) array")
    gen.add_argument("--model", choices=("vae", "gan"), default=None, help="model kind (default: vae)")
    gen.add_argument("--preset", type=str.upper, choices=tuple(PRESETS), default=None,
                     help="paper table 1 model: VAE1..VAE9 or GAN1..GAN9")
    gen.add_argument("--latent-dim", type=COUNT, default=None, help="latent dimension N_alpha")
    gen.add_argument("--beta", type=option(check_non_negative_float, float), default=None, help="KL weight (beta-VAE)")
    gen.add_argument("--info-weight", type=option(check_non_negative_float, float), default=None,
                     help="information weight lambda (InfoGAN)")
    gen.add_argument("--std-floor", type=option(check_positive_float, float), default=None,
                     help="floor of each normalisation std as a fraction of the largest (default 0.05)")
    gen.add_argument("--epochs", type=COUNT, default=5000, help="training epochs (paper: 5000)")
    gen.add_argument("--batch-size", type=COUNT, default=256, help="minibatch size (paper: 256)")
    gen.add_argument("--lr", type=option(check_positive_float, float), default=2e-4, help="Adam learning rate (2e-4)")
    _seed_option(gen, "training seed")
    gen.add_argument("--eval-every", type=COUNT, default=10, help="epochs between model-selection evaluations")
    _device_option(gen)
    gen.add_argument("--tensorboard-log", type=OUT_DIR, default=None, help="TensorBoard log folder")
    _progress_option(gen)
    gen.add_argument("--out", required=True, type=option(check_output_file), help="file to write the generator to")
    gen.set_defaults(func=_train_generator_command)


def _add_evaluate(sub: argparse._SubParsersAction) -> None:
    evaluate = sub.add_parser("evaluate", help="precision/recall and DwPR of trained generators (paper section 5.2)")
    evaluate.add_argument("models", nargs="+", type=EXISTING, metavar="MODEL_FILE", help="trained generator files")
    evaluate.add_argument("--data", required=True, type=EXISTING,
                          help="real trajectories: demonstration dataset or .npy/.npz (N, T, M) array")
    evaluate.add_argument("--out", required=True, type=OUT_DIR, help="output folder (results.csv/.md/.json, plots)")
    evaluate.add_argument("--n", type=COUNT, default=15000, help="real and generated samples, at most the data's (15000)")
    evaluate.add_argument("--dwpr-n", type=COUNT, default=10000, help="DwPR samples per intervention (paper: 10000)")
    evaluate.add_argument("--interventions", type=COUNT, default=5, help="DwPR interventions per dimension (paper: 5)")
    evaluate.add_argument("--k", type=COUNT, default=3, help="neighbourhood size (paper: 3)")
    _seed_option(evaluate)
    _device_option(evaluate)
    evaluate.set_defaults(func=_evaluate_command)


def _add_train_policy(sub: argparse._SubParsersAction) -> None:
    policy = sub.add_parser("train-policy", help="train a GenRL policy over a generator's latent space (Algorithm 1)")
    _task_option(policy)
    policy.add_argument("--generator", required=True, type=EXISTING, help="file of a trained generator")
    policy.add_argument("--episodes", type=COUNT, required=True, help="episodes (trajectories played) in total")
    _seed_option(policy)
    policy.add_argument("--out", required=True, type=OUT_DIR, help="output folder (model, learning curve, logs)")
    policy.add_argument("--e-step", choices=("trpo", "kl_penalty"), default="trpo", help="E-step variant")
    policy.add_argument("--batch-episodes", type=option(check_int, int, minimum=2), default=None,
                        help="episodes per EM iteration N, at least 2 (default: the task's, or 64 with "
                             "--library-defaults)")
    policy.add_argument("--n-envs", type=COUNT, default=1,
                        help="envs played at a time, each in its own process (one per core); a divisor of "
                             "--batch-episodes (default 1)")
    policy.add_argument("--library-defaults", action="store_true",
                        help="GenRL's own defaults instead of the task's GenRL settings and batch_episodes")
    policy.add_argument("--hindsight", action="store_true",
                        help="relabel each episode with the goal it reached (GenRL's hindsight=True)")
    policy.add_argument("--hindsight-history", type=COUNT, default=None, metavar="K",
                        help="with --hindsight: reuse the relabelled episodes of the last K iterations (GenRL's "
                             "hindsight_history; default: the task's, else 1: this iteration's only)")
    policy.add_argument("--hindsight-regression", type=option(check_int, int, minimum=0), default=None,
                        metavar="STEPS",
                        help="with --hindsight: Adam steps per iteration fitting the policy's mean to the kept "
                             "relabelled episodes (GenRL's hindsight_regression; default: the task's, else 0: none)")
    policy.add_argument("--hindsight-regression-weighted", action="store_true",
                        help="with --hindsight-regression: weight each episode by the policy's density at it, so that "
                             "the fit keeps to one of several ways to reach a goal (GenRL's "
                             "hindsight_regression_weighted; default: the task's, else off)")
    _device_option(policy)
    _progress_option(policy)
    policy.set_defaults(func=_train_policy_command)


def _add_baseline(sub: argparse._SubParsersAction) -> None:
    from sb3_genrl.baselines import BASELINES
    from sb3_genrl.baselines.hyperparameters import json_object_argument

    baseline = sub.add_parser("baseline", help="train PPO (BC), SAC (with or without prefilled buffer), SAC+HER, or a "
                              "stock algorithm on the latent space")
    baseline.add_argument("algorithm", choices=BASELINES)
    _task_option(baseline)
    baseline.add_argument("--demos", type=EXISTING, default=None,
                          help="demonstration dataset (ppo, sac, sac-no-prefill, sac-her)")
    baseline.add_argument("--demo-episodes", type=COUNT, default=None, help="use the first N demonstrations (default all)")
    baseline.add_argument("--generator", type=EXISTING, default=None, help="generator file (latent-ppo/-sac/-trpo)")
    baseline.add_argument("--episodes", type=COUNT, required=True, help="budget of episodes")
    _seed_option(baseline)
    baseline.add_argument("--algorithm-kwargs", type=json_object_argument, default=None, metavar="JSON",
                          help="changes to the rl-zoo3 settings, as arguments of the SB3 class, e.g. "
                               "'{\"target_kl\": 0.02}' for ppo (default: none)")
    baseline.add_argument("--bc-max-epochs", type=COUNT, default=200,
                          help="most behaviour cloning epochs; it stops earlier on its held-out loss (ppo)")
    baseline.add_argument("--checkpoint-every", type=option(check_int, int, minimum=0), default=250,
                          help="episodes between checkpoints of sac, sac-no-prefill and sac-her; a rerun into the same "
                               "--out resumes from the last one (0: none; default 250)")
    _device_option(baseline)
    _progress_option(baseline)
    baseline.add_argument("--out", required=True, type=OUT_DIR, help="output folder")
    baseline.set_defaults(func=_baseline_command)


def _add_compare(sub: argparse._SubParsersAction) -> None:
    compare = sub.add_parser("compare", help="GenRL vs baselines over seeds: reward curves and table contacts")
    _task_option(compare, required=False)
    compare.add_argument("--runs", nargs="+", required=True, type=EXISTING, help="run folders (several seeds per method)")
    compare.add_argument("--out", required=True, type=OUT_DIR, help="output folder")
    compare.set_defaults(func=_compare_command)


def _add_video(sub: argparse._SubParsersAction) -> None:
    from sb3_genrl.video import VIDEO_SUFFIXES

    video = sub.add_parser("video", help="render a GenRL policy (or a generator's random trajectories) to MP4 or GIF")
    _task_option(video)
    source = video.add_mutually_exclusive_group(required=True)
    source.add_argument("--policy", type=EXISTING, help="a GenRL run folder or model zip")
    source.add_argument("--generator", type=EXISTING, help="a generator file (random latent actions)")
    video.add_argument("--trust-policy", action="store_true",
                       help="unpickle the policy zip as SB3 does (runs code stored in it: only for trusted files)")
    video.add_argument("--goals", type=COUNT, default=6, help="episodes (goals) to show")
    _seed_option(video, "seed of the goals (and of the latent actions)")
    video.add_argument("--out", required=True, type=option(check_output_file, suffixes=VIDEO_SUFFIXES),
                       help="output file, .mp4 or .gif")
    video.set_defaults(func=_video_command)


def _add_quickstart(sub: argparse._SubParsersAction) -> None:
    from sb3_genrl.envs import DEFAULT_TASK, TASKS
    from sb3_genrl.study.quickstart import policy_settings

    quick = sub.add_parser("quickstart", help="demonstrations -> VAE -> evaluation -> GenRL policy -> report, in minutes")
    quick.add_argument("--out", required=True, type=OUT_DIR, help="output folder (a rerun resumes it)")
    _task_option(quick, required=False, default=DEFAULT_TASK)
    quick.add_argument("--demo-episodes", type=COUNT, default=4000, help="demonstrations to generate (default 4000)")
    quick.add_argument("--epochs", type=COUNT, default=300, help="beta-VAE training epochs (default 300)")
    own = ", ".join(f"{name} {policy_settings(spec)[0]}" for name, spec in TASKS.items())
    quick.add_argument("--episodes", type=COUNT, default=None, help=f"GenRL episodes (default: the task's own: {own})")
    _seed_option(quick)
    quick.add_argument("--no-video", action="store_true", help="skip rendering the policy")
    _device_option(quick)
    _progress_option(quick)
    quick.set_defaults(func=_quickstart_command)


def _add_study(sub: argparse._SubParsersAction) -> None:
    from sb3_genrl.study import MODELS, SCALES

    study = sub.add_parser("study", help="the paper's experiments at a scale, with tables, plots and report.md")
    _task_option(study, required=False, default="all", extra=("all",))
    study.add_argument("--scale", choices=tuple(SCALES), default="small", help="size of every stage (default: small)")
    study.add_argument("--out", required=True, type=OUT_DIR, help="study folder (a rerun resumes it)")
    study.add_argument("--executor", choices=("local", "ray"), default="local", help="worker processes or Ray tasks")
    study.add_argument("--address", default=None, help="Ray cluster address (ray executor)")
    study.add_argument("--ray-timeout", type=option(check_positive_float, float), default=30.0,
                       help="seconds to connect to --address (default 30)")
    study.add_argument("--workers", type=COUNT, default=None, help="local worker processes (default: the cores)")
    study.add_argument("--models", nargs="+", choices=MODELS, default=None, help="a subset of VAE1..GAN9 (default all)")
    _device_option(study)
    study.set_defaults(func=_study_command)


def _play_command(args: argparse.Namespace) -> int:
    from sb3_genrl.showcase import play_scripted

    print(f"wrote {play_scripted(args.out, tasks=tuple(args.task) if args.task else None, seed=args.seed)}")
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


def _train_generator_command(args: argparse.Namespace) -> int:
    from sb3_genrl.generative import train_generator

    generator = train_generator(args.data, model=args.model, preset=args.preset, latent_dim=args.latent_dim,
                                beta=args.beta, info_weight=args.info_weight, std_floor=args.std_floor, epochs=args.epochs,
                                batch_size=args.batch_size, lr=args.lr, seed=args.seed, eval_every=args.eval_every,
                                out=args.out, tensorboard_log=args.tensorboard_log and str(args.tensorboard_log),
                                progress_bar=not args.no_progress_bar, device=args.device)
    best = next((entry for entry in generator.history if entry["epoch"] == generator.best_epoch), {})
    print(f"{type(generator).__name__} (T={generator.horizon}, M={generator.action_dim}, N_alpha={generator.latent_dim})"
          f" best epoch {generator.best_epoch}, selection MSE {best.get('selection_mse', float('nan')):.6g}"
          f" -> {args.out}")
    return 0


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


def _train_policy_command(args: argparse.Namespace) -> int:
    from sb3_genrl.envs import get_task
    from sb3_genrl.genrl import train_policy
    from sb3_genrl.study.quickstart import DEFAULT_BATCH_EPISODES, policy_batch_episodes, policy_settings

    spec = get_task(args.task)
    genrl_kwargs = {} if args.library_defaults else policy_settings(spec)[1]
    batch_episodes = args.batch_episodes or (DEFAULT_BATCH_EPISODES if args.library_defaults
                                             else policy_batch_episodes(spec))
    for flag, value in (("--hindsight-history", args.hindsight_history),
                        ("--hindsight-regression", args.hindsight_regression)):
        if value is not None and not args.hindsight:
            raise ValueError(f"argument {flag}: needs --hindsight")
    if args.e_step == "kl_penalty" and genrl_kwargs.get("hindsight") and not args.hindsight:
        raise ValueError(f"argument --e-step: {args.task}'s GenRL settings relabel episodes in hindsight, which the "
                         "KL-penalty E-step does not support; add --library-defaults to train with GenRL's own "
                         "defaults")
    if args.hindsight:
        genrl_kwargs = {**genrl_kwargs, "hindsight": True}
    if args.hindsight_history is not None:
        genrl_kwargs["hindsight_history"] = args.hindsight_history
    if args.hindsight_regression is not None:
        genrl_kwargs["hindsight_regression"] = args.hindsight_regression
    if args.hindsight_regression_weighted:
        if not genrl_kwargs.get("hindsight_regression"):
            raise ValueError("argument --hindsight-regression-weighted: needs --hindsight-regression (the settings "
                             "in use have no hindsight regression)")
        genrl_kwargs["hindsight_regression_weighted"] = True
    result = train_policy(args.task, str(args.generator), episodes=args.episodes, seed=args.seed, out_dir=args.out,
                          e_step=args.e_step, batch_episodes=batch_episodes, n_envs=args.n_envs,
                          device=args.device, progress_bar=not args.no_progress_bar, **genrl_kwargs)
    print(f"GenRL on {args.task}: {result['episodes']} episodes, {result['iterations']} iterations, mean reward "
          f"final {result['final_mean_reward']:.4g}, best {result['best_mean_reward']:.4g} -> {result['model_path']}")
    return 0


def _baseline_command(args: argparse.Namespace) -> int:
    from sb3_genrl.baselines.train import train_baseline

    summary = train_baseline(args.algorithm, args.task, episodes=args.episodes, out_dir=args.out, seed=args.seed,
                             demos=args.demos, demo_episodes=args.demo_episodes, generator=args.generator,
                             bc_kwargs={"max_epochs": args.bc_max_epochs}, algorithm_kwargs=args.algorithm_kwargs,
                             checkpoint_every=args.checkpoint_every or None,
                             device=args.device, progress_bar=not args.no_progress_bar)
    if "bc" in summary:
        bc, first = summary["bc"], summary["first_batch"]
        print(f"behaviour cloning ({bc['epochs']} epochs, best {bc['best_epoch']}): mean distance to {bc['eval_goals']} "
              f"held-out goals {bc['deterministic_distance']:.3f} m deterministic, {bc['sampled_distance']:.3f} m sampled;"
              + (f" PPO's first batch ({first['episodes']} episodes) {first['mean_distance']:.3f} m"
                 if first["episodes"] else ""))
    final = summary["final_eval"]
    print(f"{args.algorithm} on {args.task}: {summary['episodes_played']} episodes, final mean reward "
          f"{summary['final_mean_reward']:.4g}, best {summary['best_mean_reward']:.4g}; the trained policy, "
          f"deterministic: mean distance to {final['goals']} held-out goals {final['mean_distance']:.3f} m "
          f"({final['object_unmoved']} of them with the object not moved) -> {args.out}")
    return 0


def _compare_command(args: argparse.Namespace) -> int:
    from sb3_genrl.baselines.compare import compare_runs

    print(compare_runs(args.runs, args.out, task=args.task).read_text())
    return 0


def _video_command(args: argparse.Namespace) -> int:
    from sb3_genrl.video import record_video

    result = record_video(args.task, args.out, policy=args.policy, generator=args.generator, goals=args.goals,
                          seed=args.seed, trust_policy=args.trust_policy)
    print(f"wrote {result['video']} (rewards {', '.join(f'{r:.3f}' for r in result['rewards'])})")
    return 0


def _quickstart_command(args: argparse.Namespace) -> int:
    from sb3_genrl.study.quickstart import quickstart

    report = quickstart(args.out, task=args.task, demo_episodes=args.demo_episodes, epochs=args.epochs,
                        policy_episodes=args.episodes, seed=args.seed, video=not args.no_video, device=args.device,
                        progress_bar=not args.no_progress_bar, log=print)
    print(f"wrote {report}")
    return 0


def _study_command(args: argparse.Namespace) -> int:
    from sb3_genrl.study import MODELS, run_study

    report = run_study(args.task, args.scale, args.out, executor=args.executor, address=args.address,
                       workers=args.workers, models=tuple(args.models) if args.models else MODELS, device=args.device,
                       connect_timeout=args.ray_timeout, log=print)
    print(f"wrote {report}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run ``genrl`` with ``argv`` (default: the command line); a known error is printed as one line, exit status 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    command: Callable[[argparse.Namespace], int] = args.func
    try:
        return int(command(args) or 0)
    except KNOWN_ERRORS as error:
        print(f"genrl {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
