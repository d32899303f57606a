"""GenRL on Gymnasium-Robotics' Fetch tasks: the deterministic policy's success rate on held-out initial states.

Stages, each kept in ``--work`` (default ``runs/fetch/TASK``) and in the JSON as it finishes, so that the same command
after a stop resumes where it stopped (a run's settings are recorded and checked on resume):

1. ``--demos`` demonstrations (seed 0; or ``--data``) and ``--generator-seeds`` generators of the task's recipe
   (``TaskSpec.generator_preset``, ``--epochs``; seeds 0, 1, ...), of which the one is kept whose fit of GenRL's mean
   to the demonstrations (the entry's ``DemonstrationCallback`` fit, before any episode) solves the most of
   ``--selection-states`` tuning initial states (reset seeds from
   :data:`~sb3_genrl.hyperparams.TUNING_GOAL_SEED`): that fit varies by about 0.1 of success with the generator's
   training seed, and it is where GenRL starts;
2. the generator's reconstructions of ``--recon-demos`` new demonstrations (seed 1, not trained on), replayed from
   their own initial states: the share that reach their own aims;
3. the generator's own limit: ``--limit-states`` held-out initial states x ``--prior-draws`` draws from its prior
   (100 x 100 = 10^4 by default), the share of states that some draw solves (and the best of 1 and 10 draws),
   measured after the first seed of stage 4;
4. GenRL with the task's entry in ``hyperparams/genrl.yml``, one run per seed, learning from the demonstrations as the
   entry's callback says (:class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback`: the policy's mean first
   fitted to their latent codes, and the demonstrations kept among the hindsight pulls; ``--no-demonstrations``: the
   entry without it, for the comparison): at episode 0 (after the fit), every ``--eval-every`` episodes (at the
   start of an iteration, after its update) and at the end, the deterministic policy plays ``--eval-states``
   held-out initial states (reset seeds from :data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`, never used in tuning);
   the curve is against episodes and environment steps (50 per episode). Each seed checkpoints at every evaluation
   (:mod:`sb3_genrl.run.checkpoint`) and resumes from it.
5. the generator's limit near the first seed's final policy: on the same ``--limit-states`` held-out states, the share
   its deterministic action solves and the share that one of ``--near-draws`` draws from the policy's own spread
   solves (``sb3_genrl.envs.demonstrations.fetch.policy_neighbourhood_success``): a gap says the search, not the
   generator, limits.

The JSON (default ``benchmarks/results/fetch_TASK.json``) says ``"complete": false`` and how far each seed got until
every stage is done and seeds 0, 1 and 2 have finished (a run of other ``--seeds`` stays partial).

    python -m benchmarks.fetch --task fetch-push                   # 3 seeds x 3000 episodes, 500 held-out states
    python -m benchmarks.fetch --task fetch-reach --seeds 0 --eval-states 100
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import time

import torch
from sb3_genrl.envs import TASKS, get_task
from sb3_genrl.envs.demonstrations.fetch import (
    policy_neighbourhood_success,
    prior_best_success,
    reconstruction_success,
)

from benchmarks.fetch_results import (
    BENCHMARK_SEEDS,
    all_seeds_finished,
    dataset_recipe,
    recorded_demonstration_recipe,
    seed_row,
    write_result,
)
from benchmarks.fetch_seed import fitted_mean_success, recorded_genrl_settings, train_seed
from benchmarks.genrl import make_benchmark_demonstrations
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, SEED
from sb3_genrl.data import dataset_info
from sb3_genrl.generative import load, train_generator
from sb3_genrl.generative.presets import resolve_generator_spec
from sb3_genrl.genrl import GenRL
from sb3_genrl.hyperparams import EVAL_GOAL_SEED, TUNING_GOAL_SEED
from sb3_genrl.provenance import provenance
from sb3_genrl.run.stages import settings_conflicts
from sb3_genrl.study.quickstart import quickstart_preset, task_settings

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FETCH_TASKS = sorted(name for name in TASKS if name.startswith("fetch-"))
RECONSTRUCTION_SEED = 1  # the demonstrations whose reconstructions are replayed: not the training set's (seed 0)


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True, choices=FETCH_TASKS, help="a Fetch task")
    parser.add_argument("--data", type=EXISTING, default=None, help="the task's dataset (default: make --demos)")
    parser.add_argument("--generator", type=EXISTING, default=None, help="a trained generator")
    parser.add_argument("--demos", type=COUNT, default=4000, help="demonstrations to make (default 4000)")
    parser.add_argument("--epochs", type=COUNT, default=300, help="generator epochs (default 300)")
    parser.add_argument(
        "--generator-seeds",
        type=COUNT,
        default=4,
        help="generators trained (seeds 0, 1, ...); the one whose fitted mean solves the most tuning "
        "initial states is kept (default 4)",
    )
    parser.add_argument(
        "--selection-states",
        type=COUNT,
        default=100,
        help="tuning initial states (reset seeds from TUNING_GOAL_SEED) that choose the generator",
    )
    parser.add_argument("--episodes", type=COUNT, default=None, help="GenRL episodes (default: the task's)")
    parser.add_argument("--seeds", type=SEED, nargs="+", default=list(BENCHMARK_SEEDS))
    parser.add_argument(
        "--eval-every",
        type=COUNT,
        default=None,
        help="episodes between evaluations, a multiple of the episodes per iteration (default: about a sixth of the budget)",
    )
    parser.add_argument("--eval-states", type=COUNT, default=500, help="held-out initial states per evaluation")
    parser.add_argument("--recon-demos", type=COUNT, default=200, help="new demonstrations reconstructed (default 200)")
    parser.add_argument("--limit-states", type=COUNT, default=100, help="held-out states of the generator's limit")
    parser.add_argument("--prior-draws", type=COUNT, default=100, help="prior draws per state of the generator's limit")
    parser.add_argument(
        "--near-draws",
        type=COUNT,
        default=16,
        help="draws from the first seed's final policy per held-out state of the generator's limit near it (default 16)",
    )
    parser.add_argument("--threads", type=COUNT, default=1, help="worker processes playing episodes (default 1)")
    parser.add_argument("--work", default=None, help="folder of the stages' files (default: runs/fetch/TASK)")
    parser.add_argument("--out", type=JSON_OUT, default=None, help="JSON output (default: results/fetch_TASK.json)")
    parser.add_argument(
        "--no-demonstrations",
        action="store_true",
        help="GenRL without the entry's learning from demonstrations (its callback "
        "sb3_genrl.genrl.demonstrations.DemonstrationCallback), for the comparison",
    )
    parser.add_argument("--overwrite", action="store_true", help="start again instead of resuming --out")
    parser.add_argument(
        "--new-runs",
        action="store_true",
        help="keep --out's demonstrations, generator and its measures, and start its GenRL runs again "
        "(when only GenRL's settings differ)",
    )
    args = parser.parse_args(argv)
    args.out = args.out or os.path.join(RESULTS, f"fetch_{args.task}.json")
    args.work = os.path.abspath(args.work or os.path.join(ROOT, "runs", "fetch", args.task))
    args.dataset = args.data or os.path.join(args.work, "demonstrations")  # the demonstrations GenRL learns from
    if not args.no_demonstrations and args.generator is not None and args.data is None:
        parser.error(
            "the task's settings learn from demonstrations: give the generator's dataset as --data with "
            "--generator (or --no-demonstrations)"
        )
    episodes, batch_episodes, _ = task_settings(args.task)
    args.episodes = args.episodes or episodes
    args.eval_every = args.eval_every or max(batch_episodes, round(args.episodes / 6 / batch_episodes) * batch_episodes)
    if args.eval_every % batch_episodes:
        parser.error(f"--eval-every must be a multiple of the task's {batch_episodes} episodes per iteration")
    return args


def settings_of(args: argparse.Namespace) -> dict[str, object]:
    """What the run is: compared with the JSON's on resume."""
    _, batch_episodes, genrl_kwargs = task_settings(args.task)
    return {
        "task": args.task,
        "env_id": get_task(args.task).env_id,
        "episodes": args.episodes,
        "batch_episodes": batch_episodes,
        "genrl_settings": recorded_genrl_settings(args.task),
        "seeds": list(args.seeds),
        "eval_every": args.eval_every,
        "eval_states": args.eval_states,
        "eval_seed": EVAL_GOAL_SEED,
        "demonstrations": args.demos if args.data is None else os.path.abspath(args.data),
        "demonstration_recipe": get_task(args.task).demonstration_recipe if args.data is None else None,
        "generator": "trained" if args.generator is None else os.path.abspath(args.generator),
        "preset": quickstart_preset(args.task),
        "generator_recipe": resolve_generator_spec(quickstart_preset(args.task)),
        "epochs": args.epochs,
        "generator_seeds": None if args.generator else args.generator_seeds,
        "selection_states": None if args.generator else args.selection_states,
        "recon_demos": args.recon_demos,
        "limit_states": args.limit_states,
        "prior_draws": args.prior_draws,
        "demonstration_callback": None if args.no_demonstrations else genrl_kwargs.get("callback"),
    }


RUN_SETTINGS = ("episodes", "batch_episodes", "genrl_settings", "seeds", "eval_every", "eval_states", "demonstration_callback")


def start(args: argparse.Namespace) -> dict[str, object]:
    """The JSON to continue (same settings) or a new one."""
    settings = settings_of(args)
    if os.path.exists(args.out) and not args.overwrite:
        with open(args.out) as file:
            result = json.load(file)
        recorded = result.setdefault("settings", {})
        if "demonstration_recipe" not in recorded:  # a file of an earlier version, which did not record it
            recorded["demonstration_recipe"] = recorded_demonstration_recipe(recorded)
        if result.get("settings") != settings:
            differ = sorted(key for key in settings if result.get("settings", {}).get(key) != settings[key])
            if not (args.new_runs and set(differ) <= set(RUN_SETTINGS)):
                raise SystemExit(
                    f"{args.out} holds another run (it differs in {', '.join(differ)}): give another "
                    "--out, --overwrite to start again, or --new-runs if only GenRL's settings differ"
                )
            print(f"{args.out}: GenRL's runs start again ({', '.join(differ)} differ); its other stages are kept")
            for run in result["runs"]:
                shutil.rmtree(os.path.join(args.work, f"seed_{run['seed']}"), ignore_errors=True)
            result.update(settings=settings, runs=[], complete=False)
            for key in ("final_success_mean", "final_success_std", "finished_seeds", "policy_neighbourhood"):
                result.pop(key, None)
        return result
    return {"benchmark": f"fetch_{args.task}", "settings": settings, "complete": False, "runs": []}


def generator_stage(args: argparse.Namespace, result: dict, write) -> str:
    """The generator: ``--generator``, the one in ``--work`` if the JSON records it, else made (demonstrations, then
    ``--generator-seeds`` trainings, each scored as it finishes, the best kept)."""
    os.makedirs(args.work, exist_ok=True)
    path = os.path.join(args.work, "vae.pt")
    if args.generator is not None:
        if "generator" not in result:
            result["generator"] = {"generator": os.path.abspath(args.generator)}
            write()
        return args.generator
    if "kept_seed" in result.get("generator", {}) and os.path.exists(path):
        return path
    data = os.path.join(args.work, "demonstrations")
    if args.data is None and os.path.isdir(data) and os.listdir(data):
        recipe = dataset_recipe(args.task, dataset_info(data))  # (a dataset of an earlier version: the 2 cm one)
        conflicts = settings_conflicts(data, recipe, get_task(args.task).demonstration_recipe)
        if conflicts:
            raise SystemExit(f"{conflicts[0]}: move that dataset away to make it again, or give it as --data")
        args.data = data  # made before the stop (a dataset folder is written as one unit)
    args.data = args.data or make_benchmark_demonstrations(args.task, args.demos, args.work, args.threads)
    record = result.setdefault("generator", {})
    record.update(
        demonstrations=args.demos if args.data == data else os.path.abspath(args.data),
        preset=quickstart_preset(args.task),
        epochs=args.epochs,
        demonstration_info=dataset_info(args.data),
    )
    candidates = record.setdefault("candidates", [])
    for seed in range(len(candidates), args.generator_seeds):
        start_time = time.perf_counter()
        candidate = os.path.join(args.work, f"vae_seed{seed}.pt")
        vae = train_generator(
            args.data, preset=quickstart_preset(args.task), epochs=args.epochs, seed=seed, out=candidate, progress_bar=True
        )
        success = fitted_mean_success(args.task, candidate, args.dataset, args.selection_states, TUNING_GOAL_SEED)
        candidates.append(
            {
                "seed": seed,
                "best_epoch": vae.best_epoch,
                "fitted_mean_tuning_success": success,
                "seconds": time.perf_counter() - start_time,
            }
        )
        print(
            f"generator seed {seed}: the mean fitted to the demonstrations solves {success:.3f} of "
            f"{args.selection_states} tuning initial states",
            flush=True,
        )
        write()
    best = max(candidates, key=lambda candidate: candidate["fitted_mean_tuning_success"])  # the first of equals
    shutil.copyfile(os.path.join(args.work, f"vae_seed{best['seed']}.pt"), path + ".tmp")
    os.replace(path + ".tmp", path)
    record.update(kept_seed=best["seed"], best_epoch=best["best_epoch"])
    write()
    return path


def generator_limit(args: argparse.Namespace, generator: object, result: dict, write) -> None:
    """The generator's limit (stage 3), unless the JSON has it."""
    if "generator_limit" not in result:
        begin = time.perf_counter()
        result["generator_limit"] = prior_best_success(
            generator, args.task, args.limit_states, args.prior_draws, EVAL_GOAL_SEED, args.threads
        )
        result["generator_limit"]["seconds"] = time.perf_counter() - begin
        write()
    print(
        f"the best of {args.prior_draws} prior draws solves {result['generator_limit']['success_rate']:.3f} of "
        f"{args.limit_states} held-out states",
        flush=True,
    )


def neighbourhood_limit(args: argparse.Namespace, generator: object, seed: int, result: dict, write) -> None:
    """What the generator allows near the first seed's final policy (stage 5), unless the JSON has it."""
    if "policy_neighbourhood" not in result:
        begin = time.perf_counter()
        model = GenRL.load(os.path.join(args.work, f"seed_{seed}", "genrl_policy.zip"), generator=generator, device="cpu")
        result["policy_neighbourhood"] = policy_neighbourhood_success(
            model, args.task, args.limit_states, args.near_draws, EVAL_GOAL_SEED, args.threads
        )
        result["policy_neighbourhood"].update(policy_seed=seed, seconds=time.perf_counter() - begin)
        write()
    near = result["policy_neighbourhood"]
    print(
        f"near seed {near['policy_seed']}'s final policy: its mean solves {near['deterministic_success']:.3f} of "
        f"{near['states']} held-out states, the best of {near['draws_per_state']} draws from it "
        f"{near['best_of_draws']:.3f}",
        flush=True,
    )


def main(argv: list[str] | None = None) -> None:
    args = arguments(argv)
    torch.set_num_threads(1)
    result = start(args)
    result.update(**provenance(), machine=platform.machine(), cpus=os.cpu_count())

    def write() -> None:
        write_result(args.out, result)

    generator_path = generator_stage(args, result, write)
    generator = load(generator_path, device="cpu")
    if "reconstruction" not in result:
        result["reconstruction"] = reconstruction_success(
            generator, args.task, args.recon_demos, RECONSTRUCTION_SEED, args.threads
        )
        write()
    print(f"reconstructions reach their aims: {result['reconstruction']['success_rate']:.3f}", flush=True)
    for index, seed in enumerate(args.seeds):
        row = seed_row(result, seed)
        if not row["finished"]:
            train_seed(args.task, generator_path, seed, args, row, write)
        print(f"seed {seed}: success {row['final_success']:.3f} after {row['curve_episodes'][-1]} episodes", flush=True)
        if index == 0:  # after the first seed: its result comes first, the generator's limits next
            generator_limit(args, generator, result, write)
            neighbourhood_limit(args, generator, seed, result, write)
    result["complete"] = all_seeds_finished(result)
    write()
    print(f"GenRL on {args.task}: {result['final_success_mean']:.3f} mean final success; wrote {args.out}")


if __name__ == "__main__":
    main()
