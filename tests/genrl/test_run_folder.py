"""genrl train-policy's run folder (sb3_genrl/run_folder.py, sb3_genrl/utils.py's lock): a rerun returns the finished
run, restarts or resumes the unfinished one, refuses another run, and never mixes two runs; one run at a time."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import LinearGenerator
from test_train_policy import fast_reach_task  # noqa: F401 (the fixture)

from sb3_genrl import GenRL
from sb3_genrl.curves import MONITOR_FILE, read_monitor
from sb3_genrl.run import train_policy
from sb3_genrl.run.folder import RunFolderError


class _Killed(Exception):
    """Stands for a kill partway through training."""


def _killed_at_update(monkeypatch: pytest.MonkeyPatch, update: int) -> None:
    train = GenRL.train

    def killed(model: GenRL) -> None:
        if model._n_updates == update:
            raise _Killed
        train(model)

    monkeypatch.setattr(GenRL, "train", killed)


def test_a_rerun_into_a_run_folder_never_mixes_two_runs(fast_reach_task, tmp_path, monkeypatch):  # noqa: F811
    run = {"seed": 0, "out_dir": tmp_path, "batch_episodes": 32}
    first = train_policy("fast-reach", LinearGenerator(), episodes=64, **run)
    monitor = tmp_path / MONITOR_FILE
    written = monitor.stat().st_mtime_ns
    # The same run again: finished, so nothing is done and its summary is returned.
    assert train_policy("fast-reach", LinearGenerator(), episodes=64, **run) == first
    assert monitor.stat().st_mtime_ns == written
    # Another run (another budget) is refused, naming what differs, and changes nothing.
    with pytest.raises(RunFolderError, match=r"holds another run \(it differs in episodes\).*--overwrite"):
        train_policy("fast-reach", LinearGenerator(), episodes=96, **run)
    assert monitor.stat().st_mtime_ns == written and (tmp_path / "summary.json").is_file()
    # Replacing it (overwrite), killed partway: the old run's summary, model and curve are gone with it.
    _killed_at_update(monkeypatch, 1)
    with pytest.raises(_Killed):
        train_policy("fast-reach", LinearGenerator(), episodes=96, overwrite=True, **run)
    for name in ("summary.json", "genrl_policy.zip", "learning_curve.csv", "learning_curve.png"):
        assert not (tmp_path / name).exists(), name
    assert len(read_monitor(monitor)["return"]) == 64  # only the new run's episodes (2 iterations played)
    assert len(list((tmp_path / "logs").glob("events.out.tfevents.*"))) == 1
    monkeypatch.undo()
    # The same command again: the unfinished run (no checkpoint) starts again from its first episode.
    second = train_policy("fast-reach", LinearGenerator(), episodes=96, **run)
    assert second["episodes"] == 96 == len(read_monitor(monitor)["return"])
    assert len(list((tmp_path / "logs").glob("events.out.tfevents.*"))) == 1
    assert json.loads((tmp_path / "summary.json").read_text()) == second
    # A folder with a run's files but no record of what run made them (an older version's) is refused too.
    (tmp_path / "run_record.json").unlink()
    with pytest.raises(
        RunFolderError, match=r"no run_record.json .*: choose another output folder \(--out\), or pass --overwrite"
    ):
        train_policy("fast-reach", LinearGenerator(), episodes=96, **run)


def test_overwrite_removes_the_runs_own_logs_and_nothing_else_there(fast_reach_task, tmp_path):  # noqa: F811
    run = {"seed": 0, "out_dir": tmp_path, "batch_episodes": 32}
    train_policy("fast-reach", LinearGenerator(), episodes=32, **run)
    mine = [tmp_path / "logs" / "mine" / "keep.txt", tmp_path / "logs" / "note.txt"]  # a user's files beside the run's
    for path in mine:
        path.parent.mkdir(exist_ok=True)
        path.write_text("x")
    train_policy("fast-reach", LinearGenerator(), episodes=64, overwrite=True, **run)
    assert all(path.read_text() == "x" for path in mine)
    assert len(list((tmp_path / "logs").glob("events.out.tfevents.*"))) == 1
    assert len(read_monitor(tmp_path / MONITOR_FILE)["return"]) == 64
    # A folder holding only another tool's logs (rl-zoo3's logs/ALGO/ENV_1/) is no run: the run goes beside them.
    other = tmp_path / "zoo"
    model = other / "logs" / "genrl" / "run_1" / "model.zip"
    model.parent.mkdir(parents=True)
    model.write_bytes(b"zip")
    train_policy("fast-reach", LinearGenerator(), episodes=32, **{**run, "out_dir": other})
    assert model.read_bytes() == b"zip" and (other / "summary.json").is_file()


def test_a_second_run_into_a_locked_folder_stops_at_once_with_exit_2(hockey_generator, tmp_path, cli):
    folder = tmp_path / "run"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent("""
        import sys
        from sb3_genrl.utils import folder_lock
        with folder_lock(sys.argv[1]):
            print("locked", flush=True)
            sys.stdin.read()  # holds the lock until the test kills it
    """),
            str(folder),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        code, _, err = cli(
            "train-policy",
            "--task",
            "hockey",
            "--generator",
            hockey_generator,
            "--episodes",
            4,
            "--batch-episodes",
            2,
            "--out",
            folder,
        )
        assert code == 2 and f"{folder} is in use by another process (PID {holder.pid}" in err
        code, _, err = cli(
            "baseline", "latent-trpo", "--task", "hockey", "--generator", hockey_generator, "--episodes", 4, "--out", folder
        )
        assert code == 2 and f"{folder} is in use by another process (PID {holder.pid}" in err
        assert sorted(path.name for path in folder.iterdir()) == [".lock"]  # nothing written
    finally:
        holder.kill()
        holder.wait()
    assert np.isfinite(
        train_policy("hockey", hockey_generator, episodes=4, batch_episodes=2, out_dir=folder)["final_mean_reward"]
    )


def test_a_run_inside_its_demonstrations_folder_is_refused(fast_reach_task, tmp_path):  # noqa: F811
    demonstrations = tmp_path / "demos"
    demonstrations.mkdir()
    (demonstrations / "metadata.json").write_text("{}")
    for out in (demonstrations, demonstrations / "run"):
        with pytest.raises(ValueError, match=r"out_dir .* is (inside )?the dataset .*would join the demonstrations' own"):
            train_policy("fast-reach", LinearGenerator(), episodes=32, seed=0, out_dir=out, demonstrations=demonstrations)
    assert sorted(path.name for path in demonstrations.iterdir()) == ["metadata.json"]
