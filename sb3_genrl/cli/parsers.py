"""The ``genrl`` command line's sub-parsers, one per command (:data:`sb3_genrl.cli.WORKFLOW`): each checks every
value and output path as it parses (:mod:`sb3_genrl.checks`) and names its command in :mod:`sb3_genrl.cli.commands`."""

from __future__ import annotations

import argparse
from pathlib import Path

from sb3_genrl.baselines import BASELINES
from sb3_genrl.checks import (
    COUNT,
    EPISODES,
    EXISTING,
    MAX_EPISODES,
    MAX_VIDEO_EPISODES,
    OUT_DIR,
    SEED,
    check_device,
    check_fraction,
    check_int,
    check_non_negative_float,
    check_output_dir,
    check_output_file,
    check_positive_float,
    json_object_argument,
    option,
)
from sb3_genrl.cli import commands
from sb3_genrl.envs import DEFAULT_TASK, TASKS, arm_tasks
from sb3_genrl.envs.demonstrations import DEFAULT_NOISE, refuse_existing_output
from sb3_genrl.envs.external import load_expert, resolve_task
from sb3_genrl.generative import PRESETS
from sb3_genrl.generative.presets import TASK_PRESETS
from sb3_genrl.generative.torch_generator import SELECTIONS
from sb3_genrl.hyperparams import known_env_ids, load_hyperparams
from sb3_genrl.metrics.scorecard import NOT_CONVERGED_PRECISION, RANK_MEASURES
from sb3_genrl.run.checkpoint import CHECKPOINT_EVERY
from sb3_genrl.study import MODELS, SCALES
from sb3_genrl.study.quickstart import (
    DEMO_EPISODES,
    MIN_DEMO_EPISODES,
    OUTSIDE_DEMO_EPISODES,
    OUTSIDE_DEMO_STEPS,
    QUICKSTART_MAX_EPISODES,
)
from sb3_genrl.video import REAL_TIME_FPS, VIDEO_SUFFIXES


def _expert_option(parser: argparse.ArgumentParser) -> None:
    """``--expert MODULE:FUNCTION``, the expert of a task from outside the package (``demos`` and ``quickstart``)."""
    parser.add_argument(
        "--expert",
        type=option(_check_expert),
        default=None,
        metavar="MODULE:FUNCTION",
        help="the expert of a task the package does not register, observation -> action, played closed loop with "
        "perturbations; each demonstration is kept only when its actions replayed open loop from its seeded reset "
        "still succeed (metaworld/<name> comes with Meta-World's scripted expert)",
    )


def _task_option(
    parser: argparse.ArgumentParser,
    *,
    required: bool = True,
    default: str | None = None,
    extra: tuple[str, ...] = (),
    nargs: str | None = None,
    arm_only: bool = False,
    external: bool = False,
) -> None:
    if external:  # any episodic Gymnasium task, checked as it parses (sb3_genrl.envs.external.resolve_task)
        parser.add_argument(
            "--task",
            required=required,
            default=default,
            type=option(_check_task),
            help="a registered task, metaworld/<name> (one of Meta-World's 50 v3 tasks), a registered Gymnasium id, "
            "or module:Id (the module registers Id when imported: a Gymnasium id, or a name it gives with "
            "sb3_genrl.envs.external.register)" + (f" (default: {default})" if default else ""),
        )
        return
    parser.add_argument(
        "--task",
        required=required,
        default=default,
        choices=(*(arm_tasks() if arm_only else TASKS), *extra),
        nargs=nargs,
        help=("a task on the package's arm" if arm_only else "a registered task")
        + (f" (default: {default})" if default else ""),
    )


def _seed_option(parser: argparse.ArgumentParser, text: str = "seed of every random draw") -> None:
    parser.add_argument("--seed", type=SEED, default=0, help=f"{text} (default: 0)")


def _device_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--device",
        type=option(check_device),
        default="auto",
        help="torch device: auto, cpu, cuda, cuda:N, mps (default: auto)",
    )


def _progress_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-progress-bar", action="store_true", help="hide the progress bar")


def _overwrite_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a run already in --out (its files only); without it, the same command finishes or "
        "resumes that run and another run's folder is refused",
    )


def _replace_option(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument(
        "--overwrite", action="store_true", help=f"replace {what} already at --out (without it, refused before any work)"
    )


def add_play(sub: argparse._SubParsersAction) -> None:
    play = sub.add_parser("play", help="play each task's scripted expert, render it and write a short report")
    play.add_argument("--out", required=True, type=OUT_DIR, help="output folder (report.md, GIFs, frame strips)")
    _task_option(play, required=False, nargs="+", arm_only=True)
    _seed_option(play, "seed of the scripted motions")
    play.set_defaults(func=commands.play_command)


def _check_task(task: str, name: str = "") -> str:
    """A task of any kind that ``--task`` takes where it says so (:func:`sb3_genrl.envs.external.resolve_task`)."""
    resolve_task(task)
    return task


def _check_expert(spec: str, name: str = "") -> object:
    """The expert callable named ``module:function`` (:func:`sb3_genrl.envs.external.load_expert`)."""
    return load_expert(spec)


def add_demos(sub: argparse._SubParsersAction) -> None:
    demos = sub.add_parser("demos", help="generate a task's demonstrations as a Minari dataset, with a coverage report")
    _task_option(demos, external=True)
    _expert_option(demos)
    demos.add_argument(
        "--from",
        dest="source",
        default=None,
        metavar="PATH_OR_ID",
        help="instead of an expert, a dataset of actions with their reset seeds: a Minari dataset folder, the id of a "
        "Minari dataset stored locally (nothing is downloaded; its episodes must carry their reset seed, as Minari's "
        "DataCollector records it), or an .npz file with actions (N, T, M) and reset_seeds (N,); each episode is kept "
        "only when its actions replayed open loop from its seeded reset succeed (--episodes and --seed do not apply)",
    )
    demos.add_argument(
        "--noise",
        type=option(check_non_negative_float, float),
        default=None,
        help=f"with an expert: largest height of one perturbation bump, as a share of the action range's half "
        f"(default {DEFAULT_NOISE}; 0: unperturbed)",
    )
    demos.add_argument(
        "--horizon",
        type=_horizon_or_expert,
        default=None,
        help="with an expert or --from: control steps of a demonstration (default: the env's); with an expert, 'expert': "
        "the shortest at which its success settles on 100 seeded resets",
    )
    demos.add_argument(
        "--success-key",
        default=None,
        help="with an expert or --from: the info key of the env's success (default is_success, falling back to success)",
    )
    demos.add_argument(
        "--episodes",
        type=EPISODES,
        default=None,
        help=f"valid demonstrations to keep (default {commands.DEMONSTRATIONS}, the paper's); with --from: replay only the "
        "dataset's first N episodes (default: all)",
    )
    demos.add_argument(
        "--out", required=True, type=option(_check_dataset_out), help="dataset folder to create (must not exist or be empty)"
    )
    demos.add_argument(
        "--seed",
        type=SEED,
        default=None,
        help="seed of every random draw (default: 0); not with --from, whose episodes start from their own reset seeds",
    )
    demos.add_argument(
        "--threads",
        type=COUNT,
        default=None,
        help="simulation threads of a package's own task, or worker processes that play an expert's episodes "
        "(default: available cores; the dataset does not depend on it)",
    )
    _progress_option(demos)
    demos.set_defaults(func=commands.demos_command)


def _check_dataset_out(path: str, name: str = "") -> Path:
    """A dataset folder to create: writable, and missing or empty (else the error says what is in the way).

    :param path: the folder
    :param name: the argument's name, for the error message
    """
    out = check_output_dir(path, name)
    refuse_existing_output(out.absolute())
    return out


def add_train_generator(sub: argparse._SubParsersAction) -> None:
    gen = sub.add_parser("train-generator", help="train a beta-VAE or InfoGAN on demonstration trajectories")
    gen.add_argument("--data", required=True, type=EXISTING, help="demonstration dataset or .npy/.npz (N, T, M) array")
    gen.add_argument("--model", choices=("vae", "gan"), default=None, help="model kind (default: vae)")
    gen.add_argument(
        "--preset",
        type=str.upper,
        choices=(*PRESETS, *TASK_PRESETS),
        default=None,
        help="paper table 1 model, VAE1..VAE9 or GAN1..GAN9, or VAE-FETCH (the Fetch and Meta-World quickstarts' "
        "generator: 10 latent dimensions, beta 0.001)",
    )
    gen.add_argument("--latent-dim", type=COUNT, default=None, help="latent dimension N_alpha")
    gen.add_argument("--beta", type=option(check_non_negative_float, float), default=None, help="KL weight (beta-VAE)")
    gen.add_argument(
        "--info-weight", type=option(check_non_negative_float, float), default=None, help="information weight lambda (InfoGAN)"
    )
    gen.add_argument(
        "--std-floor",
        type=option(check_fraction, float),
        default=None,
        help="floor of each normalisation std as a fraction of the largest (default 0.05)",
    )
    gen.add_argument("--epochs", type=COUNT, default=5000, help="training epochs (paper: 5000)")
    gen.add_argument("--batch-size", type=COUNT, default=256, help="minibatch size (paper: 256)")
    gen.add_argument("--lr", type=option(check_positive_float, float), default=2e-4, help="Adam learning rate (2e-4)")
    _seed_option(gen, "training seed")
    gen.add_argument("--eval-every", type=COUNT, default=10, help="epochs between model-selection evaluations")
    gen.add_argument(
        "--selection",
        choices=SELECTIONS,
        default="prior",
        help="how the kept checkpoint is chosen: 'prior' (the paper's: generated trajectories against their nearest "
        "held-out ones) or 'reconstruction' (a VAE: the held-out trajectories decoded from their posterior means)",
    )
    gen.add_argument(
        "--min-steps",
        type=option(check_int, int, minimum=0),
        default=0,
        help="at least this many minibatch steps: on a small dataset the epochs are raised to reach them (default 0)",
    )
    gen.add_argument(
        "--even-batches",
        action="store_true",
        help="minibatches of nearly equal sizes (at most --batch-size) instead of full ones and a remainder",
    )
    _device_option(gen)
    gen.add_argument("--tensorboard-log", type=OUT_DIR, default=None, help="TensorBoard log folder")
    _progress_option(gen)
    gen.add_argument("--out", required=True, type=option(check_output_file), help="file to write the generator to")
    gen.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a generator already at --out (the policies trained on it then refuse it, by its digest); "
        "without it an existing --out is refused before training",
    )
    gen.set_defaults(func=commands.train_generator_command)


def add_evaluate(sub: argparse._SubParsersAction) -> None:
    evaluate = sub.add_parser(
        "evaluate",
        help="precision/recall, DwPR, density/coverage and, with --task, the prior "
        "rollout of trained generators: a ranked scorecard (paper section 5.2)",
    )
    evaluate.add_argument("models", nargs="+", type=EXISTING, metavar="MODEL_FILE", help="trained generator files")
    evaluate.add_argument(
        "--data", required=True, type=EXISTING, help="real trajectories: demonstration dataset or .npy/.npz (N, T, M) array"
    )
    evaluate.add_argument("--out", required=True, type=OUT_DIR, help="output folder (results.csv/.md/.json, plots)")
    evaluate.add_argument(
        "--n",
        type=COUNT,
        default=15000,
        help="real and generated samples (paper, default: 15000); the data must hold at least as many trajectories",
    )
    evaluate.add_argument("--dwpr-n", type=COUNT, default=10000, help="DwPR samples per intervention (paper: 10000)")
    evaluate.add_argument("--interventions", type=COUNT, default=5, help="DwPR interventions per dimension (paper: 5)")
    evaluate.add_argument("--k", type=COUNT, default=3, help="neighbourhood size (paper: 3)")
    _seed_option(evaluate)
    _device_option(evaluate)
    _task_option(evaluate, required=False, external=True)
    evaluate.add_argument("--contexts", type=COUNT, default=None, help="prior rollout (with --task): goals (64)")
    evaluate.add_argument("--draws", type=COUNT, default=None, help="prior rollout: prior draws per goal (16)")
    evaluate.add_argument(
        "--prior-seed",
        type=SEED,
        default=None,
        help="prior rollout: seed of its goals (4242: neither the final evaluations' nor the tuning's)",
    )
    evaluate.add_argument(
        "--rank-by", default=None, choices=RANK_MEASURES, help="the measure the scorecard ranks by (default: recall)"
    )
    evaluate.add_argument(
        "--min-precision",
        type=option(check_fraction, float),
        default=NOT_CONVERGED_PRECISION,
        help="precision below which a model is marked not converged and ranked last "
        f"(default: {NOT_CONVERGED_PRECISION}; 0: none, e.g. for a VAE with a small KL weight)",
    )
    _replace_option(evaluate, "an evaluation")
    evaluate.set_defaults(func=commands.evaluate_command)


def add_train_policy(sub: argparse._SubParsersAction) -> None:
    policy = sub.add_parser("train-policy", help="train a GenRL policy over a generator's latent space (Algorithm 1)")
    _task_option(policy, external=True)
    policy.add_argument("--generator", required=True, type=EXISTING, help="file of a trained generator")
    policy.add_argument(
        "--data",
        type=EXISTING,
        default=None,
        help="the demonstration dataset, for a task whose settings learn from demonstrations (their callback "
        "sb3_genrl.genrl.demonstrations.DemonstrationCallback: the Fetch tasks, and every task without an entry in "
        "hyperparams/genrl.yml, which starts from its demonstrations); the generator's own dataset, as genrl demos "
        "wrote it",
    )
    policy.add_argument(
        "--episodes",
        type=EPISODES,
        required=True,
        help="episodes (trajectories played) in total, rounded up to whole iterations of --batch-episodes",
    )
    policy.add_argument(
        "--horizon",
        type=COUNT,
        default=None,
        help="the env's episodes truncated to this many steps: the --horizon its demonstrations were recorded with "
        "(default: the env's own length)",
    )
    policy.add_argument(
        "--success-key",
        default=None,
        help="the info key of the env's success, copied to is_success for the logs and the refits (default: a task "
        "from outside the package reads is_success, falling back to success)",
    )
    _seed_option(policy)
    policy.add_argument("--out", required=True, type=OUT_DIR, help="output folder (model, learning curve, logs)")
    policy.add_argument(
        "--e-step", choices=("trpo", "kl_penalty"), default=None, help="E-step variant (default: the settings', trpo)"
    )
    policy.add_argument(
        "--batch-episodes",
        type=option(check_int, int, minimum=2),
        default=None,
        help="batch_episodes, the episodes of one EM iteration, at least 2 (default: the task's, or 64 with "
        "--library-defaults)",
    )
    policy.add_argument(
        "--n-envs",
        type=COUNT,
        default=None,
        help="envs played at a time, a divisor of --batch-episodes (default: all of an iteration's episodes together "
        "on a task with a fast path, in one threaded simulation call on all cores; 1 on others); above 1 on a task "
        "without a fast path, one process each. The result depends on it, never on the number of cores",
    )
    policy.add_argument(
        "--library-defaults",
        action="store_true",
        help="GenRL's own defaults instead of the task's settings and batch_episodes (its entry in hyperparams/genrl.yml)",
    )
    policy.add_argument(
        "--genrl-kwargs",
        type=json_object_argument,
        default={},
        metavar="JSON",
        help="GenRL settings laid over the task's (or, with --library-defaults, GenRL's defaults), "
        'a mapping merged into a mapping, e.g. \'{"hindsight_kwargs": {"history": 30}}\' or '
        "'{\"hindsight_kwargs\": null}' (hindsight off); checked before any work",
    )
    policy.add_argument(
        "--checkpoint-every",
        type=option(check_int, int, minimum=0),
        default=CHECKPOINT_EVERY,
        help="episodes between checkpoints; a rerun of the same command into the same --out resumes "
        f"from the last one (0: none; default {CHECKPOINT_EVERY})",
    )
    _overwrite_option(policy)
    _device_option(policy)
    _progress_option(policy)
    policy.set_defaults(func=commands.train_policy_command)


def add_baseline(sub: argparse._SubParsersAction) -> None:
    baseline = sub.add_parser(
        "baseline",
        help="train PPO (BC), SAC (with or without prefilled buffer), SAC+HER, or a stock algorithm on the latent space",
    )
    baseline.add_argument("algorithm", choices=BASELINES)
    _task_option(baseline, external=True)  # a task on the package's arm, or one from outside the package (sac)
    baseline.add_argument(
        "--demos", type=EXISTING, default=None, help="demonstration dataset (ppo, sac, sac-no-prefill, sac-her)"
    )
    baseline.add_argument("--demo-episodes", type=COUNT, default=None, help="use the first N demonstrations (default all)")
    baseline.add_argument("--generator", type=EXISTING, default=None, help="generator file (latent-ppo/-sac/-trpo)")
    baseline.add_argument(
        "--episodes",
        type=EPISODES,
        required=True,
        help="budget of episodes, rounded up to whole updates (PPO's and TRPO's rollouts; the summary's episodes_played)",
    )
    _seed_option(baseline)
    baseline.add_argument(
        "--algorithm-kwargs",
        type=json_object_argument,
        default=None,
        metavar="JSON",
        help="changes to the rl-zoo3 settings, as arguments of the SB3 class, e.g. "
        "'{\"target_kl\": 0.02}' for ppo (default: none)",
    )
    baseline.add_argument(
        "--bc-max-epochs",
        type=COUNT,
        default=200,
        help="most behaviour cloning epochs; it stops earlier on its held-out loss (ppo)",
    )
    baseline.add_argument(
        "--checkpoint-every",
        type=option(check_int, int, minimum=0),
        default=None,
        help="episodes between checkpoints of sac, sac-no-prefill and sac-her (refused for the others); a rerun into "
        f"the same --out resumes from the last one (0: none; default {commands.BASELINE_CHECKPOINT_EVERY})",
    )
    baseline.add_argument(
        "--n-envs",
        type=COUNT,
        default=None,
        help="latent-ppo/-sac/-trpo: envs played at a time (default: an update's episodes together on a task with a "
        "fast path, in one threaded simulation call on all cores: ppo's and trpo's n_steps, 16 for sac). The result "
        "depends on it, never on the number of cores",
    )
    _overwrite_option(baseline)
    _device_option(baseline)
    _progress_option(baseline)
    baseline.add_argument("--out", required=True, type=OUT_DIR, help="output folder")
    baseline.set_defaults(func=commands.baseline_command)


def add_compare(sub: argparse._SubParsersAction) -> None:
    compare = sub.add_parser("compare", help="GenRL vs baselines over seeds: reward curves and table contacts")
    _task_option(compare, required=False, arm_only=True)
    compare.add_argument("--runs", nargs="+", required=True, type=EXISTING, help="run folders (several seeds per method)")
    compare.add_argument("--out", required=True, type=OUT_DIR, help="output folder")
    _replace_option(compare, "a comparison")
    compare.set_defaults(func=commands.compare_command)


def add_video(sub: argparse._SubParsersAction) -> None:
    video = sub.add_parser("video", help="render a GenRL policy (or a generator's random trajectories) to MP4 or GIF")
    _task_option(video, arm_only=True)
    source = video.add_mutually_exclusive_group(required=True)
    source.add_argument("--policy", type=EXISTING, help="a GenRL run folder or model zip")
    source.add_argument("--generator", type=EXISTING, help="a generator file (random latent actions)")
    video.add_argument(
        "--trust-policy",
        action="store_true",
        help="unpickle the policy zip as SB3 does (runs code stored in it: only for trusted files)",
    )
    video.add_argument(
        "--goals",
        type=option(check_int, int, minimum=1, maximum=MAX_VIDEO_EPISODES),
        default=6,
        help=f"episodes (goals) to show, at most {MAX_VIDEO_EPISODES} (default 6)",
    )
    video.add_argument(
        "--every",
        type=option(check_int, int, minimum=1),
        default=1,
        help=f"a frame every EVERY control steps, shown at {REAL_TIME_FPS} // EVERY frames a second, at least 1 "
        "(default 1: real time)",
    )
    _seed_option(video, "seed of the goals (and of the latent actions)")
    video.add_argument(
        "--out", required=True, type=option(check_output_file, suffixes=VIDEO_SUFFIXES), help="output file, .mp4 or .gif"
    )
    _replace_option(video, "a video")
    video.set_defaults(func=commands.video_command)


def add_quickstart(sub: argparse._SubParsersAction) -> None:
    quick = sub.add_parser("quickstart", help="demonstrations -> VAE -> evaluation -> GenRL policy -> report, in minutes")
    quick.add_argument("--out", required=True, type=OUT_DIR, help="output folder (a rerun resumes it)")
    _task_option(quick, required=False, default=DEFAULT_TASK, external=True)
    _expert_option(quick)
    quick.add_argument(
        "--horizon",
        type=COUNT,
        default=None,
        help="a task from outside the package: control steps of a demonstration and of GenRL's episodes (default: the "
        "task's; else the shortest at which the expert's success settles, written to horizon.json)",
    )
    own_demos = ", ".join(
        f"{name} {spec.quickstart_demo_episodes}" for name, spec in TASKS.items() if spec.quickstart_demo_episodes
    )
    quick.add_argument(
        "--demo-episodes",
        type=option(check_int, int, minimum=MIN_DEMO_EPISODES, maximum=MAX_EPISODES),
        default=None,
        help=f"demonstrations to generate, at least {MIN_DEMO_EPISODES} (default: {own_demos}, else {DEMO_EPISODES}; a task "
        f"from outside the package: {OUTSIDE_DEMO_EPISODES}, fewer above "
        f"{OUTSIDE_DEMO_STEPS // OUTSIDE_DEMO_EPISODES} steps a demonstration: {OUTSIDE_DEMO_STEPS} steps in all)",
    )
    quick.add_argument(
        "--epochs",
        type=COUNT,
        default=None,
        help="generator training epochs (default 300; a task from outside the package: at least 4800 minibatch steps, "
        "its epochs raised on a small dataset; given: exactly these epochs)",
    )
    own = ", ".join(
        f"{name} {load_hyperparams('genrl', spec.env_id)['n_timesteps']}"
        for name, spec in TASKS.items()
        if spec.env_id in known_env_ids("genrl")
    )
    quick.add_argument(
        "--episodes",
        type=EPISODES,
        default=None,
        help=f"GenRL episodes (default: the task's own, at most {QUICKSTART_MAX_EPISODES}: {own})",
    )
    _seed_option(quick)
    quick.add_argument("--no-video", action="store_true", help="skip rendering the policy")
    _device_option(quick)
    _progress_option(quick)
    quick.set_defaults(func=commands.quickstart_command)


def add_study(sub: argparse._SubParsersAction) -> None:
    study = sub.add_parser("study", help="the paper's experiments at a scale, with tables, plots and report.md")
    _task_option(study, required=False, default="all", extra=("all",), arm_only=True)
    study.add_argument("--scale", choices=tuple(SCALES), default="small", help="size of every stage (default: small)")
    study.add_argument("--out", required=True, type=OUT_DIR, help="study folder (a rerun resumes it)")
    study.add_argument("--executor", choices=("local", "ray"), default="local", help="worker processes or Ray tasks")
    study.add_argument("--address", default=None, help="Ray cluster address (ray executor)")
    study.add_argument(
        "--ray-timeout",
        type=option(check_positive_float, float),
        default=30.0,
        help="seconds to connect to --address (default 30)",
    )
    study.add_argument("--workers", type=COUNT, default=None, help="local worker processes (default: the cores)")
    study.add_argument("--models", nargs="+", choices=MODELS, default=None, help="a subset of VAE1..GAN9 (default all)")
    _device_option(study)
    study.set_defaults(func=commands.study_command)


def _horizon_or_expert(value: str) -> int | str:
    """``genrl demos --horizon``: a positive count of steps, or ``expert`` (found from the expert's success)."""
    return value if value == "expert" else COUNT(value)
