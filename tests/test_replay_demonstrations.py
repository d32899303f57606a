"""Demonstrations from a dataset of actions (sb3_genrl.envs.demonstrations.replay): each episode replayed open loop from
its seeded reset on a task the package does not ship, kept only when it still succeeds, and the share kept recorded."""

import json

import gymnasium as gym
import minari
import numpy as np
import pytest
from minari.data_collector.episode_buffer import EpisodeBuffer
from sb3_genrl.envs.demonstrations import read_replay_source, record_demonstrations, replay_demonstrations
from test_external import HORIZON, PointGoalEnv, point_expert

from sb3_genrl.data import dataset_info, load_actions, load_arrays
from sb3_genrl.generative import train_generator

TASK = "TestReplay/PointGoal-v0"
SEEDS = [11, 12, 13, 14, 15, 16, 17]
# a string entry point: Minari stores the env's spec as JSON
gym.register(TASK, entry_point="test_external:PointGoalEnv", max_episode_steps=HORIZON)


def expert_episode(reset_seed: int) -> dict[str, np.ndarray]:
    """The expert's episode from ``reset(seed=reset_seed)``, closed loop: its observations, actions and rewards."""
    env = PointGoalEnv()
    observation, _ = env.reset(seed=reset_seed)
    observations, actions, rewards = [observation], [], []
    for _ in range(HORIZON):
        action = point_expert(observation).astype(np.float32)
        observation, reward, _, _, _ = env.step(action)
        observations.append(observation)
        actions.append(action)
        rewards.append(reward)
    return {"observations": np.array(observations), "actions": np.array(actions), "rewards": np.array(rewards)}


def replayed(reset_seed: int, actions: np.ndarray) -> tuple[np.ndarray, bool]:
    """The observations and the last step's success of ``actions`` played open loop in a fresh env."""
    env = gym.make(TASK)
    observation, _ = env.reset(seed=reset_seed)
    observations = [observation]
    for action in actions:
        observation, _, _, _, info = env.step(action)
        observations.append(observation)
    return np.array(observations), bool(info["is_success"])


def minari_buffers(seeds: list[int | None]) -> list[EpisodeBuffer]:
    """Expert episodes as Minari stores what its DataCollector records: one buffer per episode, with its reset seed."""
    buffers = []
    for i, seed in enumerate(seeds):
        episode = expert_episode(0 if seed is None else seed)
        buffers.append(
            EpisodeBuffer(
                id=i,
                seed=seed,
                observations=episode["observations"],
                actions=episode["actions"],
                rewards=list(episode["rewards"]),
                terminations=[False] * HORIZON,
                truncations=[False] * (HORIZON - 1) + [True],
                infos={},
            )
        )
    return buffers


MINARI_METADATA = {  # what Minari warns about when it is missing
    "eval_env": TASK,
    "algorithm_name": "point_expert",
    "author": "sb3-genrl tests",
    "author_email": "tests@example.org",
    "code_permalink": "https://example.org/tests",
    "description": "expert episodes",
}


def minari_dataset(dataset_id: str, seeds: list[int | None]) -> minari.MinariDataset:
    """A local Minari dataset of the expert's episodes from these reset seeds (None: an episode without one)."""
    return minari.create_dataset_from_buffers(
        dataset_id,
        minari_buffers(seeds),
        env=TASK,
        **MINARI_METADATA,
    )


@pytest.fixture
def minari_root(tmp_path, monkeypatch):
    """Minari's local datasets folder, in the test's own folder."""
    root = tmp_path / "minari_datasets"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def test_replayed_demonstrations_keep_those_whose_open_loop_replay_succeeds(tmp_path):
    actions = np.stack([expert_episode(seed)["actions"] for seed in SEEDS])
    actions[1] *= -1.0  # walks away from the goal
    actions[3] = np.roll(actions[3], 1, axis=1)  # x and y swapped
    actions[4, 3:] = 0.0  # stops after 3 steps
    actions[5, 18:] = 0.0  # stops after the goal is reached
    saturated = np.abs(actions[6]) >= 1.0
    assert saturated.any()
    actions[6] = np.where(saturated, 2.0 * actions[6], actions[6])  # beyond the action space: clipped back
    path = replay_demonstrations(TASK, {"actions": actions, "reset_seeds": np.array(SEEDS)}, tmp_path / "demos")
    info = dataset_info(path)
    kept = [0, 2, 5, 6]
    assert info["source_episodes"] == kept and info["reset_seeds"] == [SEEDS[i] for i in kept]
    assert info["tried"] == 7 and info["failed_open_loop"] == 3 and info["failed_closed_loop"] == 0
    assert info["kept_share"] == pytest.approx(4 / 7) and info["episodes"] == 4
    assert info["expert"] is None and info["source"] == "arrays given in memory"
    assert info["task"] == TASK and info["horizon"] == HORIZON and info["seed"] is None
    # Minari's own record of what made the episodes says they were replayed, not played by an expert
    minari_metadata = json.loads((path / "data" / "metadata.json").read_text())
    assert minari_metadata["algorithm_name"] == "actions of arrays given in memory replayed open loop from their reset seeds"
    # The stored arrays are what the replay played: the actions clipped to the action space, the replay's observations.
    arrays = load_arrays(path)
    played = np.clip(actions[kept], -1.0, 1.0).astype(np.float32)
    np.testing.assert_array_equal(arrays["actions"], played)
    assert not np.array_equal(played[3], actions[6])
    for reset_seed, episode_actions, observations in zip(info["reset_seeds"], played, arrays["observations"], strict=True):
        expected, success = replayed(reset_seed, episode_actions)
        assert success
        np.testing.assert_array_equal(observations, expected)
    # The dropped ones do fail when replayed.
    assert not any(replayed(SEEDS[i], np.clip(actions[i], -1.0, 1.0))[1] for i in (1, 3, 4))


def test_shorter_actions_are_padded_with_zeros_and_an_npz_file_is_a_source(tmp_path):
    actions = np.stack([expert_episode(seed)["actions"][:16] for seed in SEEDS[:3]])
    np.savez(tmp_path / "actions.npz", actions=actions, reset_seeds=np.array(SEEDS[:3], dtype=np.uint32))
    path = replay_demonstrations(TASK, tmp_path / "actions.npz", tmp_path / "demos")
    stored = load_actions(path)
    assert stored.shape == (3, HORIZON, 2)
    np.testing.assert_array_equal(stored[:, :16], actions)
    assert not stored[:, 16:].any()
    assert dataset_info(path)["source"] == f"the file {tmp_path / 'actions.npz'}"


def test_a_minari_dataset_with_reset_seeds_round_trips(tmp_path, minari_root):
    minari_dataset("test/point-goal-v0", SEEDS[:4])
    by_id = replay_demonstrations(TASK, "test/point-goal-v0", tmp_path / "by_id")
    by_folder = replay_demonstrations(TASK, minari_root / "test" / "point-goal-v0", tmp_path / "by_folder")
    info = dataset_info(by_id)
    assert info["reset_seeds"] == SEEDS[:4] and info["kept_share"] == 1.0 and info["failed_open_loop"] == 0
    assert info["source"] == "the Minari dataset test/point-goal-v0"
    assert dataset_info(by_folder)["source"] == f"the Minari dataset folder {minari_root / 'test' / 'point-goal-v0'}"
    expected = np.stack([expert_episode(seed)["actions"] for seed in SEEDS[:4]])
    np.testing.assert_array_equal(load_actions(by_id), expected)
    np.testing.assert_array_equal(load_actions(by_folder), expected)
    # The replayed dataset is itself a Minari dataset, with the replay's episodes.
    episodes = list(minari.MinariDataset(by_id / "data").iterate_episodes())
    assert len(episodes) == 4
    np.testing.assert_array_equal(episodes[2].observations, expert_episode(SEEDS[2])["observations"])


def test_a_minari_dataset_recorded_by_the_data_collector_round_trips(tmp_path, minari_root):
    pytest.importorskip("jax", reason="Minari's DataCollector needs minari[create] (jax)")
    env = minari.DataCollector(gym.make(TASK))
    for seed in SEEDS[:3]:
        observation, _ = env.reset(seed=seed)
        for _ in range(HORIZON):
            observation, _, terminated, truncated, _ = env.step(point_expert(observation).astype(np.float32))
        assert truncated and not terminated
    env.create_dataset("test/collected-v0", **MINARI_METADATA)
    path = replay_demonstrations(TASK, "test/collected-v0", tmp_path / "demos")
    assert dataset_info(path)["reset_seeds"] == SEEDS[:3]
    np.testing.assert_array_equal(load_actions(path), np.stack([expert_episode(seed)["actions"] for seed in SEEDS[:3]]))


def test_a_recorded_dataset_replays_to_the_same_demonstrations(tmp_path):
    recorded = record_demonstrations(TASK, point_expert, 5, tmp_path / "recorded", seed=4, noise=0.6, n_threads=1)
    path = replay_demonstrations(TASK, recorded, tmp_path / "replayed")
    info, before = dataset_info(path), dataset_info(recorded)
    assert info["reset_seeds"] == before["reset_seeds"] and info["kept_share"] == 1.0
    original, again = load_arrays(recorded), load_arrays(path)
    for key, array in original.items():
        np.testing.assert_array_equal(again[key], array, err_msg=key)


def test_an_episode_without_a_reset_seed_is_refused_before_any_output(tmp_path, minari_root):
    minari_dataset("test/unseeded-v0", [SEEDS[0], None, SEEDS[2]])
    with pytest.raises(ValueError, match=r"episode 1 of the Minari dataset test/unseeded-v0 has no reset seed"):
        replay_demonstrations(TASK, "test/unseeded-v0", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_bad_sources_are_refused_before_any_output(tmp_path, minari_root):
    actions = np.stack([expert_episode(seed)["actions"] for seed in SEEDS[:2]])
    seeds = np.array(SEEDS[:2])
    (tmp_path / "notes.txt").write_text("not actions")
    for source, message in (
        ({"actions": np.zeros((2, HORIZON, 3)), "reset_seeds": seeds}, r"episode 0 of arrays given in memory has actions "
         r"of 3 numbers, but TestReplay/PointGoal-v0 takes 2"),
        ({"actions": np.zeros((2, HORIZON + 1, 2)), "reset_seeds": seeds}, r"has 21 steps of actions, more than the "
         r"horizon of 20 steps"),
        ({"actions": np.where(np.arange(2)[:, None, None] == 1, np.nan, actions), "reset_seeds": seeds},
         r"episode 1 of arrays given in memory: 40 of its actions' numbers are not finite"),
        ({"actions": actions, "reset_seeds": seeds.astype(float)}, r"reset_seeds .* must be 2 non-negative integers"),
        ({"actions": actions, "reset_seeds": -seeds}, r"reset_seeds .* must be 2 non-negative integers"),
        ({"actions": actions, "reset_seeds": seeds[:1]}, r"reset_seeds .* must be 2 non-negative integers"),
        ({"actions": actions[0], "reset_seeds": seeds}, r"must be a non-empty \(N, T, M\) array .* got shape \(20, 2\)"),
        ({"actions": actions.astype(str), "reset_seeds": seeds}, r"array of real numbers"),
        ({"actions": actions}, r"lacks \['reset_seeds'\]"),
        (tmp_path / "missing.npz", r"does not exist; expected an .npz file"),
        (tmp_path / "notes.txt", r"is a file but not an .npz file"),
        (tmp_path, r"is a folder but not a Minari dataset"),
        ("test/nowhere-v0", r"no Minari dataset of that id is stored locally .* nothing is downloaded"),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=message):
            replay_demonstrations(TASK, source, tmp_path / "out")
        assert not (tmp_path / "out").exists()


def test_an_env_that_reports_no_success_is_refused_before_any_output(tmp_path):
    source = {"actions": np.zeros((1, HORIZON, 2)), "reset_seeds": [SEEDS[0]]}
    with pytest.raises(ValueError, match=r"TestExternal/Silent-v0 reports no success: its step's info has no"):
        replay_demonstrations("TestExternal/Silent-v0", source, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    replay_demonstrations("TestExternal/Silent-v0", source | {"actions": expert_episode(SEEDS[0])["actions"][None]},
                          tmp_path / "out", success_key="solved")  # fmt: skip
    assert dataset_info(tmp_path / "out")["success_key"] == "solved"


def test_a_source_of_which_nothing_succeeds_is_an_error_naming_the_counts(tmp_path):
    source = {"actions": np.zeros((3, HORIZON, 2)), "reset_seeds": SEEDS[:3]}
    with pytest.raises(
        ValueError,
        match=r"none of the 3 episodes of arrays given in memory succeeded .*\(0 kept of 3 tried, 3 failed open loop\)",
    ):
        replay_demonstrations(TASK, source, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_read_replay_source_reads_the_episodes_with_their_seeds(minari_root):
    minari_dataset("test/read-v0", SEEDS[:2])
    episodes = read_replay_source("test/read-v0")
    assert episodes.reset_seeds == SEEDS[:2] and episodes.labels == ["episode 0", "episode 1"]
    np.testing.assert_array_equal(episodes.actions[1], expert_episode(SEEDS[1])["actions"])


def test_genrl_demos_from_a_dataset_writes_demonstrations_that_train_a_generator(cli, tmp_path):
    actions = np.stack([expert_episode(seed)["actions"] for seed in SEEDS])
    actions[2] *= -1.0
    np.savez(tmp_path / "actions.npz", actions=actions, reset_seeds=np.array(SEEDS))
    demos = tmp_path / "demos"
    code, out, err = cli("demos", "--task", TASK, "--from", tmp_path / "actions.npz", "--out", demos, "--no-progress-bar")
    assert code == 0, err
    info = dataset_info(demos)
    assert info["tried"] == 7 and info["failed_open_loop"] == 1 and info["source"] == f"the file {tmp_path / 'actions.npz'}"
    assert f"6 demonstrations of {TASK} (20 steps) kept of 7 replayed from the file {tmp_path / 'actions.npz'}" in out
    assert "(85.7%: 1 failed when replayed open loop)" in out
    generator = train_generator(demos, preset="VAE1", epochs=2, batch_size=4, eval_every=2, seed=0)
    assert (generator.horizon, generator.action_dim) == (HORIZON, 2) and generator.best_epoch is not None
    # --episodes N replays the first N of the dataset's episodes only
    code, out, err = cli(
        "demos", "--task", TASK, "--from", tmp_path / "actions.npz", "--episodes", 3, "--out", tmp_path / "first"
    )
    assert code == 0, err
    first = dataset_info(tmp_path / "first")
    assert first["tried"] == 3 and first["failed_open_loop"] == 1 and first["reset_seeds"] == SEEDS[:2]
    code, _, err = cli("demos", "--task", TASK, "--from", tmp_path / "actions.npz", "--episodes", 8, "--out", tmp_path / "x")
    assert code == 2 and "episodes (8) is more than the 7 episodes of the file" in err and not (tmp_path / "x").exists()


def test_genrl_demos_from_refuses_expert_options_before_any_work(cli, tmp_path):
    np.savez(tmp_path / "actions.npz", actions=np.zeros((1, HORIZON, 2)), reset_seeds=np.array(SEEDS[:1]))
    out = tmp_path / "demos"
    for arguments, message in (
        (("--expert", "test_external:point_expert"), "--expert cannot be used with --from"),
        (("--noise", "0.2"), "--noise cannot be used with --from"),
        (("--threads", "2"), "--threads cannot be used with --from"),
        (("--seed", "3"), "--seed cannot be used with --from"),
        (("--horizon", "10"), "episode 0 of the file"),
    ):
        code, _, err = cli("demos", "--task", TASK, "--from", tmp_path / "actions.npz", *arguments, "--out", out)
        assert code == 2 and message in err, (arguments, err)
        assert not out.exists()
