"""GenRL against the baselines on one task, for several seeds, on one episode budget (paper figures 6 and 8).

Methods: GenRL, PPO (BC), SAC (prefilled), SAC (no prefill), SAC + HER, and PPO / SAC / TRPO on the generator's
latent space (see :mod:`sb3_genrl.baselines.train` and :mod:`sb3_genrl.baselines.hyperparameters`). Every method
plays the same number of episodes; a feedback episode is the task's horizon in environment steps, a GenRL or
latent-space episode is one trajectory of that many steps, so both axes (episodes, environment steps) hold.

GenRL runs with its defaults (``--genrl-kwargs`` changes them; a task's own settings in ``hyperparams/genrl.yml`` are
made for its own budget of episodes), the baselines with rl-zoo3's settings (``hyperparams/ppo.yml``, ``sac.yml``,
``latent_*.yml``; ``--baseline-kwargs`` changes them, recorded with each run).

Each run has its own folder under ``--work`` (``METHOD/seedS``) where it writes its per-episode records (SB3's
Monitor file) as it goes; a run whose ``run.json`` exists is skipped when the settings recorded there match, and the
benchmark refuses to mix runs of other settings; a stopped SAC run resumes from its last checkpoint (every 250
episodes, see :mod:`sb3_genrl.baselines.checkpoint`), the others start again. The results: ``--out`` (JSON), beside
it the Markdown table of the mean distance at 100, 300, 1000 and 3000 episodes (training episodes as played, which
for a method still exploring is not what its policy can do) and of each final policy played deterministically on
the same 100 held-out goals (kept in the run's ``final_eval.json``), and the curves (reward against episodes and
against environment steps, table contacts per episode). A finished run's records (``run.json``, the Monitor file,
``logs/progress*.csv`` and ``final_eval.json``) are all the results need: a run folder kept without its policy file
and checkpoints (to store or move it) is reused as it is, and refused if its evaluation was made with other goals,
another generator or another version. ``--merge`` keeps the other methods of an existing ``--out`` and adds (or
replaces) the methods run now, so that methods run at different times share one table; it refuses a result of
another task, budget, seed list, demonstration dataset, generator or package version.

    python -m benchmarks.baselines                          # hockey, 3 seeds x 3000 episodes, every method
    python -m benchmarks.baselines --jobs 2                 # two runs at a time
    python -m benchmarks.baselines --task basketball --jobs 2   # basketball (benchmarks/results/baselines_basketball.json)
    python -m benchmarks.baselines --episodes 40 --seeds 0 --out /tmp/tiny.json --work /tmp/tiny   # end-to-end check
    python -m benchmarks.baselines --methods ppo --episodes 1000 --baseline-kwargs '{"ppo": {"target_kl": 0.02}}' \
        --work benchmarks/runs/ppo_target_kl --out /tmp/ppo_target_kl.json      # a change to the zoo's settings
    python -m benchmarks.baselines --task basketball --methods sac-her --merge   # add one method to the committed table
"""

from __future__ import annotations

import argparse
import hashlib
import json
import multiprocessing
import os
import pathlib
import platform
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

import gymnasium as gym
import torch
from sb3_genrl.baselines.evaluation import EVAL_GOALS, evaluate_trained, load_trained
from sb3_genrl.baselines.hyperparameters import baseline_kwargs_argument, settings_record
from sb3_genrl.baselines.train import train_baseline
from sb3_genrl.envs import arm_tasks, get_task
from sb3_genrl.envs.demonstrations import make_demonstrations

from benchmarks.baselines_results import METHODS, WINDOW, core_hours, merge_results, method_result, write_outputs
from sb3_genrl import __version__
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, OUT_DIR, SEED, json_object_argument
from sb3_genrl.curves import MONITOR_FILE, read_monitor
from sb3_genrl.data import dataset_info
from sb3_genrl.generative import load, train_generator
from sb3_genrl.genrl import check_genrl_settings
from sb3_genrl.hyperparams import EVAL_GOAL_SEED
from sb3_genrl.provenance import provenance
from sb3_genrl.run import train_policy
from sb3_genrl.run.folder import differing
from sb3_genrl.run.train import effective_genrl_settings
from sb3_genrl.utils import atomic_write_json

HERE = pathlib.Path(__file__).resolve().parent
# what final_evaluation keeps of evaluate_trained's result
FINAL_RESULTS = {"mean_distance", "median_distance", "p90_distance", "table_contacts", "unstable", "object_unmoved"}
GENERATOR_PRESET, GENERATOR_EPOCHS = "VAE1", 300  # the quickstart's generator


def _file_digest(path: str) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()[:16]


def _version() -> str:
    return __version__


def _dataset(demos: str) -> dict[str, Any]:
    """What identifies a demonstration dataset made by the package: its task, seed and number of episodes."""
    info = dataset_info(demos)
    return {key: info.get(key) for key in ("task", "seed", "episodes")}


def _shown(path: str) -> str:
    """A path as the results show it: relative to the repository when inside it, else absolute."""
    path = os.path.abspath(path)
    root = str(HERE.parent)
    return os.path.relpath(path, root) if path.startswith(root + os.sep) else path


def run_settings(method: str, args: argparse.Namespace, seed: int, demos: str, generator: str) -> dict[str, Any]:
    """What a run's result depends on: compared with a finished run's record before it is reused."""
    info = dataset_info(demos)
    settings: dict[str, Any] = {
        "method": method,
        "task": args.task,
        "seed": seed,
        "episodes": args.episodes,
        "sb3_genrl": __version__,
    }
    changes = args.baseline_kwargs.get(method, {})
    if changes:  # (only when given, so that the records of runs without changes stay as they were)
        settings["algorithm_kwargs"] = changes
    if method == "genrl" or method.startswith("latent-"):
        settings |= {
            "generator": os.path.abspath(generator),
            "generator_sha256": _file_digest(generator),
            "batch_episodes": args.genrl_kwargs.get("n_steps", WINDOW) if method == "genrl" else WINDOW,
        }
        if method == "genrl":  # the chosen GenRL arguments, and every setting in effect
            settings["genrl_kwargs"] = args.genrl_kwargs
            settings["genrl"] = effective_genrl_settings(args.genrl_kwargs, settings["batch_episodes"], n_envs=1)
    else:
        settings |= {
            "demos": os.path.abspath(demos),
            "demo_episodes": info["episodes"],
            "demo_seed": info.get("seed"),
            "hyperparameters": settings_record(args.task, {method: changes} if changes else None)[method],
        }
    return json.loads(json.dumps(settings))  # as it reads back from JSON


def run_one(method: str, settings: dict[str, Any], demos: str, generator: str, run_dir: str) -> str:
    """One run (a worker process' job); skipped when done with the same settings, refused when done with others."""
    torch.set_num_threads(1)
    run = pathlib.Path(run_dir)
    if finished(run, settings):
        return run_dir
    run.mkdir(parents=True, exist_ok=True)
    began = time.perf_counter()
    if method == "genrl":
        genrl_kwargs = {key: value for key, value in settings["genrl_kwargs"].items() if key != "n_steps"}
        summary = train_policy(
            settings["task"],
            generator,
            episodes=settings["episodes"],
            seed=settings["seed"],
            out_dir=run,
            batch_episodes=settings["batch_episodes"],
            n_envs=1,  # as the committed results were made; the methods' runs go side by side (--jobs)
            device="cpu",
            **genrl_kwargs,
        )
        timing = {"setup_seconds": 0.0, "setup_cpu_seconds": 0.0, "learn_seconds": time.perf_counter() - began}
    else:
        latent = method.startswith("latent-")
        summary = train_baseline(
            method,
            settings["task"],
            episodes=settings["episodes"],
            out_dir=run,
            seed=settings["seed"],
            demos=None if latent else demos,
            generator=generator if latent else None,
            algorithm_kwargs=settings.get("algorithm_kwargs"),
            device="cpu",
            n_envs=1 if latent else None,  # as the committed results were made; the methods' runs go side by side
        )
        timing = {key: summary[key] for key in ("setup_seconds", "setup_cpu_seconds", "learn_seconds")}
    atomic_write_json(
        run / "run.json",
        {
            "settings": settings,
            **timing,
            "episodes_played": _episodes_played(run),
            "bc": summary.get("bc"),
            "first_batch": summary.get("first_batch"),
        },
    )
    return run_dir


def finished(run: pathlib.Path, settings: dict[str, Any]) -> bool:
    """Whether ``run`` holds a finished run of ``settings``; raises if it holds one of other settings."""
    record = run / "run.json"
    if not record.exists():
        return False
    recorded = json.loads(record.read_text())["settings"]
    if recorded != settings:
        raise ValueError(
            f"{run} holds a finished run with other settings ({', '.join(differing(recorded, settings))}); use another --work"
        )
    return True


def _episodes_played(run: pathlib.Path) -> int:
    return len(read_monitor(run / MONITOR_FILE).get("return", []))


def prepare(args: argparse.Namespace, work: pathlib.Path) -> tuple[str, str]:
    """The demonstrations and the generator: given, or made once in ``work`` (and reused on a rerun)."""
    demos = args.demos
    if demos is None:
        demos = str(work / "demonstrations")
        if not pathlib.Path(demos).exists():
            make_demonstrations(args.task, args.demo_count, demos, seed=0, progress_bar=False)
    generator = args.generator
    needs_generator = any(m == "genrl" or m.startswith("latent-") for m in args.methods)
    if generator is None and needs_generator:
        generator = str(work / f"{GENERATOR_PRESET}.pt")
        if not pathlib.Path(generator).exists():
            tmp = work / f".{GENERATOR_PRESET}.pt.tmp"
            train_generator(demos, preset=GENERATOR_PRESET, epochs=GENERATOR_EPOCHS, seed=0, out=tmp, device="cpu")
            os.replace(tmp, generator)
    return demos, generator


def final_evaluation(run: pathlib.Path, method: str, task: str, generator: str | None) -> dict[str, Any]:
    """The run's trained policy, deterministic, on the held-out goals every method is evaluated on (the cloned
    policy's, ``sb3_genrl.baselines.evaluation.EVAL_GOALS``); kept in the run's ``final_eval.json`` under the digests of
    the policy and generator files and the package's version, so a rerun reads it and a retrained policy, another
    generator or another version is evaluated again."""
    policy = run / f"{method}_policy.zip"
    key = {
        "policy_sha256": _file_digest(str(policy)) if policy.exists() else None,
        "task": task,
        "goals": EVAL_GOALS,
        "goal_seed": EVAL_GOAL_SEED,
        "generator_sha256": _file_digest(generator) if generator else None,
        "sb3_genrl": __version__,
    }
    cache = run / "final_eval.json"
    if not policy.exists():  # an archived run (see the module doc): its evaluation is all there is
        if not cache.exists():
            raise ValueError(f"{run} has neither {policy.name} nor its final evaluation ({cache.name})")
        record = json.loads(cache.read_text())
        differ = [name for name in key if name != "policy_sha256" and record.get(name) != key[name]]
        missing = sorted(FINAL_RESULTS - record.keys())
        if differ or missing:
            why = f"was made with another {', '.join(differ)}" if differ else f"lacks {', '.join(missing)}"
            raise ValueError(f"{run} has no {policy.name} to evaluate again, and its {cache.name} {why}")
        return record
    if cache.exists():
        record = json.loads(cache.read_text())
        # (a record from before a result was added, e.g. ``object_unmoved``, is evaluated again)
        if {name: record.get(name) for name in key} == key and FINAL_RESULTS <= record.keys():
            return record
    latent = None
    if method == "genrl" or method.startswith("latent-"):
        latent = load(generator)
    model = load_trained(method, policy, task, generator=latent)
    record = key | evaluate_trained(method, model, task, generator=latent, goals=EVAL_GOALS, seed=EVAL_GOAL_SEED)
    atomic_write_json(cache, record)
    return record


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    """The benchmark's checked arguments (``--genrl-kwargs`` by :func:`sb3_genrl.genrl.check_genrl_settings`)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="hockey", choices=arm_tasks(), help="a task on the arm (default: hockey)")
    parser.add_argument("--episodes", type=COUNT, default=3000, help="episode budget of every run")
    parser.add_argument("--seeds", type=SEED, nargs="+", default=[0, 1, 2])
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument(
        "--demos", type=EXISTING, default=None, help="demonstration dataset (default: make --demo-count of them)"
    )
    parser.add_argument("--demo-count", type=COUNT, default=4000, help="demonstrations to make when --demos is not given")
    parser.add_argument(
        "--generator",
        type=EXISTING,
        default=None,
        help=f"generator for GenRL and the latent baselines (default: {GENERATOR_PRESET}, "
        f"{GENERATOR_EPOCHS} epochs, on the demonstrations)",
    )
    parser.add_argument(
        "--genrl-kwargs",
        type=json_object_argument,
        default={},
        help="GenRL's arguments, as JSON (default: GenRL's defaults; see the module doc)",
    )
    parser.add_argument(
        "--baseline-kwargs",
        type=baseline_kwargs_argument,
        default={},
        help="changes to the baselines' rl-zoo3 settings, as JSON: {baseline: {argument: value}}, e.g. "
        '\'{"ppo": {"target_kl": 0.02}}\' (default: none)',
    )
    parser.add_argument("--jobs", type=COUNT, default=1, help="runs at a time, one process (one core) each")
    parser.add_argument(
        "--work", type=OUT_DIR, default=None, help="folder of the runs (default: benchmarks/runs/baselines_TASK)"
    )
    parser.add_argument(
        "--out",
        type=JSON_OUT,
        default=None,
        help="JSON result (default: benchmarks/results/baselines[_TASK].json); .md and PNGs beside it",
    )
    parser.add_argument(
        "--merge",
        action="store_true",
        help="keep the methods of an existing --out that this call does not run (same settings only)",
    )
    args = parser.parse_args(argv)
    if set(args.baseline_kwargs) - set(args.methods):
        parser.error(
            f"--baseline-kwargs changes {', '.join(sorted(set(args.baseline_kwargs) - set(args.methods)))}, "
            "which --methods does not run"
        )
    try:
        check_genrl_settings(args.genrl_kwargs)
    except (TypeError, ValueError) as error:
        parser.error(f"argument --genrl-kwargs: {error}")
    return args


class MergeCheck:
    """With ``--merge``, refuses ``--out``'s result when it was made with other settings than the benchmark's so far
    (checked before the demonstrations or the generator are made, then before any run)."""

    def __init__(self, out: pathlib.Path, merge: bool) -> None:
        self.out, self.active, self.previous = out, merge and out.exists(), None

    def __call__(self, benchmark: dict[str, Any]) -> None:
        if not self.active:
            return
        try:
            self.previous = json.loads(self.out.read_text()) if self.previous is None else self.previous
            merge_results(self.previous, benchmark)
        except (ValueError, KeyError, TypeError) as error:  # (a JSON error is a ValueError)
            raise SystemExit(f"baselines.py: --merge: cannot merge into {self.out}: {error}") from None


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark from the command line."""
    args = arguments(argv)
    spec = get_task(args.task)
    args.task = spec.name
    work = pathlib.Path(args.work or HERE / "runs" / f"baselines_{spec.name}")
    out = pathlib.Path(
        args.out or HERE / "results" / ("baselines.json" if spec.name == "hockey" else f"baselines_{spec.name}.json")
    )
    # what the result is a result of, built up as it becomes known; with --merge, compared with --out's at each step
    benchmark = {
        "benchmark": "baselines",
        "task": spec.name,
        "horizon": spec.horizon,
        "episodes": args.episodes,
        "seeds": args.seeds,
        "window": WINDOW,
        "sb3_genrl": _version(),
        "methods": {},
    }
    check_merge = MergeCheck(out, args.merge)
    check_merge(benchmark)
    work.mkdir(parents=True, exist_ok=True)
    demos, generator = prepare(args, work)
    benchmark |= {"demos": _shown(demos), "demo_dataset": _dataset(demos)}
    if generator:
        benchmark["generator_sha256"] = _file_digest(generator)
    check_merge(benchmark)
    jobs = [
        (method, run_settings(method, args, seed, demos, generator), demos, generator, str(work / method / f"seed{seed}"))
        for method in args.methods
        for seed in args.seeds
    ]
    run_jobs(jobs, args.jobs)
    result = benchmark | provenance() | {"machine": platform.machine(), "cpus": os.cpu_count(), "jobs": args.jobs}
    result = collect(result, args, work, generator, {job[0]: job[1] for job in jobs})
    if check_merge.previous is not None:
        result = merge_results(check_merge.previous, result)
    result["core_hours_3000_episodes_3_seeds"] = core_hours(result, 3000, 3)
    write_outputs(result, out)
    print(out.with_suffix(".md").read_text())
    print(f"estimated single-core hours for 3 seeds x 3000 episodes: {result['core_hours_3000_episodes_3_seeds']:.1f}")


def run_jobs(jobs: list[tuple[Any, ...]], processes: int) -> None:
    """Run the jobs not done yet (:func:`run_one`), ``processes`` at a time; refuse before running anything if a
    finished run of other settings is in the way."""
    try:
        todo = [job for job in jobs if not finished(pathlib.Path(job[-1]), job[1])]
    except ValueError as error:
        raise SystemExit(f"baselines.py: {error}") from None
    print(f"{len(jobs) - len(todo)} of {len(jobs)} runs already done", flush=True)
    began = time.perf_counter()
    if processes <= 1:
        for job in todo:
            print(f"done {run_one(*job)} ({time.perf_counter() - began:.0f} s)", flush=True)
        return
    with ProcessPoolExecutor(processes, mp_context=multiprocessing.get_context("spawn")) as pool:
        for future in as_completed([pool.submit(run_one, *job) for job in todo]):
            print(f"done {future.result()} ({time.perf_counter() - began:.0f} s)", flush=True)


def collect(
    result: dict[str, Any],
    args: argparse.Namespace,
    work: pathlib.Path,
    generator: str | None,
    settings: dict[str, dict[str, Any]],
) -> dict[str, Any]:
    """``result`` with each method's :func:`method_result` (its runs' final evaluations made or read first);
    ``settings``: each method's run settings (the same for all its seeds)."""
    spec = get_task(args.task)
    worst_reward = result["worst_reward"] = float(gym.make(spec.env_id).unwrapped.worst_reward)
    for method in args.methods:
        runs = [work / method / f"seed{seed}" for seed in args.seeds]
        try:
            finals = [final_evaluation(run, method, spec.name, generator) for run in runs]
        except ValueError as error:
            raise SystemExit(f"baselines.py: {error}") from None
        result["methods"][method] = method_result(runs, spec.horizon, finals, worst_reward)
        if method == "genrl":  # what GenRL ran with (e.g. hindsight), as each run's settings record it
            result["methods"][method] |= {key: settings[method][key] for key in ("genrl_kwargs", "genrl")}
    return result


if __name__ == "__main__":
    main()
