"""The benchmark scripts check their arguments and output paths before any work, as the command line does."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.mark.parametrize(("script", "argv", "message"), [
    ("genrl_hockey.py", ["--episodes", "0"], "argument --episodes: must be an integer >= 1, got 0"),
    ("genrl_basketball.py", ["--out", "FILE/result.json"], "argument --out: 'FILE/result.json' cannot be created"),
    ("baselines.py", ["--task", "golf"], "argument --task: invalid choice: 'golf'"),
    ("baselines.py", ["--work", "FILE"], "argument --work: 'FILE' is a file; expected a folder"),
    ("behaviour_cloning.py", ["--out", "result.txt"], "argument --out: 'result.txt' must end in .json"),
    ("generator_training.py", ["--device", "bogus", "--out", "out.json"],
     "argument --device: must be 'auto' or a torch device"),
    ("precision_recall.py", ["--out", "FOLDER"], "argument --out: 'FOLDER' is a folder; expected a file name"),
    ("sim_throughput.py", ["--repeats", "0"], "argument --repeats: must be an integer >= 1, got 0"),
    ("genrl_tuning.py", ["--generator", "missing.pt"], "argument --generator: 'missing.pt' does not exist"),
    ("basketball_diagnosis.py", ["--data", "FOLDER", "--generator", "FILE", "--name", "../x"], "argument --name: '../x'"),
    ("reachable.py", ["--task", "hockey", "--generator", "missing.pt", "--out", "out.json"], "missing.pt is not a file"),
])
def test_benchmarks_refuse_bad_arguments_before_any_work(tmp_path, script, argv, message):
    (tmp_path / "FILE").write_text("")
    (tmp_path / "FOLDER").mkdir()
    done = subprocess.run([sys.executable, str(BENCHMARKS / script), *argv], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert done.stderr.splitlines()[-1].startswith(f"{script}: error: ")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["FILE", "FOLDER"]  # nothing was written
