"""Checkpoints (sb3_genrl/run/checkpoint.py): a stopped train-policy run resumed with the same command ends as the run
that was not stopped, bit for bit; GenRL's and the off-policy baselines' checkpoints are one mechanism."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import LinearGenerator
from genrl_test_helpers import SuccessReachEnv
from sb3_genrl.baselines.checkpoint import ReplayBufferCheckpoint
from sb3_genrl.baselines.train import train_baseline
from test_baselines import demo_transitions
from test_train_policy import fast_reach_task  # noqa: F401 (the fixture)

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.curves import MONITOR_FILE, read_monitor
from sb3_genrl.run import train_policy
from sb3_genrl.run.checkpoint import EpisodeCheckpoint, GenRLCheckpoint
from sb3_genrl.run.folder import RunFolderError


class _Killed(Exception):
    """Stands for a kill partway through training."""


@pytest.fixture
def hindsight_task(fast_reach_task):  # noqa: F811
    """The registered toy task, its pulls relabelled with the point they reached, with their success."""
    import gymnasium as gym

    gym.registry[fast_reach_task.env_id].entry_point = SuccessReachEnv
    yield fast_reach_task


def _parameters(path) -> dict[str, np.ndarray]:
    model = GenRL.load(path, generator=LinearGenerator())
    tensors = {f"policy.{key}": value for key, value in model.policy.state_dict().items()}
    tensors |= {f"average.{key}": value for key, value in model.policy_average.state_dict().items()}
    tensors |= {f"hindsight_adam.{key}": value for key, value in model.hindsight.optimizer.state_dict()["state"][0].items()}
    return {key: value.cpu().numpy() for key, value in tensors.items()}


@pytest.mark.parametrize(("n_envs", "pulls_per_context"), [(1, 1), (2, 1), (2, 2)])
def test_a_stopped_run_resumed_with_the_same_command_ends_as_the_run_not_stopped(
    hindsight_task, tmp_path, monkeypatch, n_envs, pulls_per_context
):
    settings = {
        "episodes": 192,
        "seed": 3,
        "batch_episodes": 32,
        "n_envs": n_envs,
        "pulls_per_context": pulls_per_context,
        "value_history": 2,
        "policy_averaging": 0.9,
        "hindsight_kwargs": {"history": 2, "regression_steps": 4, "refit_every": 64, "refit_start": 32, "refit_steps": 20},
        "checkpoint_every": 64,
    }
    whole = train_policy("fast-reach", LinearGenerator(), out_dir=tmp_path / "whole", **settings)

    learn = GenRL.train
    monkeypatch.setattr(
        GenRL, "train", lambda model: learn(model) if model._n_updates < 3 else (_ for _ in ()).throw(_Killed())
    )  # killed in the fourth update: the last checkpoint is at 64 episodes (two updates)
    with pytest.raises(_Killed):
        train_policy("fast-reach", LinearGenerator(), out_dir=tmp_path / "stopped", **settings)
    state = json.loads((tmp_path / "stopped" / "checkpoint" / "state.json").read_text())
    assert state["episodes"] == 64 and sorted(state["files"]) == ["memories", "model"]
    assert len(read_monitor(tmp_path / "stopped" / MONITOR_FILE)["return"]) == 128  # four batches played
    monkeypatch.undo()
    resumed = train_policy("fast-reach", LinearGenerator(), out_dir=tmp_path / "stopped", **settings)

    assert resumed["resumed_at_episodes"] == [64] and not (tmp_path / "stopped" / "checkpoint").exists()
    assert {
        key: value for key, value in resumed.items() if "path" not in key and key != "log_dir" and key != "resumed_at_episodes"
    } == {key: value for key, value in whole.items() if "path" not in key and key != "log_dir"}
    # The same episodes (the Monitor's rewards and goals) and the same parameters, bit for bit.
    rows = [read_monitor(tmp_path / name / MONITOR_FILE) for name in ("whole", "stopped")]
    assert len(rows[1]["return"]) == 192
    np.testing.assert_array_equal(rows[1]["return"], rows[0]["return"])
    np.testing.assert_array_equal(rows[1]["distance"], rows[0]["distance"])
    expected, got = (_parameters(tmp_path / name / "genrl_policy.zip") for name in ("whole", "stopped"))
    assert got.keys() == expected.keys()
    for key in expected:
        np.testing.assert_array_equal(got[key], expected[key], err_msg=key)
    # The training log: the rows up to the checkpoint (the first update's: SB3 writes an update's values with the next
    # batch's) and the resumed run's, from the second update on, are those of the run not stopped.
    logs = tmp_path / "stopped" / "logs"
    whole_log, early, late = (
        _progress(path)
        for path in (
            tmp_path / "whole" / "logs" / "progress.csv",
            logs / "progress.until_episode_64.csv",
            logs / "progress.csv",
        )
    )
    for key in ("train/mean_reward", "train/kl"):
        assert len(whole_log[key]) == 6 and early[key][:1] + late[key] == whole_log[key]


def _progress(path) -> dict[str, list[str]]:
    import csv

    with open(path) as file:
        rows = [row for row in csv.DictReader(file) if row.get("train/kl")]
    return {key: [row[key] for row in rows] for key in ("train/mean_reward", "train/kl")}


def test_a_truncated_memories_file_is_refused_naming_it_and_the_checkpoint_is_kept(fast_reach_task, tmp_path, monkeypatch):  # noqa: F811
    settings = {"episodes": 128, "seed": 3, "batch_episodes": 32, "checkpoint_every": 32}
    learn = GenRL.train
    monkeypatch.setattr(
        GenRL, "train", lambda model: learn(model) if model._n_updates < 2 else (_ for _ in ()).throw(_Killed())
    )
    with pytest.raises(_Killed):
        train_policy("fast-reach", LinearGenerator(), out_dir=tmp_path, **settings)
    monkeypatch.undo()
    folder = tmp_path / "checkpoint"
    state = json.loads((folder / "state.json").read_text())
    memories = folder / state["files"]["memories"]
    memories.write_bytes(memories.read_bytes()[:-10])  # cut short, as by a copy that stopped
    with pytest.raises(ValueError, match="is truncated or corrupt") as error:
        train_policy("fast-reach", LinearGenerator(), out_dir=tmp_path, **settings)
    assert str(memories) in str(error.value) and f"delete {folder}" in str(error.value)
    # A checkpoint of an earlier version (no recorded sizes) is refused with the same words when torch cannot read it.
    (folder / "state.json").write_text(json.dumps({key: value for key, value in state.items() if key != "sizes"}))
    with pytest.raises(ValueError, match="is truncated or corrupt") as error:
        train_policy("fast-reach", LinearGenerator(), out_dir=tmp_path, **settings)
    assert str(memories) in str(error.value) and f"delete {folder}" in str(error.value)
    assert sorted(path.name for path in folder.iterdir()) == sorted(["state.json", *state["files"].values()])  # kept


def test_a_genrl_run_and_a_sac_run_stop_and_resume_through_one_checkpoint_mechanism(fast_reach_task, tmp_path, monkeypatch):  # noqa: F811
    genrl_run = {"episodes": 96, "seed": 3, "batch_episodes": 32, "checkpoint_every": 32, "out_dir": tmp_path / "genrl"}
    sac_run = {
        "episodes": 3,
        "demos": demo_transitions(2),
        "checkpoint_every": 1,
        "device": "cpu",
        "seed": 1,
        "window": 3,
        "eval_goals": 2,
        "out_dir": tmp_path / "sac",
    }
    saved = []
    save = EpisodeCheckpoint.save

    def save_and_stop(callback, episodes):  # the shared base's save: both runs stop right after their first checkpoint
        save(callback, episodes)
        saved.append((type(callback), episodes))
        raise _Killed

    monkeypatch.setattr(EpisodeCheckpoint, "save", save_and_stop)
    with pytest.raises(_Killed):
        train_policy("fast-reach", LinearGenerator(), **genrl_run)
    with pytest.raises(_Killed):
        train_baseline("sac", "hockey", **sac_run)
    monkeypatch.undo()
    assert saved == [(GenRLCheckpoint, 32), (ReplayBufferCheckpoint, 1)]
    assert issubclass(GenRLCheckpoint, EpisodeCheckpoint) and issubclass(ReplayBufferCheckpoint, EpisodeCheckpoint)

    kept = {name: tmp_path / "kept" / name for name in ("genrl", "sac")}
    for name, folder in kept.items():
        shutil.move(tmp_path / name / "checkpoint", folder)

    # One kind's checkpoint in the other kind's run folder is refused on resume, naming what differs, and left whole.
    shutil.copytree(kept["sac"], genrl_run["out_dir"] / "checkpoint")
    closed = []
    close = LatentActionWrapper.close
    monkeypatch.setattr(LatentActionWrapper, "close", lambda env: closed.append(env) or close(env))
    with pytest.raises(RunFolderError, match=r"holds a checkpoint of another run \(it differs in algorithm, "):
        train_policy("fast-reach", LinearGenerator(), **genrl_run)
    monkeypatch.undo()
    assert len(closed) == 1  # the env the refused run had made
    shutil.copytree(kept["genrl"], sac_run["out_dir"] / "checkpoint")
    with pytest.raises(RunFolderError, match=r"holds a checkpoint of another run \(it differs in algorithm, "):
        train_baseline("sac", "hockey", **sac_run)
    for name, other in (("genrl", "sac"), ("sac", "genrl")):
        assert sorted(path.name for path in (tmp_path / name / "checkpoint").iterdir()) == sorted(
            path.name for path in kept[other].iterdir()
        )

    # Each run's own checkpoint back in place: both resume from it and meet their budgets.
    for name, folder in kept.items():
        shutil.rmtree(tmp_path / name / "checkpoint")
        shutil.copytree(folder, tmp_path / name / "checkpoint")
    genrl = train_policy("fast-reach", LinearGenerator(), **genrl_run)
    sac = train_baseline("sac", "hockey", **sac_run)
    assert genrl["resumed_at_episodes"] == [32] and genrl["episodes"] == 96
    assert sac["resumed_at_episodes"] == [1] and sac["episodes_played"] == 3
