"""The ``genrl`` commands: each takes the parsed arguments (:mod:`sb3_genrl.cli.parsers`), calls one library
function that a user could call too, and prints what it made."""

from __future__ import annotations

import argparse
import csv
import functools
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sb3_genrl.baselines import OFF_POLICY_BASELINES
from sb3_genrl.baselines.compare import compare_runs
from sb3_genrl.baselines.train import CHECKPOINT_EVERY as BASELINE_CHECKPOINT_EVERY
from sb3_genrl.baselines.train import train_baseline
from sb3_genrl.checks import check_output_dir
from sb3_genrl.data import dataset_info, load_trajectories
from sb3_genrl.envs import arm_tasks
from sb3_genrl.envs.demonstrations import (
    describe_horizon,
    expert_horizon,
    own_maker,
    refuse_existing_output,
    replay_demonstrations,
    task_demonstrations,
)
from sb3_genrl.envs.external import make_task_env, resolve_task
from sb3_genrl.generative import train_generator
from sb3_genrl.genrl import check_genrl_settings
from sb3_genrl.genrl.demonstrations import callback_entries
from sb3_genrl.hyperparams import PRIOR_ROLLOUT_SEED, lay_over
from sb3_genrl.metrics import evaluate_generators
from sb3_genrl.metrics.prior_rollout import DEFAULT_CONTEXTS, DEFAULT_DRAWS
from sb3_genrl.metrics.scorecard import scorecard_markdown
from sb3_genrl.run import train_policy
from sb3_genrl.showcase import play_scripted
from sb3_genrl.study import MODELS, run_study
from sb3_genrl.study.quickstart import outside_task_settings, quickstart, task_settings
from sb3_genrl.video import REAL_TIME_FPS, record_video


def play_command(args: argparse.Namespace) -> int:
    print(f"wrote {play_scripted(args.out, tasks=tuple(args.task) if args.task else None, seed=args.seed)}")
    return 0


DEMONSTRATIONS = 40000  # genrl demos' default count, the paper's
EXPERT_HORIZON = "expert"  # genrl demos --horizon expert: the shortest at which the expert's success settles


def demos_command(args: argparse.Namespace) -> int:
    """``genrl demos``: a dataset replayed open loop (``--from``), else the task's demonstrations through the one entry
    of every task (:func:`sb3_genrl.envs.demonstrations.task_demonstrations`): its own maker, or its expert's."""
    if args.source is not None:
        return _replayed_demos(args)
    args.episodes = DEMONSTRATIONS if args.episodes is None else args.episodes
    args.seed = 0 if args.seed is None else args.seed
    task = resolve_task(args.task)
    recorded = args.expert is not None or own_maker(task) is None
    if recorded and args.expert is None and task.make_expert is None:
        raise ValueError(f"task {args.task!r} has no expert of the package's: give its expert as --expert MODULE:FUNCTION")
    given = [f"--{name.replace('_', '-')}" for name in ("noise", "horizon", "success_key") if getattr(args, name) is not None]
    if given and not recorded:
        verb = "applies" if len(given) == 1 else "apply"
        raise ValueError(f"{', '.join(given)} {verb} to demonstrations from an expert (--expert), not to {args.task}'s own")
    began = time.perf_counter()
    if args.horizon == EXPERT_HORIZON:
        check_output_dir(args.out, "out")
        refuse_existing_output(Path(args.out))
        found = expert_horizon(args.task, args.expert, seed=args.seed, success_key=args.success_key or "is_success")
        args.horizon = found["horizon"]
        print(f"horizon: {found['horizon']} steps, {describe_horizon(found)}")
    path = task_demonstrations(
        args.task,
        args.episodes,
        args.out,
        expert=args.expert,
        seed=args.seed,
        noise=args.noise,
        horizon=args.horizon,
        success_key=args.success_key,
        n_threads=args.threads,
        progress_bar=not args.no_progress_bar,
    )
    print(f"{dataset_line(path)} in {time.perf_counter() - began:.1f} s -> {path}")
    coverage = path / "coverage.json"
    if coverage.is_file():
        report = json.loads(coverage.read_text())
        print(
            f"coverage: {100 * report['coverage']:.1f}% of {report['cells']} goal-region cells of {report['cell_size']} m"
            f" ({100 * report['in_region']:.1f}% of reached points in the region) -> {report['png']}"
        )
    return 0


def dataset_line(path: Path) -> str:
    """What a dataset of ``genrl demos`` holds, in words: a recorded one's kept share and why the others were dropped,
    or a task's own maker's episodes and draws."""
    info = dataset_info(path)
    if "failed_open_loop" in info:
        return (
            f"{info['episodes']} demonstrations of {info['task']} ({info['horizon']} steps) kept of {info['tried']} tried "
            f"({100 * info['kept_share']:.1f}%: {info['failed_closed_loop']} failed closed loop, {info['failed_open_loop']} "
            "failed when replayed open loop)"
        )
    return f"{info['episodes']} {info['task']} demonstrations ({info['drawn']} drawn)"


def _replayed_demos(args: argparse.Namespace) -> int:
    """``genrl demos --from`` a dataset of actions (:func:`sb3_genrl.envs.demonstrations.replay_demonstrations`)."""
    if args.horizon == EXPERT_HORIZON:
        raise ValueError(f"--horizon {EXPERT_HORIZON} reads the horizon from an expert; --from replays a dataset's actions")
    given = [option for option in ("expert", "noise", "threads") if getattr(args, option) is not None]
    if given:
        raise ValueError(
            f"{', '.join(f'--{option}' for option in given)} cannot be used with --from, which replays a dataset's "
            "actions: they apply to demonstrations from an expert"
        )
    if args.seed is not None:
        raise ValueError("--seed cannot be used with --from: each replayed episode starts from the dataset's reset seed")
    began = time.perf_counter()
    path = replay_demonstrations(
        args.task,
        args.source,
        args.out,
        horizon=args.horizon,
        success_key=args.success_key or "is_success",
        progress_bar=not args.no_progress_bar,
        episodes=args.episodes,
    )
    info = dataset_info(path)
    print(
        f"{info['episodes']} demonstrations of {info['task']} ({info['horizon']} steps) kept of {info['tried']} replayed "
        f"from {info['source']} ({100 * info['kept_share']:.1f}%: {info['failed_open_loop']} failed when replayed open "
        f"loop) in {time.perf_counter() - began:.1f} s -> {path}"
    )
    return 0


def train_generator_command(args: argparse.Namespace) -> int:
    out, data = Path(args.out).resolve(), Path(args.data).resolve()
    if out.exists() and not args.overwrite and data != out and data not in out.parents:  # (the data: refused below)
        raise FileExistsError(f"--out {str(args.out)!r} already exists; pass --overwrite to replace it")
    generator = train_generator(
        args.data,
        model=args.model,
        preset=args.preset,
        latent_dim=args.latent_dim,
        beta=args.beta,
        info_weight=args.info_weight,
        std_floor=args.std_floor,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        seed=args.seed,
        eval_every=args.eval_every,
        selection=args.selection,
        min_steps=args.min_steps,
        even_batches=args.even_batches,
        out=args.out,
        tensorboard_log=args.tensorboard_log and str(args.tensorboard_log),
        progress_bar=not args.no_progress_bar,
        device=args.device,
    )
    best = next((entry for entry in generator.history if entry["epoch"] == generator.best_epoch), {})
    print(
        f"{type(generator).__name__} (T={generator.horizon}, M={generator.action_dim}, N_alpha={generator.latent_dim})"
        f" best epoch {generator.best_epoch} of {generator.history[-1]['epoch'] if generator.history else 0},"
        f" {generator.selection} selection MSE {best.get('selection_mse', float('nan')):.6g}"
        f" -> {args.out}"
    )
    return 0


def _refuse_replacing(args: argparse.Namespace, made: Path, what: str) -> None:
    """Refuse ``made`` (the mark of an earlier output at ``--out``) unless ``--overwrite``: a command that would
    replace another run's results asks first."""
    if made.exists() and not args.overwrite:
        raise FileExistsError(f"--out {str(args.out)!r} already holds {what} ({made.name}); pass --overwrite to replace it")


def evaluate_command(args: argparse.Namespace) -> int:
    _refuse_replacing(args, Path(args.out) / "results.json", "an evaluation")
    rollout = {"contexts": DEFAULT_CONTEXTS, "draws": DEFAULT_DRAWS, "prior_seed": PRIOR_ROLLOUT_SEED}
    given = [f"--{name.replace('_', '-')}" for name in rollout if getattr(args, name) is not None]
    if args.task is None and given:  # else they would set nothing
        raise ValueError(f"{', '.join(given)} set the prior rollout, which runs only with --task")
    for name, default in rollout.items():
        setattr(args, name, default if getattr(args, name) is None else getattr(args, name))
    task, spec = args.task, None if args.task is None else resolve_task(args.task).spec
    if task is not None and spec is None:
        task = _outside_env_maker(task, args.data)
        print(
            f"{args.task} is a task from outside the package: the prior rollout plays its {args.contexts} x {args.draws} "
            "episodes through its step path, as long as the data's trajectories"
        )
    elif spec is not None and not hasattr(spec.env_class, "play_trajectories"):
        print(
            f"{task} has no fast path (play_trajectories): the prior rollout plays its "
            f"{args.contexts} x {args.draws} episodes through the step path"
        )
    evaluations = evaluate_generators(
        args.models,
        args.data,
        n=args.n,
        k=args.k,
        dwpr_n=args.dwpr_n,
        interventions=args.interventions,
        seed=args.seed,
        out_dir=args.out,
        device=args.device,
        task=task,
        contexts=args.contexts,
        draws=args.draws,
        prior_seed=args.prior_seed,
        rank_by=args.rank_by,
        min_precision=args.min_precision,
    )
    print(scorecard_markdown([evaluation.row() for evaluation in evaluations], args.rank_by, args.min_precision))
    print(f"wrote {args.out}/scorecard.md, results.md, results.csv, results.json, precision_recall.png, disentanglement.png")
    return 0


def _outside_env_maker(task: str, data: str | Path) -> Callable[[], Any]:
    """Makes the env of a task from outside the package with episodes as long as the trajectories of ``data`` (a
    dataset's recorded horizon, or the second axis of an array), for the prior rollout."""
    path = Path(data)
    horizon = dataset_info(path)["horizon"] if path.is_dir() else load_trajectories(path).shape[1]
    return functools.partial(make_task_env, task, horizon=int(horizon))


def train_policy_command(args: argparse.Namespace) -> int:
    outside = resolve_task(args.task).spec is None
    if outside:  # metaworld/<name>, module:Id, a name given by register(): the Gymnasium id
        args.task = resolve_task(args.task).env_id
    result = train_policy(
        args.task,
        str(args.generator),
        episodes=args.episodes,
        seed=args.seed,
        out_dir=args.out,
        n_envs=args.n_envs,
        device=args.device,
        progress_bar=not args.no_progress_bar,
        checkpoint_every=args.checkpoint_every or None,
        overwrite=args.overwrite,
        demonstrations=args.data and str(args.data),
        horizon=args.horizon,
        success_key=args.success_key,
        **policy_arguments(args),
    )
    print(
        f"GenRL on {args.task}: {result['episodes']} episodes, {result['iterations']} iterations, mean reward "
        f"final {result['final_mean_reward']:.4g}, best {result['best_mean_reward']:.4g} -> {result['model_path']}"
    )
    line = _success_line(result["log_dir"], outside)
    if line is not None:
        print(line)
    return 0


def _success_line(log_dir: str, outside: bool) -> str | None:
    """What a run logged of the task's success: the last ``rollout/success_rate`` in SB3's log (its share over the last
    episodes played, up to 100), or, for a task from outside the package, that the env reported none (None for the
    package's tasks that report none: their score is a distance)."""
    with open(Path(log_dir) / "progress.csv", newline="", encoding="utf-8") as file:
        rates = [row.get("rollout/success_rate") for row in csv.DictReader(file)]
    rates = [float(rate) for rate in rates if rate]
    if not rates:
        return (
            None
            if not outside
            else (
                "success: the env reports no info['is_success'] at an episode's last step, so none is logged; the run "
                "learns from the rewards alone"
            )
        )
    return (
        f"success: {rates[-1]:.3f} of the last episodes played (info['is_success'] at their last step; SB3's "
        f"rollout/success_rate over up to 100 episodes, in {Path(log_dir) / 'progress.csv'})"
    )


def policy_arguments(args: argparse.Namespace) -> dict:
    """``genrl train-policy``'s GenRL settings: the task's entry in ``hyperparams/genrl.yml`` (or GenRL's defaults,
    ``--library-defaults``) with ``--e-step``, ``--batch-episodes`` and ``--genrl-kwargs`` laid over it, checked by
    :func:`sb3_genrl.genrl.check_genrl_settings` before any work; the entry's ``callback`` (``--genrl-kwargs
    '{"callback": null}'``: none) is checked by :func:`sb3_genrl.genrl.demonstrations.callback_entries`."""
    if args.library_defaults:
        batch_episodes, genrl_kwargs = None, {}
    elif resolve_task(args.task).spec is not None:
        _, batch_episodes, genrl_kwargs = task_settings(args.task)
    else:  # a task of the user's own: its entry if it has one, else GenRL's defaults started from the demonstrations
        _, batch_episodes, genrl_kwargs = outside_task_settings(resolve_task(args.task))
    given = args.genrl_kwargs.get("e_step", args.e_step)
    if args.e_step is not None and given != args.e_step:  # neither may silently win
        raise ValueError(
            f"argument --e-step/--genrl-kwargs: --e-step {args.e_step} and --genrl-kwargs' e_step {given!r} disagree: "
            "give one of them"
        )
    genrl_kwargs = lay_over({**genrl_kwargs, **({} if args.e_step is None else {"e_step": args.e_step})}, args.genrl_kwargs)
    source = "GenRL's defaults" if args.library_defaults else f"{args.task}'s entry in hyperparams/genrl.yml"
    name = f"argument --e-step/--genrl-kwargs: {source}" + ("" if args.e_step is None else f", --e-step {args.e_step}")
    name += ", --genrl-kwargs" if args.genrl_kwargs else ""
    callback = genrl_kwargs.pop("callback", None)
    genrl_kwargs = check_genrl_settings(genrl_kwargs, name)
    callback_entries(callback, f"{name}: callback")
    batch_episodes = args.batch_episodes or batch_episodes
    return (
        genrl_kwargs
        | ({} if batch_episodes is None else {"batch_episodes": batch_episodes})
        | ({} if callback is None else {"callback": callback})
    )


def baseline_command(args: argparse.Namespace) -> int:
    spec = resolve_task(args.task).spec
    if spec is not None and spec.name not in arm_tasks():
        raise ValueError(
            f"genrl baseline takes a task on the package's arm ({', '.join(arm_tasks())}) or one from outside the "
            f"package (sac, sac-no-prefill), not {args.task}: the Fetch tasks' SAC + HER runs through rl-zoo3 "
            "(benchmarks/fetch_sac_her.py)"
        )
    # (a task from outside the package takes only checkpointed baselines: train_baseline names that first)
    if args.checkpoint_every is not None and spec is not None and args.algorithm not in OFF_POLICY_BASELINES:
        raise ValueError(
            f"argument --checkpoint-every: {args.algorithm} is not checkpointed (only {', '.join(OFF_POLICY_BASELINES)}); "
            "its runs restart from their first episode"
        )
    checkpoint_every = BASELINE_CHECKPOINT_EVERY if args.checkpoint_every is None else args.checkpoint_every
    summary = train_baseline(
        args.algorithm,
        args.task,
        episodes=args.episodes,
        out_dir=args.out,
        seed=args.seed,
        demos=args.demos,
        demo_episodes=args.demo_episodes,
        generator=args.generator,
        bc_kwargs={"max_epochs": args.bc_max_epochs},
        algorithm_kwargs=args.algorithm_kwargs,
        checkpoint_every=checkpoint_every or None,
        overwrite=args.overwrite,
        device=args.device,
        progress_bar=not args.no_progress_bar,
        n_envs=args.n_envs,
    )
    if "bc" in summary:
        bc, first = summary["bc"], summary["first_batch"]
        print(
            f"behaviour cloning ({bc['epochs']} epochs, best {bc['best_epoch']}): mean distance to {bc['eval_goals']} "
            f"held-out goals {bc['deterministic_distance']:.3f} m deterministic, {bc['sampled_distance']:.3f} m sampled;"
            + (
                f" PPO's first batch ({first['episodes']} episodes) {first['mean_distance']:.3f} m"
                if first["episodes"]
                else ""
            )
        )
    final = summary["final_eval"]
    if "success_rate" in final:  # a task from outside the package: its held-out seeded resets
        print(
            f"{args.algorithm} on {args.task}: {summary['episodes_played']} episodes of {summary['horizon']} steps; the "
            f"trained policy, deterministic: success on {final['resets']} held-out seeded resets {final['success_rate']:.3f}"
            f" -> {args.out}"
        )
        return 0
    print(
        f"{args.algorithm} on {args.task}: {summary['episodes_played']} episodes, final mean reward "
        f"{summary['final_mean_reward']:.4g}, best {summary['best_mean_reward']:.4g}; the trained policy, "
        f"deterministic: mean distance to {final['goals']} held-out goals {final['mean_distance']:.3f} m "
        f"({final['object_unmoved']} of them with the object not moved) -> {args.out}"
    )
    return 0


def compare_command(args: argparse.Namespace) -> int:
    _refuse_replacing(args, Path(args.out) / "comparison.csv", "a comparison")
    print(compare_runs(args.runs, args.out, task=args.task).read_text())
    return 0


def video_command(args: argparse.Namespace) -> int:
    _refuse_replacing(args, Path(args.out), "a video")
    result = record_video(
        args.task,
        args.out,
        policy=args.policy,
        generator=args.generator,
        goals=args.goals,
        seed=args.seed,
        fps=max(1, REAL_TIME_FPS // args.every),
        every=args.every,
        trust_policy=args.trust_policy,
    )
    print(f"wrote {result['video']} (rewards {', '.join(f'{r:.3f}' for r in result['rewards'])})")
    return 0


def quickstart_command(args: argparse.Namespace) -> int:
    report = quickstart(
        args.out,
        task=args.task,
        demo_episodes=args.demo_episodes,
        epochs=args.epochs,
        policy_episodes=args.episodes,
        seed=args.seed,
        video=not args.no_video,
        device=args.device,
        progress_bar=not args.no_progress_bar,
        log=print,
        expert=args.expert,
        horizon=args.horizon,
    )
    print(f"wrote {report}")
    return 0


def study_command(args: argparse.Namespace) -> int:
    report = run_study(
        args.task,
        args.scale,
        args.out,
        executor=args.executor,
        address=args.address,
        workers=args.workers,
        models=tuple(args.models) if args.models else MODELS,
        device=args.device,
        connect_timeout=args.ray_timeout,
        log=print,
    )
    print(f"wrote {report}")
    return 0
