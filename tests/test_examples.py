"""The examples run as a user runs them (small sizes) and print what they promise."""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"


def run_example(name: str, *args: str, cwd: pathlib.Path) -> str:
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"), OMP_NUM_THREADS="1")
    completed = subprocess.run([sys.executable, str(EXAMPLES / name), *args], cwd=cwd, env=env, capture_output=True,
                               text=True, timeout=600)
    assert completed.returncode == 0, completed.stderr[-3000:]
    return completed.stdout


def test_quickstart_example_runs_the_whole_workflow(tmp_path):
    out = tmp_path / "hockey"
    stdout = run_example("quickstart.py", "--out", str(out), "--demos", "80", "--epochs", "2", "--episodes", "64",
                         cwd=tmp_path)
    for path in ("demonstrations", "vae.pt", "policy/genrl_policy.zip", "policy/learning_curve.png",
                 "policy/learning_curve.csv"):
        assert (out / path).exists(), path
    match = re.search(r"mean final distance to 100 new goals: ([0-9.]+) cm", stdout)
    assert match is not None, stdout
    assert 0.0 < float(match.group(1)) < 300.0  # a physical distance on the table, in cm


def test_custom_env_example_improves_its_policy(tmp_path):
    stdout = run_example("custom_env.py", cwd=tmp_path)
    before = float(re.search(r"before training: mean reward (-?[0-9.]+)", stdout).group(1))
    after = float(re.search(r"after \d+ episodes: mean reward (-?[0-9.]+)", stdout).group(1))
    assert after > before, stdout
