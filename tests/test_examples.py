"""The examples run as a user runs them (small sizes) and print what they promise."""

from __future__ import annotations

import json
import os
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import HANG_S, policy_distances

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"


def run_example(name: str, *args: str, cwd: pathlib.Path) -> str:
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"), OMP_NUM_THREADS="1")
    completed = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=HANG_S
    )
    assert completed.returncode == 0, completed.stderr[-3000:]
    return completed.stdout


def test_quickstart_example_runs_the_whole_workflow(tmp_path):
    out = tmp_path / "hockey"
    stdout = run_example(
        "quickstart.py", "--out", str(out), "--demo-episodes", "80", "--epochs", "2", "--episodes", "64", cwd=tmp_path
    )
    for path in (
        "demonstrations",
        "vae.pt",
        "policy/genrl_policy.zip",
        "policy/learning_curve.png",
        "policy/learning_curve.csv",
    ):
        assert (out / path).exists(), path
    summary = json.loads((out / "policy" / "summary.json").read_text())  # hockey's own settings, as the quickstart's
    from sb3_genrl.hyperparams import load_genrl_settings

    _, batch_episodes, entry = load_genrl_settings("GenRL/Hockey-v0")  # hyperparams/genrl.yml's entry
    assert summary["iterations"] == 64 // batch_episodes == 64 // 32 and summary["genrl_settings"]["hindsight_kwargs"]
    entry.pop("policy")  # (the records name the policy only when it is not the default MlpPolicy)
    # every one of the entry's settings, its network included
    assert {name: summary["genrl_settings"][name] for name in entry} == entry
    match = re.search(r"mean final distance to 100 new goals: ([0-9.]+) cm \(median ([0-9.]+) cm", stdout)
    assert match is not None, stdout
    # What the example prints is the saved policy's distance to the 100 goals of seed 0 + 1, replayed here.
    distances = 100 * policy_distances(out / "policy" / "genrl_policy.zip", "GenRL/Hockey-v0", 100, 1)
    assert float(match.group(1)) == pytest.approx(distances.mean(), abs=0.051)
    assert float(match.group(2)) == pytest.approx(np.median(distances), abs=0.051)


def test_custom_env_example_improves_its_policy(tmp_path):
    stdout = run_example("custom_env.py", cwd=tmp_path)
    before = float(re.search(r"before training: mean reward (-?[0-9.]+)", stdout).group(1))
    after = float(re.search(r"after \d+ episodes: mean reward (-?[0-9.]+)", stdout).group(1))
    assert after > before, stdout


def test_your_task_example_goes_from_an_expert_to_a_saved_policy(tmp_path):
    from sb3_genrl.data import dataset_info

    stdout = run_example("your_task.py", "--out", "out", "--demos", "40", "--epochs", "2", "--episodes", "128", cwd=tmp_path)
    info = dataset_info(tmp_path / "out" / "demonstrations")
    assert info["episodes"] == 40 and info["failed_open_loop"] == 0  # the example's env is deterministic
    assert f"demonstrations: 40 kept of {info['tried']} tried ({info['failed_closed_loop']} failed closed loop" in stdout
    assert "generator: T=20, M=2, N_alpha=2" in stdout
    assert re.search(r"success after 128 episodes: [0-9.]+ of 100 held-out resets", stdout), stdout
    assert (tmp_path / "out" / "vae.pt").is_file() and (tmp_path / "out" / "genrl_policy.zip").is_file()
