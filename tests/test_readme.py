"""The README: its test command is CI's, it stays short, and its example runs exactly as printed."""

import os
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _code_blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.DOTALL)


def test_ci_runs_exactly_the_readmes_test_command():
    commands = [line for block in _code_blocks("bash") for line in block.splitlines() if line.startswith("python3.11")]
    assert len(commands) == 2, commands
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert commands[1] in ci
    assert "ruff format --check ." in commands[1] and "ruff check ." in commands[1]


def test_the_getting_started_page_gives_the_readmes_two_commands():
    readme = [line for line in README.splitlines() if line.startswith("python3.11")]
    page = (ROOT / "docs" / "guide" / "getting_started.md").read_text(encoding="utf-8")
    assert [line for line in page.splitlines() if line.startswith("python3.11")] == readme


def test_readme_is_at_most_1200_words():
    assert len(README.split()) <= 1200


@pytest.mark.slow
def test_readme_example_runs_as_printed(tmp_path):
    example = _code_blocks("python")[0]
    assert "GenRL.load" in example  # the first Python block is the example
    environment = os.environ | {"MUJOCO_GL": "egl", "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", example], cwd=tmp_path, capture_output=True, text=True, env=environment)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "hockey_genrl.zip").is_file() and (tmp_path / "vae.pt").is_file()
    assert "total_timesteps     | 640" in done.stdout
