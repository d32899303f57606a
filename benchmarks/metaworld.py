"""GenRL on Meta-World's MT10 with one configuration: success on held-out seeded resets, beside the expert and SAC.

Per task (``--tasks``, default the ten MT10 tasks), each unit is kept in ``--work`` (default ``runs/metaworld/TASK``) and
in the JSON as it finishes, so that the same command after a stop resumes where it stopped (the settings are recorded
and a rerun with others is refused before any work):

0. the horizon, as ``genrl quickstart`` finds it: the shortest at which the scripted expert's success settles on 100
   seeded resets (:func:`~sb3_genrl.envs.demonstrations.expert_horizon`, seed 0; never the held-out resets);
1. ``--demos`` demonstrations of Meta-World's scripted expert, perturbed, of that horizon
   (:func:`~sb3_genrl.envs.demonstrations.record_demonstrations`, seed 0, in Meta-World's training env, which runs on
   after a success), kept when their open-loop replay succeeds;
2. a generator of the quickstart's Meta-World preset (:data:`sb3_genrl.envs.metaworld.GENERATOR_PRESET`), seed 0,
   trained as the quickstart trains the generator of a task from outside the package
   (:data:`~sb3_genrl.study.quickstart.OUTSIDE_GENERATOR_TRAINING`: ``--epochs``, raised to at least its minibatch
   steps, in even minibatches, the checkpoint with the closest reconstructions kept);
3. the expert closed loop, unperturbed, from the held-out resets, and its actions replayed open loop from the same
   resets; then what the generator can reproduce: the first 200 demonstrations encoded to their latent codes, decoded
   and replayed open loop from their own resets (the share that succeeds);
4. per seed, the fit to the demonstrations at episode 0: GenRL's policy mean fitted to the demonstrations' latent codes
   (:class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback`'s fit, ``--fit-steps`` Adam steps), before any
   episode is played;
5. per seed, GenRL with the settings of a task without an entry in ``hyperparams/genrl.yml``
   (:data:`~sb3_genrl.study.quickstart.OUTSIDE_TASK_KWARGS`: the fit of step 4, a spread fixed at 0.37 prior standard
   deviations, the mean refitted to the pulls that solved their own reset, the KL bound scaled by the batch's failed
   share, then GenRL's defaults, ``--batch-episodes`` a batch), ``--episodes`` episodes (checkpointed; a stopped run
   resumes);
6. per ``--sac-seeds`` seed (default one: SAC's runs take hours per task on a CPU; ``--sac-from`` takes them from an
   earlier result whose SAC settings and demonstrations are this run's), ``genrl baseline sac`` of the
   task (:mod:`sb3_genrl.baselines.outside`): SB3's SAC (its defaults, learning from the first step, observations
   normalised with the demonstrations' statistics) with the demonstrations' transitions in its replay buffer, for the
   same ``--episodes`` episodes of the task's horizon, in Meta-World's training env (no end at a success, as
   Meta-World trains step-based learners); checkpointed, and a stopped run resumes.

Every policy is scored deterministically on ``--held-out`` held-out seeded resets: reset seeds from ``2**31``
(:func:`~sb3_genrl.envs.external.evaluate_success`), which the recorder never draws and which choose nothing, each
episode ending at its first success (Meta-World's evaluation protocol) or at the horizon. Each
method's CPU seconds per seed are recorded (process time; every env plays in this process). The JSON (default
``benchmarks/results/metaworld.json``, with :func:`sb3_genrl.provenance.provenance`) says ``"complete": false`` until
every unit of every task asked for is done; the Markdown table is written beside it (``.md``).

    python -m benchmarks.metaworld                                   # MT10 x seeds 0 1 2 (hours on a CPU)
    python -m benchmarks.metaworld --tasks push-v3 --seeds 0 --out push.json
    python -m benchmarks.metaworld --seeds --sac-seeds               # each task's stages 1-3 only (no seed)
    python -m benchmarks.metaworld --out new.json --sac-from benchmarks/results/metaworld.json   # GenRL anew, SAC kept

Runs with other ``--tasks`` can write one JSON at the same time (two cores, two runs): each keeps the other's rows.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch
from sb3_genrl.baselines.train import train_baseline
from sb3_genrl.envs import metaworld
from sb3_genrl.envs.demonstrations import expert_horizon, record_demonstrations
from sb3_genrl.envs.external import HELD_OUT_SEED, evaluate_success, make_task_env

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, OUT_DIR, SEED, check_int, option
from sb3_genrl.curves import MONITOR_FILE, read_monitor
from sb3_genrl.data import dataset_info
from sb3_genrl.generative import load, train_generator
from sb3_genrl.genrl.demonstrations import DemonstrationCallback, fit_mean_to_demonstrations
from sb3_genrl.markdown import markdown_table
from sb3_genrl.provenance import provenance
from sb3_genrl.run import train_policy
from sb3_genrl.run.stages import STAGE_FILE, SettingsConflictError, read_settings, refuse_conflicts, settings_conflicts
from sb3_genrl.study.quickstart import OUTSIDE_GENERATOR_TRAINING, OUTSIDE_TASK_KWARGS
from sb3_genrl.utils import FolderInUseError, atomic_write_json, atomic_write_text, folder_lock

RESULTS = Path(__file__).resolve().parent / "results"
METHODS = ("fit", "genrl", "sac")  # the per-seed units, in the order they run
RECONSTRUCTIONS = 200  # demonstrations the generator's reconstructions are replayed from
COMPLETE_SEEDS, COMPLETE_SAC_SEEDS = (0, 1, 2), (0,)  # the seeds of a complete result (the defaults)
SAC_CHECKPOINT_EVERY = 250  # SAC's episodes between checkpoints (model and replay buffer)
# The settings SAC's rows depend on (--sac-from takes the rows of a result that records the same), beside its data
SAC_SETTINGS = ("horizon", "demos", "episodes", "held_out", "held_out_seed", "success", "reward", "sac")


def known_task(name: str, _: str = "") -> str:
    metaworld.check_task_name(name)
    return name


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--tasks",
        nargs="+",
        type=option(known_task),
        default=list(metaworld.MT10_TASK_NAMES),
        help="Meta-World v3 tasks (default: MT10)",
    )
    parser.add_argument("--seeds", nargs="*", type=SEED, default=[0, 1, 2], help="seeds of the fit and GenRL (default 0 1 2)")
    parser.add_argument(
        "--sac-seeds",
        nargs="*",
        type=SEED,
        default=[0],
        help="seeds of SAC (default 0: its runs take hours per task on a CPU; the table gives each method's seed count)",
    )
    parser.add_argument(
        "--demos", type=COUNT, default=1000, help="demonstrations per task (default 1000, the quickstart's up to 150 steps)"
    )
    parser.add_argument("--epochs", type=COUNT, default=300, help="generator epochs (default 300)")
    parser.add_argument("--episodes", type=COUNT, default=3000, help="episodes of GenRL and of SAC per seed (default 3000)")
    parser.add_argument(
        "--batch-episodes",
        type=option(check_int, int, minimum=2),
        default=64,
        help="GenRL's episodes per iteration (default 64)",
    )
    parser.add_argument("--held-out", type=COUNT, default=200, help="held-out seeded resets (default 200)")
    parser.add_argument("--fit-steps", type=COUNT, default=4000, help="Adam steps of the fit at episode 0 (default 4000)")
    parser.add_argument("--work", type=OUT_DIR, default="runs/metaworld", help="work folder (default runs/metaworld)")
    parser.add_argument(
        "--out", type=JSON_OUT, default=str(RESULTS / "metaworld.json"), help="result JSON (the table beside it, .md)"
    )
    parser.add_argument(
        "--sac-from",
        type=EXISTING,
        default=None,
        help="take each task's SAC rows from this result JSON of the benchmark instead of running SAC (its SAC settings "
        "must be this run's, and each task's demonstrations, checked as they are recorded)",
    )
    args = parser.parse_args(argv)
    if not metaworld.installed():
        parser.error(metaworld.INSTALL_HINT)
    if args.sac_from is not None:
        try:
            args.sac_rows = sac_rows(Path(args.sac_from), settings(args))
        except ValueError as error:
            parser.error(f"argument --sac-from: {error}")
    try:  # a result or a work folder of other settings: refused before any work
        refuse_conflicts(args.out if Path(args.out).is_file() else args.work, _conflicts(args))
    except SettingsConflictError as error:
        parser.error(str(error))
    return args


def _conflicts(args: argparse.Namespace) -> list[str]:
    """Where the result JSON or a task's work folder (``stage.json``) records other settings than this run's."""
    wanted = settings(args)
    out = Path(args.out)
    recorded = read_settings(out) if out.is_file() else None
    lines = settings_conflicts(
        out, None if recorded is None else recorded.get("settings"), wanted, output_exists=bool(recorded)
    )
    for task in args.tasks:
        work = Path(args.work) / task
        lines += settings_conflicts(work, read_settings(work / STAGE_FILE), wanted, output_exists=work.is_dir())
    return lines


def settings(args: argparse.Namespace) -> dict[str, Any]:
    """What every result of the run depends on (a rerun with other settings is refused)."""
    return {
        "horizon": "the shortest at which the expert's success settles (expert_horizon, seed 0), per task",
        "demos": args.demos,
        "epochs": args.epochs,
        "preset": metaworld.GENERATOR_PRESET,
        "generator_training": dict(OUTSIDE_GENERATOR_TRAINING),
        "episodes": args.episodes,
        "batch_episodes": args.batch_episodes,
        "held_out": args.held_out,
        "held_out_seed": HELD_OUT_SEED,
        "fit_steps": args.fit_steps,
        "genrl": outside_settings(args.fit_steps),
        "success": "Meta-World's evaluation protocol: an episode ends at its first success",
        "reward": "Meta-World's v2 reward, 10 at the step that ends an episode at its success",
        "sac": "SB3's defaults, learning_starts 0, the demonstrations in the buffer, trained without an end at success",
    }


def sac_rows(path: Path, wanted: dict[str, Any]) -> dict[str, Any]:
    """The tasks of the benchmark's result ``path`` that have SAC rows: per task, its SAC rows and the demonstrations
    and horizon they were made from, with where they were made (the file and its commit, or the result the file took
    them from); ``ValueError`` when its SAC settings are not ``wanted``'s."""
    recorded = read_settings(path)
    if not recorded or "settings" not in recorded or "tasks" not in recorded:
        raise ValueError(f"{path} is not a result of this benchmark")
    differ = [key for key in SAC_SETTINGS if recorded["settings"].get(key) != wanted[key]]
    if differ:
        raise ValueError(
            f"{path} records SAC's runs with other settings: "
            + "; ".join(f"{key} {recorded['settings'].get(key)!r} (recorded) vs {wanted[key]!r} (this run)" for key in differ)
        )
    return {
        task: {
            "sac": row["sac"],
            "demonstrations": row["demonstrations"],
            "horizon": row["horizon"]["horizon"],
            "from": row.get("sac_from") or {"file": str(path), "git_commit": recorded.get("git_commit")},
        }
        for task, row in recorded["tasks"].items()
        if row.get("sac")
    }


def closed_loop(env: Any, policy: Any, reset_seed: int, horizon: int) -> tuple[bool, np.ndarray]:
    """One episode of ``policy`` (observation -> action) from ``reset(seed=reset_seed)``: its success at the last step
    and the actions it played."""
    observation, _ = env.reset(seed=reset_seed)
    actions, info = [], {}
    for _ in range(horizon):
        action = np.clip(np.asarray(policy(observation), dtype=np.float32), -1.0, 1.0)
        observation, _, terminated, truncated, info = env.step(action)
        actions.append(action)
        if terminated or truncated:
            break
    return bool(info.get("is_success", False)), np.array(actions)


def open_loop(env: Any, actions: np.ndarray, reset_seed: int) -> bool:
    """``actions`` replayed from ``reset(seed=reset_seed)``: the success at the last step."""
    env.reset(seed=reset_seed)
    info = {}
    for action in actions:
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    return bool(info.get("is_success", False))


def expert_row(task: str, held_out: int, horizon: int) -> dict[str, Any]:
    """The expert closed loop from the held-out resets, and its actions replayed open loop from the same resets."""
    env, expert = make_task_env(f"metaworld/{task}", horizon=horizon), metaworld.metaworld_expert(task)
    began = time.process_time()
    closed, opened = [], []
    for i in range(held_out):
        success, actions = closed_loop(env, expert, HELD_OUT_SEED + i, horizon)
        closed.append(success)
        opened.append(open_loop(env, actions, HELD_OUT_SEED + i))
    env.close()
    return {
        "closed_loop": float(np.mean(closed)),
        "open_loop": float(np.mean(opened)),
        "cpu_seconds": round(time.process_time() - began, 1),
    }


def reconstruction_row(task: str, generator_path: Path, dataset: Path, horizon: int, count: int) -> dict[str, Any]:
    """What the generator can reproduce: the first ``count`` demonstrations encoded to their latent codes (the
    posterior means, clipped to GenRL's latent box, as the fit at episode 0 takes them), decoded and replayed open
    loop from each one's own seeded reset; the share that succeeds."""
    began = time.process_time()
    generator = load(generator_path, device="cpu")
    env = LatentActionWrapper(make_task_env(f"metaworld/{task}", horizon=horizon), generator)
    demonstrations = DemonstrationCallback(dataset, fit_steps=1, keep=False)
    _, latents = demonstrations.pulls(generator, env.observation_space, env.latent_clip)
    seeds = dataset_info(dataset)["reset_seeds"]
    successes = []
    for latent, reset_seed in zip(latents[:count].numpy(), seeds[:count], strict=False):
        env.reset(seed=int(reset_seed))
        _, _, _, _, info = env.step(latent)
        successes.append(bool(info.get("is_success", False)))
    env.close()
    return {
        "success": float(np.mean(successes)),
        "demonstrations": len(successes),
        "cpu_seconds": round(time.process_time() - began, 1),
    }


def fit_row(
    task: str, generator_path: Path, dataset: Path, seed: int, horizon: int, args: argparse.Namespace
) -> dict[str, Any]:
    """GenRL's policy with its mean fitted to the demonstrations' latent codes, before any episode, on held-out resets."""
    began = time.process_time()
    generator = load(generator_path, device="cpu")
    model = GenRL(LatentActionWrapper(make_task_env(f"metaworld/{task}", horizon=horizon), generator), seed=seed, device="cpu")
    contexts, latents = DemonstrationCallback(dataset, fit_steps=args.fit_steps, keep=False).pulls(
        generator, model.observation_space, model.latent_clip
    )
    fit = fit_mean_to_demonstrations(model.policy, contexts, latents, steps=args.fit_steps)
    fitted = time.process_time() - began
    score = evaluate_success(model, f"metaworld/{task}", resets=args.held_out, horizon=horizon)
    return {"success": score["success_rate"], "cpu_seconds": round(fitted, 1), "last_loss": fit["last_loss"]}


def genrl_row(
    task: str, generator_path: Path, dataset: Path, work: Path, seed: int, horizon: int, args: argparse.Namespace
) -> dict[str, Any]:
    """GenRL with the settings of a task without an entry (:data:`~sb3_genrl.study.quickstart.OUTSIDE_TASK_KWARGS`:
    started from the demonstrations, a fixed spread, refits to the solving pulls, then its defaults) for ``--episodes``
    episodes (resumed from its checkpoint), on held-out resets."""
    began = time.process_time()
    run = train_policy(
        metaworld.metaworld_env_id(task),
        str(generator_path),
        episodes=args.episodes,
        batch_episodes=args.batch_episodes,
        n_envs=1,  # in this process, so that its CPU time is this process's
        seed=seed,
        out_dir=work / f"genrl_seed{seed}",
        horizon=horizon,
        device="cpu",
        demonstrations=dataset,
        **outside_settings(args.fit_steps),
    )
    trained = time.process_time() - began
    model = GenRL.load(run["model_path"], device="cpu")
    score = evaluate_success(model, f"metaworld/{task}", resets=args.held_out, horizon=horizon)
    return {
        "success": score["success_rate"],
        "cpu_seconds": round(trained, 1),
        "episodes": run["episodes"],
        **({"resumed_at_episodes": run["resumed_at_episodes"]} if "resumed_at_episodes" in run else {}),
    }


def outside_settings(fit_steps: int) -> dict[str, Any]:
    """:data:`~sb3_genrl.study.quickstart.OUTSIDE_TASK_KWARGS` with the fit's ``--fit-steps``."""
    settings = copy.deepcopy(OUTSIDE_TASK_KWARGS)
    for entry in settings["callback"]:
        for arguments in entry.values():
            arguments["fit_steps"] = fit_steps
    return settings


def sac_row(task: str, dataset: Path, work: Path, seed: int, horizon: int, args: argparse.Namespace) -> dict[str, Any]:
    """SAC with the demonstrations' transitions in its replay buffer, ``--episodes`` episodes, on held-out resets:
    ``genrl baseline sac --task metaworld/TASK --demos DATASET`` (:func:`~sb3_genrl.baselines.train_baseline` of a task
    from outside the package, :mod:`sb3_genrl.baselines.outside`) in ``work/sac_seedN``.

    The run checkpoints its model and replay buffer every :data:`SAC_CHECKPOINT_EVERY` episodes and a rerun resumes
    from it, since a run takes hours of CPU; a resumed run is not bitwise the uninterrupted one (SB3's random streams
    restart), and the row names the episodes it resumed at. The row's CPU seconds are the Monitor's, those of the
    episodes played and the updates between them (before a resume included).
    """
    folder = work / f"sac_seed{seed}"
    summary = train_baseline(
        "sac",
        f"metaworld/{task}",
        episodes=args.episodes,
        out_dir=folder,
        seed=seed,
        demos=dataset,
        checkpoint_every=SAC_CHECKPOINT_EVERY,
        device="cpu",
        eval_resets=args.held_out,
    )
    if summary["horizon"] != horizon:
        raise RuntimeError(f"{dataset}: recorded with {summary['horizon']} steps, the task's horizon is {horizon}")
    cpu_seconds = float(read_monitor(folder / MONITOR_FILE)["cpu_seconds"][-1])
    row = {"success": summary["final_eval"]["success_rate"], "cpu_seconds": round(cpu_seconds, 1), "episodes": args.episodes}
    resumed = summary.get("resumed_at_episodes")
    return row | ({"resumed_at_episodes": resumed} if resumed else {})


def run_task(task: str, args: argparse.Namespace, result: dict[str, Any], save: Any) -> None:
    """Every unit of ``task`` not in ``result`` yet, each saved as it finishes."""
    work = Path(args.work) / task
    work.mkdir(parents=True, exist_ok=True)
    atomic_write_json(work / STAGE_FILE, settings(args))  # the settings its files are made with (checked on a rerun)
    row = result["tasks"].setdefault(task, {})
    dataset, generator_path = work / "demonstrations", work / "vae.pt"
    if "horizon" not in row:  # the quickstart's: the expert's settled horizon from seed 0
        began = time.process_time()
        found = expert_horizon(f"metaworld/{task}", seed=0, n_threads=1)  # in this process: its CPU time is counted
        row["horizon"] = {key: value for key, value in found.items() if key != "success_by_step"} | {
            "cpu_seconds": round(time.process_time() - began, 1)
        }
        save()
    horizon = int(row["horizon"]["horizon"])
    began = time.process_time()
    if not (dataset.is_dir() and any(dataset.iterdir())):  # a dataset is written whole or not at all
        record_demonstrations(  # in this process, so that its CPU time is this process's
            f"metaworld/{task}", None, args.demos, dataset, seed=0, horizon=horizon, n_threads=1
        )
    info = dataset_info(dataset)
    counts = {key: info[key] for key in ("episodes", "tried", "kept_share", "failed_closed_loop", "failed_open_loop")}
    if "demonstrations" not in row:
        row["demonstrations"] = counts | {"cpu_seconds": round(time.process_time() - began, 1)}
        save()
    elif counts != {key: row["demonstrations"][key] for key in counts}:
        # a work folder made anew (the JSON kept, the datasets not): the recording is seeded, so it must give the
        # dataset the JSON's other units were made from
        raise RuntimeError(
            f"{dataset}: {counts} differs from the demonstrations {args.out} records for {task} "
            f"({row['demonstrations']}); remove the folder or write another --out"
        )
    if "generator" not in row:
        began = time.process_time()
        if not generator_path.is_file():  # written atomically once training ends
            train_generator(
                dataset,
                preset=metaworld.GENERATOR_PRESET,
                epochs=args.epochs,
                seed=0,
                out=generator_path,
                **OUTSIDE_GENERATOR_TRAINING,
            )
        row["generator"] = {
            "best_epoch": load(generator_path).best_epoch,
            "cpu_seconds": round(time.process_time() - began, 1),
        }
        save()
    if "expert" not in row:
        row["expert"] = expert_row(task, args.held_out, horizon)
        save()
    kept = getattr(args, "sac_rows", {}).get(task)
    if kept is not None and "sac_from" not in row:  # SAC's rows of an earlier result, made from the same data
        made = {key: kept["demonstrations"][key] for key in counts}
        if kept["horizon"] != horizon or made != counts:
            raise RuntimeError(
                f"{args.sac_from}: {task}'s SAC rows were made from the demonstrations {made} of horizon "
                f"{kept['horizon']}, this run's are {counts} of horizon {horizon}"
            )
        row["sac"] = copy.deepcopy(kept["sac"]) | row.get("sac", {})
        row["sac_from"] = kept["from"]
        save()
    if "reconstruction" not in row:
        row["reconstruction"] = reconstruction_row(task, generator_path, dataset, horizon, RECONSTRUCTIONS)
        save()
    for seed in sorted({*args.seeds, *args.sac_seeds}):
        for method in METHODS:
            done = row.setdefault(method, {})
            if str(seed) in done or seed not in (args.sac_seeds if method == "sac" else args.seeds):
                continue
            if method == "fit":
                done[str(seed)] = fit_row(task, generator_path, dataset, seed, horizon, args)
            elif method == "genrl":
                done[str(seed)] = genrl_row(task, generator_path, dataset, work, seed, horizon, args)
            else:
                done[str(seed)] = sac_row(task, dataset, work, seed, horizon, args)
            save()


def table(result: dict[str, Any]) -> str:
    """The Markdown table: per task, each method's held-out success (mean +- std over seeds, "not run" where it has no
    seed yet) and CPU seconds per seed; then the mean over the tasks of each column every task has."""

    def over_seeds(units: dict[str, dict[str, Any]], key: str) -> tuple[float, float] | None:
        values = [unit[key] for unit in units.values()]
        return (float(np.mean(values)), float(np.std(values))) if values else None

    rows, means = [], {method: [] for method in METHODS}
    for task, row in result["tasks"].items():
        expert = row.get("expert", {})
        cells: list[Any] = [
            task,
            row.get("horizon", {}).get("horizon", "-"),
            expert.get("closed_loop", "-"),
            expert.get("open_loop", "-"),
            row.get("reconstruction", {}).get("success", "-"),
        ]
        for method in METHODS:
            success = over_seeds(row.get(method, {}), "success")
            means[method].append(None if success is None else success[0])
            seeds = len(row.get(method, {}))
            cells.append("not run" if success is None else f"{success[0]:.3f} +- {success[1]:.3f} ({seeds})")
        for method in METHODS:
            cpu = over_seeds(row.get(method, {}), "cpu_seconds")
            cells.append("-" if cpu is None else f"{cpu[0]:.0f}")
        rows.append(cells)
    if len(rows) > 1:
        tasks = len(rows)
        mean_cells = ["-" if None in values else f"{np.mean(values):.3f}" for values in (means[method] for method in METHODS)]
        rows.append([f"mean over the {tasks} tasks", "", "", "", "", *mean_cells, "", "", ""])
    header = [
        "task",
        "horizon",
        "expert closed loop",
        "expert open loop",
        "generator's reconstructions",
        "fit at episode 0 (seeds)",
        "GenRL (seeds)",
        "SAC + demonstrations (seeds)",
        "fit CPU s",
        "GenRL CPU s",
        "SAC CPU s",
    ]
    text = markdown_table(header, rows, digits=3, align="lrrrrrrrrrr")
    sources = sorted(
        {(row["sac_from"]["file"], row["sac_from"]["git_commit"]) for row in result["tasks"].values() if "sac_from" in row}
    )
    for path, commit in sources:  # SAC's rows taken from an earlier result (--sac-from)
        text += f"\n\nSAC's rows: from {path} (commit {commit}), made from the same demonstrations and SAC settings."
    return text


def main(argv: list[str] | None = None) -> int:
    args = arguments(argv)
    torch.set_num_threads(1)
    out = Path(args.out)
    result = read_settings(out) if out.is_file() else None
    result = result or {"benchmark": "metaworld", "settings": settings(args), "tasks": {}}

    def save() -> None:
        with _locked(out):  # another process running other --tasks into the same JSON: its rows are kept
            on_disk = read_settings(out) if out.is_file() else None
            for task, row in (on_disk or {}).get("tasks", {}).items():
                if task not in args.tasks:
                    result["tasks"][task] = row
            result["tasks"] = dict(sorted(result["tasks"].items(), key=lambda item: _task_order(item[0])))
            _write(out, result)

    for task in args.tasks:
        run_task(task, args, result, save)
        print(f"{task}: done", flush=True)
    save()
    print(table(result))
    return 0


def _task_order(task: str) -> tuple[int, str]:
    """MT10's tasks in MT10's order, then any other by name."""
    names = metaworld.MT10_TASK_NAMES
    return (names.index(task), task) if task in names else (len(names), task)


@contextlib.contextmanager
def _locked(out: Path) -> Iterator[None]:
    """Hold the result JSON's lock (a sibling file), waiting while another run of the benchmark writes it."""
    while True:
        held = contextlib.ExitStack()
        try:
            held.enter_context(folder_lock(out.parent, out.with_name(out.name + ".lock")))
            break
        except FolderInUseError:
            time.sleep(0.2)
    with held:
        yield


def _write(out: Path, result: dict[str, Any]) -> None:
    """The result JSON (with its provenance and whether every unit of MT10 is done) and its table."""
    result.pop("provenance", None)  # (where results made before kept it)
    result |= provenance()
    result["complete"] = all(
        all(
            key in result["tasks"].get(task, {})
            for key in ("horizon", "demonstrations", "generator", "expert", "reconstruction")
        )
        and all(
            str(seed) in result["tasks"][task].get(method, {})
            for method in METHODS
            for seed in (COMPLETE_SAC_SEEDS if method == "sac" else COMPLETE_SEEDS)
        )
        for task in metaworld.MT10_TASK_NAMES
    )
    atomic_write_json(out, result)
    atomic_write_text(out.with_suffix(".md"), table(result) + "\n")


if __name__ == "__main__":
    sys.exit(main())
