"""Interruption and reruns: recorded settings, the folder lock, workers that exit with their parent, dataset writes
that leave nothing half-made, and a Ray address that cannot hang the study."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import HANG_S
from gymnasium import spaces

from sb3_genrl.cli import main
from sb3_genrl.data import write_dataset
from sb3_genrl.data.minari_io import remove_stale_partials
from sb3_genrl.run.stages import SettingsConflictError, check_and_record, settings_conflicts
from sb3_genrl.study import run_study
from sb3_genrl.utils import FolderInUseError, folder_lock


def _alive(pid: int) -> bool:
    """Whether the process runs (a zombie, ended but not yet reaped, counts as ended)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return True


def _python(script: str, *args: str) -> subprocess.Popen:
    """A Python process running ``script``; its stdin is a pipe that stays open until the test ends it."""
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(script), *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )


def test_recorded_settings_are_compared_and_each_difference_named(tmp_path: Path) -> None:
    record = tmp_path / "stage" / "stage.json"
    wanted = {"epochs": 2, "eval_every": 1, "shape": [2, 3]}
    check_and_record(record, wanted, output_exists=False, folder=tmp_path)
    assert json.loads(record.read_text()) == wanted
    check_and_record(record, {"epochs": 2, "eval_every": 1, "shape": (2, 3)}, output_exists=True, folder=tmp_path)
    with pytest.raises(SettingsConflictError) as error:
        check_and_record(
            record, {"epochs": 150, "eval_every": 1, "shape": [2, 3], "seed": 0}, output_exists=True, folder=tmp_path
        )
    message = str(error.value)
    assert f"{tmp_path / 'stage'}: epochs 2 (recorded) vs 150 (this run), seed unset (recorded) vs 0" in message
    assert "eval_every" not in message and "--out" in message and "delete" in message
    assert json.loads(record.read_text()) == wanted  # a refused run changes nothing
    # Output without a record (an older version's) is never reused as if its settings were known.
    assert "no recorded settings" in settings_conflicts(tmp_path / "old", None, wanted)[0]
    assert settings_conflicts(tmp_path / "new", None, wanted, output_exists=False) == []


def test_lock_refuses_a_second_holder_and_is_released_when_it_dies(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "study"
    holder = _python(
        """
        import sys
        from sb3_genrl.utils import folder_lock
        with folder_lock(sys.argv[1]):
            print("locked", flush=True)
            sys.stdin.read()  # holds the lock until the test kills it
    """,
        str(folder),
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(FolderInUseError, match=f"{folder} is in use by another process \\(PID {holder.pid}"):
            run_study("hockey", "smoke", folder)
        assert main(["quickstart", "--out", str(folder), "--no-video"]) == 2
        assert f"PID {holder.pid}" in capsys.readouterr().err
        assert sorted(p.name for p in folder.iterdir()) == [".lock"]  # nothing was started
    finally:
        holder.kill()  # SIGKILL: the holder cannot clean up, the OS releases its lock
        holder.wait()
    with folder_lock(folder) as lock:
        assert lock.read_text() == f"{os.getpid()}\n"
    assert not lock.exists()


def test_workers_exit_when_the_study_process_is_killed(tmp_path: Path) -> None:
    script = tmp_path / "parent.py"  # spawned workers import the jobs' module by its file
    script.write_text(
        textwrap.dedent("""
        import os, sys, time

        def job(seconds):
            # One write of the whole line: print() makes two when Python's output is unbuffered (PYTHONUNBUFFERED),
            # and the two workers' halves could then interleave on the shared pipe.
            os.write(sys.stdout.fileno(), f"{os.getpid()}\\n".encode())
            time.sleep(seconds)

        if __name__ == "__main__":
            from sb3_genrl.study.runner import _local_map  # the study's own pool of worker processes

            seconds = float(sys.argv[1])
            for _ in _local_map(2)([(job, (seconds,)), (job, (seconds,))]):
                pass
    """)
    )
    # The jobs would run on well past the bound this test waits for their end: only their parent's death ends them.
    parent = subprocess.Popen([sys.executable, str(script), str(2 * HANG_S)], stdout=subprocess.PIPE, text=True)
    workers = []
    try:
        workers = [int(parent.stdout.readline()) for _ in range(2)]
        assert all(_alive(pid) for pid in workers)
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        deadline = time.monotonic() + HANG_S  # only against a hang: the workers end as soon as the OS tells them
        while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(pid) for pid in workers)
    finally:
        parent.kill()
        parent.wait()
        for pid in workers:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def _write_small_dataset(path: Path) -> Path:
    n, t = 3, 4
    arrays = {
        "observations": np.zeros((n, t + 1, 16), np.float32),
        "actions": np.zeros((n, t, 7), np.float32),
        "rewards": np.zeros((n, t)),
        "terminations": np.ones((n, t), bool),
        "truncations": np.zeros((n, t), bool),
        "reached": np.zeros((n, 2)),
        "sampled_goals": np.zeros((n, 2)),
    }
    return write_dataset(
        path,
        arrays,
        dataset_id="genrl/hockey-v0",
        genrl={"task": "hockey", "horizon": t},
        observation_space=spaces.Box(-np.inf, np.inf, (16,), np.float32),
        action_space=spaces.Box(-0.5, 0.5, (7,), np.float32),
    )


def test_stale_partial_folders_of_dead_writers_are_removed_and_only_those(tmp_path: Path) -> None:
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    stale = tmp_path / f".demos.partial-{ended.pid}-0a1b2c3d"
    running = tmp_path / f".demos.partial-{os.getpid()}-4e5f6a7b"  # a writer that is still running
    other = tmp_path / f".other.partial-{ended.pid}-8c9d0e1f"  # another dataset's
    for folder in (stale, running, other):
        (folder / "data").mkdir(parents=True)
    _write_small_dataset(tmp_path / "demos")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([running.name, other.name, "demos"])
    assert remove_stale_partials(tmp_path / "other") == [other]


def test_a_dataset_is_never_visible_without_its_coverage_report(tmp_path: Path, monkeypatch) -> None:
    from sb3_genrl.envs.demonstrations import make_demonstrations

    renames = []
    replace = os.replace

    def watched_replace(src, dst):
        if Path(src).name.startswith(".demos.partial-"):
            renames.append(sorted(p.name for p in Path(src).iterdir()))
            raise KeyboardInterrupt  # a kill just before the dataset appears
        replace(src, dst)

    monkeypatch.setattr(os, "replace", watched_replace)
    with pytest.raises(KeyboardInterrupt):
        make_demonstrations("hockey", 2, tmp_path / "demos", seed=1, n_threads=1, progress_bar=False)
    assert renames == [["coverage.json", "coverage.png", "data"]]  # all there before the rename
    assert list(tmp_path.iterdir()) == []  # nothing half-made is left, no lock file either
    monkeypatch.setattr(os, "replace", replace)
    path = make_demonstrations("hockey", 2, tmp_path / "demos", seed=1, n_threads=1, progress_bar=False)
    report = json.loads((path / "coverage.json").read_text())
    assert report["png"] == str(path / "coverage.png") and Path(report["png"]).is_file()


def test_demos_explains_what_is_in_the_way(tmp_path: Path, cli) -> None:
    from sb3_genrl.envs.demonstrations import make_demonstrations

    path = make_demonstrations("hockey", 2, tmp_path / "demos", seed=1, n_threads=1, progress_bar=False)
    args = ["demos", "--task", "hockey", "--episodes", "2", "--out", str(path), "--no-progress-bar"]
    code, _, err = cli(*args)
    assert code == 2 and "argument --out" in err  # refused while the arguments are read, before any work
    assert "holds a complete dataset (2 hockey demonstrations, seed 1)" in err
    for name in ("coverage.json", "coverage.png"):  # as an older version left it when killed after the rename
        (path / name).unlink()
    code, _, error = cli(*args)
    assert code == 2
    assert "without its coverage report" in error and "older sb3-genrl version" in error and str(path) in error
    with pytest.raises(ValueError, match="without its coverage report"):  # the library says the same
        make_demonstrations("hockey", 2, path, seed=1, n_threads=1, progress_bar=False)


def test_unreachable_ray_address_fails_within_the_timeout_and_names_it(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    # Two addresses in one fresh process (Ray's global state stays out of this one): a closed port, and a port
    # that accepts connections but never answers, where only the time limit on ray.init helps.
    probe = _python(
        """
        import contextlib, io, socket, sys
        from sb3_genrl.cli import main

        closed = socket.socket(); closed.bind(("127.0.0.1", 0)); port = closed.getsockname()[1]; closed.close()
        silent = socket.socket(); silent.bind(("127.0.0.1", 0)); silent.listen(8)
        for address in (f"127.0.0.1:{port}", f"127.0.0.1:{silent.getsockname()[1]}"):
            error = io.StringIO()
            with contextlib.redirect_stderr(error):
                code = main(["study", "--task", "hockey", "--scale", "smoke", "--out", sys.argv[1], "--executor",
                             "ray", "--address", address, "--ray-timeout", "4"])
            named = f"Ray cluster at {address} within 4 s" in error.getvalue()
            print(address, code, named, flush=True)
    """,
        str(tmp_path / "study"),
    )
    # Without the time limit on ray.init the silent port would hold the probe forever; with it, both addresses end.
    out, _ = probe.communicate(timeout=HANG_S)
    lines = [line.split() for line in out.splitlines() if line.startswith("127.0.0.1:")]
    assert len(lines) == 2, out
    for address, code, named in lines:
        assert (code, named) == ("2", "True"), (address, code, named)
    assert not (tmp_path / "study" / "study.json").exists()
