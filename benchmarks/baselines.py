"""GenRL against the baselines on one task, for several seeds, on one episode budget (paper figures 6 and 8).

Methods: GenRL, PPO (BC), SAC (prefilled), SAC (no prefill), SAC + HER, and PPO / SAC / TRPO on the generator's
latent space (see :mod:`sb3_genrl.baselines.train` and :mod:`sb3_genrl.baselines.hyperparameters`). Every method
plays the same number of episodes; a feedback episode is the task's horizon in environment steps, a GenRL or
latent-space episode is one trajectory of that many steps, so both axes (episodes, environment steps) hold.

GenRL runs with its defaults (``--genrl-kwargs`` changes them), the baselines with rl-zoo3's settings
(``--baseline-kwargs`` changes them, recorded with each run). At this benchmark's 3000 episodes they do best on
both tasks' tuning surrogates (``benchmarks/genrl_tuning.py``, tuning goals): basketball's own settings, made to
anneal the policy's spread over 20000 episodes, end at 0.83 m there after 3000 against 0.50 m with the defaults
(``benchmarks/results/genrl_tuning_basketball.json``); hockey's settings are the defaults.

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

    python benchmarks/baselines.py                          # hockey, 3 seeds x 3000 episodes, every method
    python benchmarks/baselines.py --jobs 2                 # two runs at a time
    python benchmarks/baselines.py --task basketball --jobs 2   # basketball (benchmarks/results/baselines_basketball.json)
    python benchmarks/baselines.py --episodes 40 --seeds 0 --out /tmp/tiny.json --work /tmp/tiny   # end-to-end check
    python benchmarks/baselines.py --methods ppo --episodes 1000 --baseline-kwargs '{"ppo": {"target_kl": 0.02}}' \
        --work benchmarks/runs/ppo_target_kl --out /tmp/ppo_target_kl.json      # a change to the zoo's settings
    python benchmarks/baselines.py --task basketball --methods sac-her --merge   # add one method to the committed table
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
import numpy as np
from sb3_genrl.baselines.hyperparameters import baseline_kwargs_argument
from sb3_genrl.envs import TASKS

from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT, OUT_DIR, SEED
from sb3_genrl.genrl.train import genrl_kwargs_argument
from sb3_genrl.utils import atomic_write_json

HERE = pathlib.Path(__file__).resolve().parent
METHODS = ("genrl", "ppo", "sac", "sac-no-prefill", "sac-her", "latent-ppo", "latent-sac", "latent-trpo")
MILESTONES = (100, 300, 1000, 3000)  # episodes at which the table reports the mean distance
WINDOW = 64  # episodes averaged per point (GenRL's batch)
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
    import sb3_genrl

    return sb3_genrl.__version__


def _dataset(demos: str) -> dict[str, Any]:
    """What identifies a demonstration dataset made by the package: its task, seed and number of episodes."""
    from sb3_genrl.data import dataset_info

    info = dataset_info(demos)
    return {key: info.get(key) for key in ("task", "seed", "episodes")}


def _shown(path: str) -> str:
    """A path as the results show it: relative to the repository when inside it, else absolute."""
    path = os.path.abspath(path)
    root = str(HERE.parent)
    return os.path.relpath(path, root) if path.startswith(root + os.sep) else path


def run_settings(method: str, args: argparse.Namespace, seed: int, demos: str, generator: str) -> dict[str, Any]:
    """What a run's result depends on: compared with a finished run's record before it is reused."""
    from sb3_genrl.baselines.hyperparameters import settings_record

    from sb3_genrl import __version__
    from sb3_genrl.data import dataset_info

    info = dataset_info(demos)
    settings: dict[str, Any] = {"method": method, "task": args.task, "seed": seed, "episodes": args.episodes,
                                "sb3_genrl": __version__}
    changes = args.baseline_kwargs.get(method, {})
    if changes:  # (only when given, so that the records of runs without changes stay as they were)
        settings["algorithm_kwargs"] = changes
    if method == "genrl" or method.startswith("latent-"):
        settings |= {"generator": os.path.abspath(generator), "generator_sha256": _file_digest(generator),
                     "batch_episodes": args.genrl_kwargs.get("n_steps", WINDOW) if method == "genrl" else WINDOW}
        if method == "genrl":  # the chosen GenRL arguments, and every setting in effect
            from sb3_genrl.genrl.train import genrl_settings

            settings["genrl_kwargs"] = args.genrl_kwargs
            settings["genrl"] = genrl_settings(settings["genrl_kwargs"])
    else:
        settings |= {"demos": os.path.abspath(demos), "demo_episodes": info["episodes"], "demo_seed": info.get("seed"),
                     "hyperparameters": settings_record({method: changes} if changes else None)[method]}
    return json.loads(json.dumps(settings))  # as it reads back from JSON


def run_one(method: str, settings: dict[str, Any], demos: str, generator: str, run_dir: str) -> str:
    """One run (a worker process' job); skipped when done with the same settings, refused when done with others."""
    import torch

    torch.set_num_threads(1)
    run = pathlib.Path(run_dir)
    if finished(run, settings):
        return run_dir
    run.mkdir(parents=True, exist_ok=True)
    began = time.perf_counter()
    if method == "genrl":
        from sb3_genrl.genrl import train_policy

        genrl_kwargs = {key: value for key, value in settings["genrl_kwargs"].items() if key != "n_steps"}
        summary = train_policy(settings["task"], generator, episodes=settings["episodes"], seed=settings["seed"],
                               out_dir=run, batch_episodes=settings["batch_episodes"], device="cpu", **genrl_kwargs)
        timing = {"setup_seconds": 0.0, "setup_cpu_seconds": 0.0, "learn_seconds": time.perf_counter() - began}
    else:
        from sb3_genrl.baselines.train import train_baseline

        latent = method.startswith("latent-")
        summary = train_baseline(method, settings["task"], episodes=settings["episodes"], out_dir=run,
                                 seed=settings["seed"], demos=None if latent else demos,
                                 generator=generator if latent else None,
                                 algorithm_kwargs=settings.get("algorithm_kwargs"), device="cpu")
        timing = {key: summary[key] for key in ("setup_seconds", "setup_cpu_seconds", "learn_seconds")}
    atomic_write_json(run / "run.json", {"settings": settings, **timing, "episodes_played": _episodes_played(run),
                                         "bc": summary.get("bc"), "first_batch": summary.get("first_batch")})
    return run_dir


def finished(run: pathlib.Path, settings: dict[str, Any]) -> bool:
    """Whether ``run`` holds a finished run of ``settings``; raises if it holds one of other settings."""
    record = run / "run.json"
    if not record.exists():
        return False
    recorded = json.loads(record.read_text())["settings"]
    if recorded != settings:
        differ = sorted(k for k in set(recorded) | set(settings) if recorded.get(k) != settings.get(k))
        raise ValueError(f"{run} holds a finished run with other settings ({', '.join(differ)}); use another --work")
    return True


def _episodes_played(run: pathlib.Path) -> int:
    from sb3_genrl.curves import MONITOR_FILE, read_monitor

    return len(read_monitor(run / MONITOR_FILE).get("return", []))


def prepare(args: argparse.Namespace, work: pathlib.Path) -> tuple[str, str]:
    """The demonstrations and the generator: given, or made once in ``work`` (and reused on a rerun)."""
    demos = args.demos
    if demos is None:
        demos = str(work / "demonstrations")
        if not pathlib.Path(demos).exists():
            from sb3_genrl.envs.demonstrations import make_demonstrations

            make_demonstrations(args.task, args.demo_count, demos, seed=0, progress_bar=False)
    generator = args.generator
    needs_generator = any(m == "genrl" or m.startswith("latent-") for m in args.methods)
    if generator is None and needs_generator:
        generator = str(work / f"{GENERATOR_PRESET}.pt")
        if not pathlib.Path(generator).exists():
            from sb3_genrl.generative import train_generator

            tmp = work / f".{GENERATOR_PRESET}.pt.tmp"
            train_generator(demos, preset=GENERATOR_PRESET, epochs=GENERATOR_EPOCHS, seed=0, out=tmp, device="cpu")
            os.replace(tmp, generator)
    return demos, generator


def final_evaluation(run: pathlib.Path, method: str, task: str, generator: str | None) -> dict[str, Any]:
    """The run's trained policy, deterministic, on the held-out goals every method is evaluated on (the cloned
    policy's, ``sb3_genrl.baselines.train.EVAL_GOALS``); kept in the run's ``final_eval.json`` under the digests of
    the policy and generator files and the package's version, so a rerun reads it and a retrained policy, another
    generator or another version is evaluated again."""
    from sb3_genrl.baselines.train import EVAL_GOAL_SEED, EVAL_GOALS, evaluate_trained, load_trained

    import sb3_genrl

    policy = run / f"{method}_policy.zip"
    key = {"policy_sha256": _file_digest(str(policy)) if policy.exists() else None, "task": task, "goals": EVAL_GOALS,
           "goal_seed": EVAL_GOAL_SEED, "generator_sha256": _file_digest(generator) if generator else None,
           "sb3_genrl": sb3_genrl.__version__}
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
        from sb3_genrl.generative import load

        latent = load(generator)
    model = load_trained(method, policy, task, generator=latent)
    record = key | evaluate_trained(method, model, task, generator=latent, goals=EVAL_GOALS, seed=EVAL_GOAL_SEED)
    atomic_write_json(cache, record)
    return record


def method_result(runs: list[pathlib.Path], horizon: int, finals: list[dict[str, Any]],
                  worst_reward: float) -> dict[str, Any]:
    """Distances, table contacts and timings of one method's runs (one per seed); ``finals``: their
    :func:`final_evaluation`; ``worst_reward``: the task's (the reward's floor)."""
    from sb3_genrl.baselines.train import training_health

    from sb3_genrl.curves import MONITOR_FILE, read_monitor, windowed_curve

    per_seed = [read_monitor(run / MONITOR_FILE) for run in runs]
    records = [json.loads((run / "run.json").read_text()) for run in runs]
    n = min(len(columns["return"]) for columns in per_seed)
    distances = np.stack([-columns["return"][:n] for columns in per_seed])
    contacts = np.stack([columns.get("table_contacts", np.full(n, np.nan))[:n] for columns in per_seed])
    grid, _ = windowed_curve(distances[0], WINDOW)
    curves = np.stack([windowed_curve(d, WINDOW)[1] for d in distances])
    has_contacts = bool(np.isfinite(contacts).any())  # a task without a table (basketball) reports none
    contact_curves = np.stack([windowed_curve(c, WINDOW)[1] for c in contacts]) if has_contacts else None
    milestones = {}
    for episodes in MILESTONES:
        if n >= episodes:
            values = distances[:, episodes - min(WINDOW, episodes):episodes].mean(axis=1)
            milestones[str(episodes)] = {"mean": float(values.mean()), "std": float(values.std()),
                                         "per_seed": values.tolist()}
    # Steady-state cost: CPU seconds per episode over the second half of each run (the process' own CPU time, so
    # what else runs on the machine does not count).
    half = n // 2
    cpu_rates = [(n - half) / (columns["cpu_seconds"][n - 1] - (columns["cpu_seconds"][half - 1] if half else 0.0))
                 for columns in per_seed]
    final_distances = np.array([final["mean_distance"] for final in finals])
    final_contacts = [final["table_contacts"] for final in finals]
    final = {"goals": finals[0]["goals"], "goal_seed": finals[0]["goal_seed"], "mean": float(final_distances.mean()),
             "std": float(final_distances.std()), "per_seed": final_distances.tolist(),
             "median_per_seed": [f["median_distance"] for f in finals], "p90_per_seed": [f["p90_distance"] for f in finals],
             "table_contacts": None if None in final_contacts else float(np.mean(final_contacts)),
             "unstable_per_seed": [f["unstable"] for f in finals],
             "object_unmoved_per_seed": [f["object_unmoved"] for f in finals]}
    return {"seeds": len(runs), "episodes": int(n), "env_steps_per_episode": horizon, "milestones": milestones,
            "final_deterministic": final,
            "training_health": [training_health(run) for run in runs],
            "curve": {"episodes": grid.tolist(), "mean_distance": curves.mean(0).tolist(),
                      "std_distance": curves.std(0).tolist(),
                      "table_contacts": np.nanmean(contact_curves, 0).tolist() if has_contacts else None},
            "table_contacts_per_episode": float(np.nanmean(contacts)) if has_contacts else None,
            # training episodes at the task's worst reward, the reward's floor: that far from the goal or further,
            # a ball that never came down through the rim's height (basketball), or an unstable simulation
            "worst_reward_share": float(np.isclose(-distances, worst_reward).mean()),
            "setup_seconds": float(np.mean([r["setup_seconds"] for r in records])),
            "setup_cpu_seconds": float(np.mean([r["setup_cpu_seconds"] for r in records])),
            "episodes_per_second": float(np.mean([r["episodes_played"] / r["learn_seconds"] for r in records])),
            "episodes_per_cpu_second": float(np.mean(cpu_rates)),
            "bc": [r["bc"] for r in records if r.get("bc")], "first_batch": [r["first_batch"] for r in records
                                                                              if r.get("first_batch")]}


# what must agree between a result and the methods merged into it (see ``merge_results``)
MERGE_KEYS = ("benchmark", "task", "horizon", "episodes", "seeds", "window", "sb3_genrl", "worst_reward", "demos",
              "demo_dataset", "generator_sha256")


def merge_results(previous: dict[str, Any], current: dict[str, Any]) -> dict[str, Any]:
    """``current`` with the methods of ``previous`` that it did not run, in the benchmark's order of methods.

    Raises ``ValueError`` naming what differs when the two are not results of the same benchmark settings; a key that
    ``previous`` does not hold (a result written before it was recorded) is not compared, except ``demos``, the
    dataset's path, which every result holds; one that only ``previous`` holds (the generator's digest, when
    ``current`` ran no method that uses it) is kept. ``merged_methods`` lists the methods taken from ``previous``."""
    differ = [key for key in MERGE_KEYS
              if (key in previous or key == "demos") and key in current and previous.get(key) != current[key]]
    if differ:
        shown = "; ".join(f"{key}: {previous.get(key)!r} there, {current[key]!r} now" for key in differ)
        raise ValueError(f"the result to merge into was made with other settings ({shown})")
    kept = [method for method in previous["methods"] if method not in current["methods"]]
    methods = previous["methods"] | current["methods"]
    order = [m for m in METHODS if m in methods] + [m for m in methods if m not in METHODS]
    carried = {key: previous[key] for key in MERGE_KEYS if key in previous and key not in current}
    return carried | current | {"methods": {method: methods[method] for method in order}, "merged_methods": kept}


def write_outputs(result: dict[str, Any], out: pathlib.Path) -> None:
    """The JSON, the Markdown table and the three plots."""
    from sb3_genrl.baselines.compare import LABELS
    from sb3_genrl.baselines.train import UNMOVED

    from sb3_genrl.curves import plot_curves
    from sb3_genrl.markdown import markdown_table
    from sb3_genrl.utils import atomic_write_text

    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out, result)
    stem, task = out.with_suffix(""), result["task"]
    series = {}
    for method, row in result["methods"].items():
        curve = row["curve"]
        series[LABELS.get(method, method)] = (np.array(curve["episodes"]), -np.array(curve["mean_distance"]),
                                              np.array(curve["std_distance"]))
    plot_curves(series, f"{stem}_episodes.png", ylabel="mean reward (-distance, m)", title=f"{task}: mean +- std over seeds")
    steps = {label: (x * result["horizon"], y, s) for label, (x, y, s) in series.items()}
    plot_curves(steps, f"{stem}_env_steps.png", ylabel="mean reward (-distance, m)", xlabel="environment steps",
                title=f"{task}: mean +- std over seeds")
    contacts = {LABELS.get(m, m): (np.array(r["curve"]["episodes"]), np.array(r["curve"]["table_contacts"]), None)
                for m, r in result["methods"].items() if r["curve"]["table_contacts"] is not None}
    if contacts:
        plot_curves(contacts, f"{stem}_contacts.png", ylabel="table contacts per episode (control steps)",
                    title=f"{task}: table contacts")
    goals = next(iter(result["methods"].values()))["final_deterministic"]["goals"]
    header = ["method", "seeds", *(f"{m} episodes" for m in MILESTONES), "final policy, deterministic",
              f"final policy: goals of {goals} with the object not moved, per seed", "table contacts / episode",
              "episodes at the worst reward", "setup (CPU s)", "episodes / CPU s"]
    rows = []
    for method, row in result["methods"].items():
        cells = [f"{row['milestones'][str(m)]['mean']:.3f} +- {row['milestones'][str(m)]['std']:.3f}"
                 if str(m) in row["milestones"] else "n/a" for m in MILESTONES]
        contacts_cell = "n/a" if row["table_contacts_per_episode"] is None else f"{row['table_contacts_per_episode']:.2f}"
        final = row["final_deterministic"]
        rows.append([LABELS.get(method, method), row["seeds"], *cells, f"{final['mean']:.3f} +- {final['std']:.3f}",
                     " / ".join(str(n) for n in final["object_unmoved_per_seed"]), contacts_cell,
                     f"{100 * row['worst_reward_share']:.1f}%", f"{row['setup_cpu_seconds']:.0f}",
                     f"{row['episodes_per_cpu_second']:.2f}"])
    lines = [f"# {task}: mean distance to the goal (m), mean +- std over seeds", "",
             f"Mean over the {WINDOW} episodes before each budget (training episodes, as played), and the final "
             f"policy's deterministic mean distance to {goals} held-out goals (the same goals for every method). "
             f"Episodes at the worst reward ({result['worst_reward']:g} m), the reward's floor, are training episodes "
             "that ended that far from the goal or further (hockey: a puck sent off the table), whose ball never came "
             "down through the rim's height (basketball), or whose simulation went unstable. An object not moved ends within "
             f"{UNMOVED * 100:g} cm of where it rests at the start: the final policy never hit the puck (or threw the "
             "ball), and scores what the arm holding still does.", "",
             markdown_table(header, rows)]
    warned = [f"- {LABELS.get(method, method)}, seed {seed}: {warning}" for method, row in result["methods"].items()
              for seed, health in zip(result["seeds"], row["training_health"], strict=True)
              for warning in health["warnings"]]
    if warned:
        lines += ["", "Training that did not stay stable (SB3's logs, `training_health`):", "", *warned]
    lines += ["", f"![episodes]({stem.name}_episodes.png)", "", f"![environment steps]({stem.name}_env_steps.png)", ""]
    if contacts:
        lines += [f"![table contacts]({stem.name}_contacts.png)", ""]
    atomic_write_text(out.with_suffix(".md"), "\n".join(lines))


def core_hours(result: dict[str, Any], episodes: int, seeds: int) -> float:
    """Single-core hours of the whole benchmark at ``episodes`` x ``seeds``, from the measured CPU costs (setup and
    steady-state episodes). SAC without prefill plays random actions until ``learning_starts``; a run too short to
    pass it is charged SAC (prefilled)'s rate, its cost once learning, beyond that point."""
    from sb3_genrl.baselines.hyperparameters import SAC_SETTINGS

    methods, seconds = result["methods"], 0.0
    for method, row in methods.items():
        rate = row["episodes_per_cpu_second"]
        warm_up = SAC_SETTINGS["learning_starts"] / result["horizon"]
        if method == "sac-no-prefill" and row["episodes"] <= warm_up and "sac" in methods:
            learning = max(episodes - warm_up, 0)
            cost = (episodes - learning) / rate + learning / methods["sac"]["episodes_per_cpu_second"]
        else:
            cost = episodes / rate
        seconds += seeds * (row["setup_cpu_seconds"] + cost)
    return seconds / 3600


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="hockey", choices=sorted(TASKS), help="a registered task (default: hockey)")
    parser.add_argument("--episodes", type=COUNT, default=3000, help="episode budget of every run")
    parser.add_argument("--seeds", type=SEED, nargs="+", default=[0, 1, 2])
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--demos", type=EXISTING, default=None,
                        help="demonstration dataset (default: make --demo-count of them)")
    parser.add_argument("--demo-count", type=COUNT, default=4000, help="demonstrations to make when --demos is not given")
    parser.add_argument("--generator", type=EXISTING, default=None,
                        help=f"generator for GenRL and the latent baselines (default: {GENERATOR_PRESET}, "
                             f"{GENERATOR_EPOCHS} epochs, on the demonstrations)")
    parser.add_argument("--genrl-kwargs", type=genrl_kwargs_argument, default={},
                        help="GenRL's arguments, as JSON (default: GenRL's defaults; see the module doc)")
    parser.add_argument("--baseline-kwargs", type=baseline_kwargs_argument, default={},
                        help="changes to the baselines' rl-zoo3 settings, as JSON: {baseline: {argument: value}}, e.g. "
                             "'{\"ppo\": {\"target_kl\": 0.02}}' (default: none)")
    parser.add_argument("--jobs", type=COUNT, default=1, help="runs at a time, one process (one core) each")
    parser.add_argument("--work", type=OUT_DIR, default=None,
                        help="folder of the runs (default: benchmarks/runs/baselines_TASK)")
    parser.add_argument("--out", type=JSON_OUT, default=None,
                        help="JSON result (default: benchmarks/results/baselines[_TASK].json); .md and PNGs beside it")
    parser.add_argument("--merge", action="store_true",
                        help="keep the methods of an existing --out that this call does not run (same settings only)")
    args = parser.parse_args()
    if set(args.baseline_kwargs) - set(args.methods):
        parser.error(f"--baseline-kwargs changes {', '.join(sorted(set(args.baseline_kwargs) - set(args.methods)))}, "
                     "which --methods does not run")
    from sb3_genrl.envs import get_task

    spec = get_task(args.task)
    args.task = spec.name
    work = pathlib.Path(args.work or HERE / "runs" / f"baselines_{spec.name}")
    out = pathlib.Path(args.out or HERE / "results" / ("baselines.json" if spec.name == "hockey"
                                                       else f"baselines_{spec.name}.json"))
    # what the result is a result of, built up as it becomes known; with --merge, compared with --out's at each step
    # (before the demonstrations or the generator are made, then before any run)
    benchmark = {"benchmark": "baselines", "task": spec.name, "horizon": spec.horizon, "episodes": args.episodes,
                 "seeds": args.seeds, "window": WINDOW, "sb3_genrl": _version(), "methods": {}}
    previous = None

    def check_merge() -> None:
        """Refuse --out's result when it was made with other settings than those in ``benchmark`` so far."""
        nonlocal previous
        try:
            previous = json.loads(out.read_text()) if previous is None else previous
            merge_results(previous, benchmark)
        except (ValueError, KeyError, TypeError) as error:  # (a JSON error is a ValueError)
            raise SystemExit(f"baselines.py: --merge: cannot merge into {out}: {error}") from None

    merge = args.merge and out.exists()
    if merge:
        check_merge()
    work.mkdir(parents=True, exist_ok=True)
    demos, generator = prepare(args, work)
    benchmark |= {"demos": _shown(demos), "demo_dataset": _dataset(demos)}
    if generator:
        benchmark["generator_sha256"] = _file_digest(generator)
    if merge:
        check_merge()
    jobs = [(method, run_settings(method, args, seed, demos, generator), demos, generator,
             str(work / method / f"seed{seed}")) for method in args.methods for seed in args.seeds]
    jobs_settings = {job[0]: job[1] for job in jobs}  # (the settings shared by a method's seeds are the same)
    try:  # refuse before running anything if a finished run of other settings is in the way
        todo = [job for job in jobs if not finished(pathlib.Path(job[-1]), job[1])]
    except ValueError as error:
        raise SystemExit(f"baselines.py: {error}") from None
    print(f"{len(jobs) - len(todo)} of {len(jobs)} runs already done", flush=True)
    began = time.perf_counter()
    if args.jobs <= 1:
        for job in todo:
            print(f"done {run_one(*job)} ({time.perf_counter() - began:.0f} s)", flush=True)
    else:
        with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            for future in as_completed([pool.submit(run_one, *job) for job in todo]):
                print(f"done {future.result()} ({time.perf_counter() - began:.0f} s)", flush=True)
    result = benchmark | {"machine": platform.machine(), "cpus": os.cpu_count(), "jobs": args.jobs}
    worst_reward = result["worst_reward"] = float(gym.make(spec.env_id).unwrapped.worst_reward)
    for method in args.methods:
        runs = [work / method / f"seed{seed}" for seed in args.seeds]
        try:
            finals = [final_evaluation(run, method, spec.name, generator) for run in runs]
        except ValueError as error:
            raise SystemExit(f"baselines.py: {error}") from None
        result["methods"][method] = method_result(runs, spec.horizon, finals, worst_reward)
        if method == "genrl":  # what GenRL ran with (e.g. hindsight), as each run's settings record it
            result["methods"][method] |= {key: jobs_settings[method][key] for key in ("genrl_kwargs", "genrl")}
    if previous is not None:
        result = merge_results(previous, result)
    result["core_hours_3000_episodes_3_seeds"] = core_hours(result, 3000, 3)
    write_outputs(result, out)
    print(out.with_suffix(".md").read_text())
    print(f"estimated single-core hours for 3 seeds x 3000 episodes: {result['core_hours_3000_episodes_3_seeds']:.1f}")


if __name__ == "__main__":
    main()
