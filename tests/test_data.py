"""Demonstration datasets on disk (sb3_genrl.data): round trip, metadata, bad paths, foreign tasks."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces

from sb3_genrl.data import dataset_info, load_actions, load_arrays, load_reached, load_transitions, write_dataset

N, T, M, D = 5, 6, 7, 16


def _arrays(seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    terminations = np.zeros((N, T), dtype=bool)
    terminations[:, -1] = True
    rewards = np.zeros((N, T))
    rewards[:, -1] = -rng.uniform(size=N)
    return {
        "observations": rng.normal(size=(N, T + 1, D)).astype(np.float32),
        "actions": rng.uniform(-0.4, 0.4, size=(N, T, M)).astype(np.float32),
        "rewards": rewards,
        "terminations": terminations,
        "truncations": np.zeros((N, T), dtype=bool),
        "reached": rng.normal(size=(N, 2)),
        "sampled_goals": rng.normal(size=(N, 2)),
    }


def _write(path: Path, arrays: dict[str, np.ndarray], task: str = "hockey") -> Path:
    return write_dataset(
        path,
        arrays,
        dataset_id=f"genrl/{task}-v0",
        observation_space=spaces.Box(-np.inf, np.inf, (D,), np.float32),
        action_space=spaces.Box(-0.5, 0.5, (M,), np.float32),
        genrl={"task": task, "horizon": T, "seed": 3, "version": "0.test"},
    )


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, np.ndarray]]:
    arrays = _arrays()
    return _write(tmp_path_factory.mktemp("data") / "hockey", arrays), arrays


def test_round_trip(dataset: tuple[Path, dict[str, np.ndarray]]) -> None:
    path, arrays = dataset
    actions = load_actions(path, task="hockey", horizon=T)
    assert actions.dtype == np.float32 and actions.shape == (N, T, M)
    np.testing.assert_array_equal(actions, arrays["actions"])
    np.testing.assert_array_equal(load_reached(path), arrays["reached"])
    loaded = load_arrays(path)
    for key, value in arrays.items():
        np.testing.assert_array_equal(loaded[key], value)


def test_transitions(dataset: tuple[Path, dict[str, np.ndarray]]) -> None:
    path, arrays = dataset
    transitions = load_transitions(path, task="hockey")
    assert transitions["observations"].shape == (N * T, D) and transitions["actions"].shape == (N * T, M)
    # Independent computation: episode i, step t is row i * T + t.
    for i in range(N):
        for t in range(T):
            row = i * T + t
            np.testing.assert_array_equal(transitions["observations"][row], arrays["observations"][i, t])
            np.testing.assert_array_equal(transitions["next_observations"][row], arrays["observations"][i, t + 1])
            np.testing.assert_array_equal(transitions["actions"][row], arrays["actions"][i, t])
            assert transitions["rewards"][row] == np.float32(arrays["rewards"][i, t])
            assert transitions["dones"][row] == (t == T - 1)


def test_transitions_leave_out_the_padding_after_an_episode_that_ended_early(tmp_path: Path) -> None:
    arrays = _arrays(1)
    ends = [T, 2, 4, 1, T]  # the steps each episode played before its end flag (a Meta-World success, say)
    arrays["terminations"][:] = False
    for i, played in enumerate(ends):
        arrays["terminations"][i, played - 1] = True
    transitions = load_transitions(_write(tmp_path / "early", arrays))
    assert len(transitions["actions"]) == sum(ends)
    rows = [(i, t) for i, played in enumerate(ends) for t in range(played)]  # the played steps, in order
    for key, source, offset in (("observations", "observations", 0), ("next_observations", "observations", 1)):
        np.testing.assert_array_equal(transitions[key], np.stack([arrays[source][i, t + offset] for i, t in rows]))
    np.testing.assert_array_equal(transitions["actions"], np.stack([arrays["actions"][i, t] for i, t in rows]))
    np.testing.assert_array_equal(transitions["dones"], [t == ends[i] - 1 for i, t in rows])


def test_info_and_metadata(dataset: tuple[Path, dict[str, np.ndarray]]) -> None:
    path, _ = dataset
    info = dataset_info(path)
    assert (info["task"], info["horizon"], info["episodes"], info["seed"], info["version"]) == ("hockey", T, N, 3, "0.test")
    assert info["dataset_id"] == "genrl/hockey-v0"
    metadata = json.loads((path / "data" / "metadata.json").read_text())
    assert metadata["total_episodes"] == N and metadata["total_steps"] == N * T
    assert dataset_info(path / "data")["task"] == "hockey"  # the data folder itself works too


def test_wrong_task_or_horizon(dataset: tuple[Path, dict[str, np.ndarray]]) -> None:
    path, _ = dataset
    with pytest.raises(ValueError, match="task 'hockey', not 'basketball'"):
        load_actions(path, task="basketball")
    with pytest.raises(ValueError, match="horizon 6, expected 69"):
        load_actions(path, horizon=69)
    with pytest.raises(ValueError, match="not 'basketball'"):
        load_transitions(path, task="basketball")


def test_not_a_dataset(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="does not exist"):
        load_actions(tmp_path / "missing")
    (tmp_path / "file.npy").write_bytes(b"not a dataset")
    with pytest.raises(ValueError, match="got a file"):
        load_actions(tmp_path / "file.npy")
    with pytest.raises(ValueError, match="not a Minari dataset directory"):
        dataset_info(tmp_path)
    foreign = tmp_path / "foreign" / "data"
    foreign.mkdir(parents=True)
    (foreign / "metadata.json").write_text(json.dumps({"dataset_id": "other/thing-v0", "total_episodes": 1}))
    with pytest.raises(ValueError, match="no 'genrl' entry"):
        load_actions(tmp_path / "foreign")
    (foreign / "metadata.json").write_text("{broken")
    with pytest.raises(ValueError, match="cannot read the dataset metadata"):
        load_actions(tmp_path / "foreign")


def test_write_refuses_existing_and_leaves_nothing_half_written(tmp_path: Path) -> None:
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "x").write_text("x")
    with pytest.raises(ValueError, match="already exists"):
        _write(tmp_path / "taken", _arrays())
    broken = _arrays()
    del broken["reached"]
    with pytest.raises(ValueError, match="missing"):
        _write(tmp_path / "new", broken)
    with pytest.raises(ValueError, match="Malformed dataset ID"):
        write_dataset(
            tmp_path / "bad-id",
            _arrays(),
            dataset_id="not an id",
            observation_space=spaces.Box(0, 1, (D,)),
            action_space=spaces.Box(0, 1, (M,)),
            genrl={"task": "hockey", "horizon": T},
        )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def test_relative_output_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    arrays = _arrays()
    path = _write(Path("runs") / "demos", arrays)
    assert path.is_absolute() and path == tmp_path / "runs" / "demos"
    np.testing.assert_array_equal(load_actions(Path("runs") / "demos"), arrays["actions"])


def test_minari_reads_it(dataset: tuple[Path, dict[str, np.ndarray]]) -> None:
    pytest.importorskip("h5py")
    import minari

    path, arrays = dataset
    episodes = list(minari.MinariDataset(path / "data").iterate_episodes())
    assert len(episodes) == N
    np.testing.assert_array_equal(episodes[1].actions, arrays["actions"][1])
    np.testing.assert_array_equal(episodes[1].observations, arrays["observations"][1])


def test_core_does_not_import_the_tasks() -> None:
    import sb3_genrl.data

    for source in Path(sb3_genrl.data.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(source.read_text())):
            names = (
                [alias.name for alias in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            assert not any(name.startswith(("sb3_genrl.envs", "sb3_genrl.baselines")) for name in names), source


def _copy(dataset: tuple[Path, dict[str, np.ndarray]], tmp_path: Path) -> Path:
    import shutil

    return Path(shutil.copytree(dataset[0], tmp_path / "copy"))


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def test_truncated_or_overwritten_npz_gives_an_error_naming_it(dataset, tmp_path: Path) -> None:
    copy = _copy(dataset, tmp_path)
    npz = copy / "data" / "genrl_episodes.npz"
    _truncate(npz)
    for loader in (load_actions, load_transitions):
        with pytest.raises(ValueError, match="damaged") as error:
            loader(copy)
        assert str(npz) in str(error.value)
    data = bytearray((dataset[0] / "data" / "genrl_episodes.npz").read_bytes())
    start = bytes(data).find(dataset[1]["actions"].tobytes()[:64])
    data[start : start + 64] = bytes(64)  # 64 bytes overwritten inside the actions array: its CRC-32 no longer matches
    npz.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="damaged") as error:
        load_actions(copy)
    assert str(npz) in str(error.value)


def test_corrupted_hdf5_gives_an_error_naming_it(dataset, tmp_path: Path) -> None:
    pytest.importorskip("h5py")
    copy = _copy(dataset, tmp_path)
    hdf5 = copy / "data" / "main_data.hdf5"
    _truncate(hdf5)  # next to an intact npz: refused, not silently ignored
    with pytest.raises(ValueError, match="damaged") as error:
        load_actions(copy)
    assert str(hdf5) in str(error.value)
    hdf5.unlink()  # a file the dataset lists gone: said so, not called damaged
    with pytest.raises(ValueError, match="is missing: the dataset is incomplete") as error:
        load_actions(copy)
    assert str(hdf5) in str(error.value)
    (copy / "data" / "genrl_episodes.npz").unlink()  # only Minari's storage left, and it is damaged
    hdf5.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(4096))
    with pytest.raises(ValueError, match="damaged") as error:
        load_transitions(copy)
    assert str(hdf5) in str(error.value)


def test_non_finite_demonstrations_are_refused_by_every_loader(tmp_path: Path) -> None:
    for key in ("actions", "observations", "rewards"):
        arrays = _arrays()
        arrays[key][1, 2, ...] = np.nan
        path = _write(tmp_path / key, arrays)
        for loader in (load_transitions, load_actions) if key == "actions" else (load_transitions,):
            with pytest.raises(ValueError, match=f"{key} hold .* non-finite") as error:
                loader(path)
            assert str(path) in str(error.value)


def test_one_trajectory_loader_for_arrays_files_and_datasets(dataset, tmp_path) -> None:
    from sb3_genrl.data import load_trajectories

    path, arrays = dataset
    actions = arrays["actions"]
    np.testing.assert_array_equal(load_trajectories(path), actions)  # a dataset: its actions
    np.testing.assert_array_equal(load_trajectories(actions), actions)
    np.save(tmp_path / "a.npy", actions)
    np.testing.assert_array_equal(load_trajectories(tmp_path / "a.npy"), actions)
    np.savez(tmp_path / "one.npz", anything=actions)
    np.savez(tmp_path / "named.npz", trajectories=actions, goals=arrays["reached"])
    for name in ("one.npz", "named.npz"):
        np.testing.assert_array_equal(load_trajectories(str(tmp_path / name)), actions)
    np.savez(tmp_path / "two.npz", a=actions, b=actions)
    with pytest.raises(ValueError, match=r"holds arrays \['a', 'b'\]"):
        load_trajectories(tmp_path / "two.npz")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_trajectories(tmp_path / "missing.npy")
    with pytest.raises(ValueError, match="neither a demonstration dataset directory nor a .npy/.npz file"):
        load_trajectories(Path(__file__))
    with pytest.raises(ValueError, match=r"shape \(N, T, M\)"):
        load_trajectories(actions[0])
    np.save(tmp_path / "complex.npy", actions.astype(np.complex64))
    with pytest.raises(ValueError, match="trajectories must hold real numbers, got dtype complex64"):
        load_trajectories(tmp_path / "complex.npy")
    np.save(tmp_path / "objects.npy", np.empty((2, 3, 1), dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match=r"'.*objects.npy' cannot be read as an array of trajectories: Object arrays"):
        load_trajectories(tmp_path / "objects.npy")
    # The generators' training and their evaluation read data through this one loader.
    import sb3_genrl.generative.training
    import sb3_genrl.metrics.evaluate

    assert sb3_genrl.generative.training.load_trajectories is load_trajectories
    assert sb3_genrl.metrics.evaluate.load_trajectories is load_trajectories
