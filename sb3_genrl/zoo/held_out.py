"""A study's best trial against the task entry's own settings, on the held-out goals.

rl-zoo3's study (``python -m sb3_genrl.zoo train --algo genrl -optimize --storage ... --study-name ...
--optimization-log-path TRIALS``) ranks its trials on the tuning goals; its first trial is the task's entry in
``hyperparams/genrl.yml`` (:mod:`sb3_genrl.zoo.experiment`). This plays the policy that each of the two saved
(``TRIALS/trial_N/best_model.zip``, the best of its evaluations on the tuning goals) on the held-out goals
(:data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`) with the package's evaluation,
:func:`sb3_genrl.run.train.evaluate_on_goals`, and with rl-zoo3's ``enjoy --no-render`` on the same goals, and
writes both, and which is better there, to a JSON file::

    python -m sb3_genrl.zoo.held_out --env GenRL/Hockey-v0 --storage sqlite:///hockey.db --study-name genrl-hockey \\
        --trials trials --out benchmarks/results/zoo_study_hockey.json
"""

from __future__ import annotations

import argparse
import os
import pathlib
import platform
import shutil
import sys
import tempfile
from typing import Any

import numpy as np
import optuna
import yaml
from huggingface_sb3 import EnvironmentName

from sb3_genrl import GenRL
from sb3_genrl.checks import COUNT, EXISTING, JSON_OUT
from sb3_genrl.genrl.generator_files import generator_digest, generator_file
from sb3_genrl.hyperparams import EVAL_GOAL_SEED
from sb3_genrl.provenance import provenance
from sb3_genrl.run.train import evaluate_on_goals
from sb3_genrl.utils import atomic_write_json
from sb3_genrl.zoo.__main__ import main as zoo
from sb3_genrl.zoo.experiment import WRAPPER
from sb3_genrl.zoo.sampler import convert_genrl_params
from sb3_genrl.zoo.wrapper import load_generator


def compare(env_id: str, storage: str, study_name: str, trials_folder: str, goals: int = 300) -> dict[str, Any]:
    """The study's trials, and the entry's and the best trial's policies on ``goals`` held-out goals."""
    study = optuna.load_study(study_name=study_name, storage=storage)
    complete = [trial for trial in study.trials if trial.state == optuna.trial.TrialState.COMPLETE]
    entry = next((trial for trial in complete if "settings" in trial.user_attrs), None)
    if entry is None or not complete:
        raise ValueError(f"study {study_name!r} has no complete trial of the task entry's settings (its first trial)")
    best = max(complete, key=lambda trial: trial.value)
    result: dict[str, Any] = {
        **provenance(),
        "env_id": env_id,
        "study_name": study_name,
        "command": study.user_attrs.get("command"),
        "held_out_goals": goals,
        "held_out_goal_seed": EVAL_GOAL_SEED,
        "python": platform.python_version(),
        "trials": [
            {"number": trial.number, "state": trial.state.name, "tuning_mean_reward": trial.value, "params": trial.params}
            for trial in study.trials
        ],
    }
    for name, trial in (("entry", entry), ("best", best)):
        model_path = os.path.join(trials_folder, f"trial_{trial.number}", "best_model.zip")
        distances = held_out_distances(model_path, env_id, goals)
        enjoyed = -enjoy_rewards(model_path, env_id, goals)
        result[name] = {
            "trial": trial.number,
            "tuning_mean_reward": trial.value,
            "genrl_kwargs": convert_genrl_params(trial.params),
            "held_out_mean_m": float(distances.mean()),
            "held_out_median_m": float(np.median(distances)),
            "held_out_max_m": float(distances.max()),
            "enjoy_mean_m": float(enjoyed.mean()),
            "enjoy_max_difference_m": float(np.abs(enjoyed - distances).max()),
            "enjoy_goals_differing_by_over_1mm": int(np.sum(np.abs(enjoyed - distances) > 1e-3)),
        }
    result["better"] = "best" if result["best"]["held_out_mean_m"] < result["entry"]["held_out_mean_m"] else "entry"
    return result


def held_out_distances(model_path: str, env_id: str, goals: int) -> np.ndarray:
    """The final distances of a saved policy's deterministic trajectories to the held-out goals."""
    model = GenRL.load(model_path, device="cpu")
    _, rewards, _ = evaluate_on_goals(model, env_id, goals=goals, seed=EVAL_GOAL_SEED)
    return -np.asarray(rewards)


def enjoy_rewards(model_path: str, env_id: str, goals: int) -> np.ndarray:
    """The episode rewards of rl-zoo3's ``enjoy --no-render -n goals --seed EVAL_GOAL_SEED`` on a saved policy, put in
    an rl-zoo3 log folder of its own (the policy as its best model, the generator saved beside it as the env
    wrapper's)."""
    generator = generator_file(model_path)
    wrapper = {WRAPPER: {"generator": str(generator), "generator_sha256": generator_digest(load_generator(generator))}}
    with tempfile.TemporaryDirectory() as folder:
        run = pathlib.Path(folder) / "genrl" / f"{EnvironmentName(env_id)}_1"
        (run / EnvironmentName(env_id)).mkdir(parents=True)
        shutil.copy(model_path, run / "best_model.zip")
        shutil.copy(generator, run / "best_model.generator.pt")  # the copy's generator beside it, as GenRL.save puts it
        (run / EnvironmentName(env_id) / "config.yml").write_text(yaml.dump({"env_wrapper": [wrapper]}))
        (run / EnvironmentName(env_id) / "args.yml").write_text(yaml.dump({"env_kwargs": None}))
        zoo(
            [
                "enjoy",
                "--algo",
                "genrl",
                "--env",
                env_id,
                "-f",
                folder,
                "--exp-id",
                "1",
                "--load-best",
                "--no-render",
                "-n",
                str(goals),
                "--seed",
                str(EVAL_GOAL_SEED),
                "--reward-log",
                folder,
                "--device",
                "cpu",
                "--verbose",
                "0",
            ]
        )
        return np.loadtxt(pathlib.Path(folder) / "0.monitor.csv", delimiter=",", skiprows=2, ndmin=2)[:, 0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True, help="the study's env id, e.g. GenRL/Hockey-v0")
    parser.add_argument("--storage", required=True, help="the study's optuna storage (rl-zoo3's --storage)")
    parser.add_argument("--study-name", required=True, help="rl-zoo3's --study-name")
    parser.add_argument("--trials", required=True, type=EXISTING, help="rl-zoo3's --optimization-log-path")
    parser.add_argument("--goals", type=COUNT, default=300, help="held-out goals (default 300)")
    parser.add_argument("--out", required=True, type=JSON_OUT, help="the JSON file to write")
    args = parser.parse_args(argv)
    result = compare(args.env, args.storage, args.study_name, str(args.trials), args.goals)
    result["comparison_command"] = " ".join(["python -m sb3_genrl.zoo.held_out", *(argv or sys.argv[1:])])
    atomic_write_json(args.out, result)
    for name in ("entry", "best"):
        row = result[name]
        print(
            f"{name}: trial {row['trial']}, tuning mean reward {row['tuning_mean_reward']:.4f}, held-out mean "
            f"distance {row['held_out_mean_m']:.4f} m"
        )
    print(f"better on the held-out goals: {result['better']}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
