"""The demonstration generator (envs/demonstrations/), the coverage report (envs/coverage.py) and ``genrl demos``."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from sb3_genrl.envs import TASKS, external
from sb3_genrl.envs import demonstrations as demonstrations_package
from sb3_genrl.envs.coverage import coverage_fraction, coverage_report, covered_cells, region_cells
from sb3_genrl.envs.demonstrations import (
    arm,
    fetch,
    horizon,
    make_demonstrations,
    recorder,
    replay,
    sample_trajectories,
    tasks,
    within_limits,
)

from sb3_genrl.data import dataset_info, load_arrays

EPISODES = 8


@pytest.fixture(scope="module")
def hockey_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_demonstrations(
        "hockey", EPISODES, tmp_path_factory.mktemp("demos") / "hockey", seed=5, n_threads=2, progress_bar=False, chunk=12
    )


@pytest.mark.parametrize("task", ["hockey", "basketball"])
def test_sampling_is_seeded_and_within_limits(task: str) -> None:
    env = TASKS[task].make_env()
    first = sample_trajectories(task, 16, np.random.default_rng(1), home=env.home_qpos())
    again = sample_trajectories(task, 16, np.random.default_rng(1), home=env.home_qpos())
    other = sample_trajectories(task, 16, np.random.default_rng(2), home=env.home_qpos())
    assert first.shape == (16, env.horizon, 7) and first.dtype == np.float32
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    assert within_limits(first.astype(np.float64), env.home_qpos()).all()
    assert np.abs(first).max() < env.max_joint_delta
    with pytest.raises(ValueError, match="unknown task"):
        sample_trajectories("golf", 1, np.random.default_rng(0))


@pytest.mark.parametrize("task", ["hockey", "basketball"])
def test_joint_states_match_play_trajectories_and_step(task: str) -> None:
    env = TASKS[task].make_env()
    rng = np.random.default_rng(3)
    actions = sample_trajectories(task, 2, rng, home=env.home_qpos())
    goals = np.stack([env.sample_goal(rng) for _ in range(2)])
    rewards, infos, joints = env.play_trajectories(actions, goals, n_threads=2, return_joint_states=True)
    expected_rewards, expected_infos = env.play_trajectories(actions, goals)
    np.testing.assert_array_equal(rewards, expected_rewards)
    for info, expected in zip(infos, expected_infos, strict=True):
        np.testing.assert_array_equal(info["reached"], expected["reached"])
    # The joint readings are the step env's observations (after the goal) at every control step.
    env.reset(options={"goal": goals[0]})
    observations = [env._get_obs()]
    for action in actions[0]:
        observation, reward, terminated, _, _ = env.step(action)
        observations.append(observation)
    assert terminated and reward == rewards[0]
    np.testing.assert_array_equal(np.array(observations)[:, 2:], joints[0])


def test_stored_episodes_are_valid_replays(hockey_dataset: Path) -> None:
    arrays = load_arrays(hockey_dataset, task="hockey")
    assert arrays["actions"].shape == (EPISODES, 69, 7) and arrays["observations"].shape == (EPISODES, 70, 16)
    env = TASKS["hockey"].make_env()
    rewards, infos = env.play_trajectories(arrays["actions"], arrays["reached"], allow_outside_region=True)
    np.testing.assert_array_equal(rewards, 0.0)  # each demonstration's goal is the point it reached
    for i, info in enumerate(infos):
        np.testing.assert_array_equal(info["reached"], arrays["reached"][i])
        assert info["table_contacts"] == 0 and not info["joint_limit_clipped"] and not info["unstable"]
    for i in (0, EPISODES - 1):  # through the step env: the same observations, rewards and terminal flags
        observation, _ = env.reset(options={"goal": arrays["reached"][i], "allow_outside_region": True})
        observations, step_rewards, ends = [observation], [], []
        for action in arrays["actions"][i]:
            observation, reward, terminated, truncated, _ = env.step(action)
            observations.append(observation)
            step_rewards.append(reward)
            ends.append(terminated)
        np.testing.assert_array_equal(np.array(observations), arrays["observations"][i])
        np.testing.assert_array_equal(step_rewards, arrays["rewards"][i])
        np.testing.assert_array_equal(ends, arrays["terminations"][i])


def test_determinism_threads_and_seeds(hockey_dataset: Path, tmp_path: Path) -> None:
    same = make_demonstrations("hockey", EPISODES, tmp_path / "same", seed=5, n_threads=1, progress_bar=False, chunk=5)
    other = make_demonstrations("hockey", EPISODES, tmp_path / "other", seed=6, n_threads=2, progress_bar=False, chunk=12)
    reference, repeated = load_arrays(hockey_dataset), load_arrays(same)
    for key in reference:
        np.testing.assert_array_equal(reference[key], repeated[key])
    assert not np.array_equal(reference["actions"], load_arrays(other)["actions"])
    info = dataset_info(hockey_dataset)
    assert (info["task"], info["horizon"], info["seed"], info["episodes"]) == ("hockey", 69, 5, EPISODES)
    import mujoco

    assert info["mujoco"] == mujoco.__version__  # the simulator the demonstrations were played on
    with pytest.raises(ValueError, match="already exists"):
        make_demonstrations("hockey", 1, same, progress_bar=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other", "same"]  # no temporary directories left


def _cells_by_hand(task: str) -> int:
    """The goal region's cells counted from the paper's geometry (section 6.1.1), cell by cell."""
    if task == "hockey":  # x in [0.65, 1.3] m, y in [-0.4, 0.4] m, all inside: 13 x 16 cells of 5 cm
        return 13 * 16
    # Basketball: cells of 0.25 m over x in [0, 8] m, y in [-8, 8] m; the half-annulus keeps radii 1 to 8 m.
    return sum(1 for i in range(32) for j in range(64) if 1 <= math.hypot(0.125 + 0.25 * i, -7.875 + 0.25 * j) <= 8)


def _brute_force_coverage(points: np.ndarray, task: str) -> float:
    centres = region_cells(task)
    covered = [any(np.hypot(*(p - c)) <= TASKS[task].cell_size for p in points) for c in centres]
    return float(np.mean(covered))


@pytest.mark.parametrize("task", ["hockey", "basketball"])
def test_coverage_against_brute_force(task: str) -> None:
    centres = region_cells(task)
    assert len(centres) == _cells_by_hand(task)
    assert coverage_fraction(centres, task) == 1.0
    corner = centres[np.argmin(centres.sum(axis=1))][None]
    assert 0 < coverage_fraction(corner, task) < 0.05
    assert coverage_fraction(np.zeros((0, 2)), task) == 0.0
    rng = np.random.default_rng(0)
    low, high = centres.min(axis=0) - 0.3, centres.max(axis=0) + 0.3
    points = rng.uniform(low, high, size=(60, 2))
    assert coverage_fraction(points, task) == pytest.approx(_brute_force_coverage(points, task))
    assert covered_cells(points, task).shape == (len(centres),)


def test_basketball_region_cells() -> None:
    centres = region_cells("basketball")
    radius = np.linalg.norm(centres, axis=1)
    assert np.all((radius >= 1) & (radius <= 8) & (centres[:, 0] >= 0))
    area = np.pi / 2 * (8**2 - 1**2)
    assert len(centres) * 0.25**2 == pytest.approx(area, rel=0.03)


def test_coverage_report_files(hockey_dataset: Path, tmp_path: Path) -> None:
    report = coverage_report(hockey_dataset, None, tmp_path / "report")
    assert report["task"] == "hockey" and report["episodes"] == EPISODES and report["cells"] == 208
    assert json.loads((tmp_path / "report" / "coverage.json").read_text())["coverage"] == report["coverage"]
    assert (tmp_path / "report" / "coverage.png").stat().st_size > 0
    assert (hockey_dataset / "coverage.json").is_file()  # written by make_demonstrations
    with pytest.raises(ValueError, match="not 'basketball'"):
        coverage_report(hockey_dataset, "basketball", tmp_path / "other")


def test_cli_demos(tmp_path: Path, cli) -> None:
    out = tmp_path / "cli"
    code, printed, err = cli(
        "demos", "--task", "basketball", "--episodes", 3, "--out", out, "--seed", 1, "--threads", 2, "--no-progress-bar"
    )
    assert code == 0, err
    assert "3 basketball demonstrations" in printed and str(out) in printed and "coverage:" in printed
    assert dataset_info(out)["task"] == "basketball"
    arrays = load_arrays(out, task="basketball")
    rewards, infos = (
        TASKS["basketball"].make_env().play_trajectories(arrays["actions"], arrays["reached"], allow_outside_region=True)
    )
    np.testing.assert_array_equal(rewards, 0.0)  # hindsight goals: every demonstration succeeds
    assert all(info["crossings"] > 0 and not info["joint_limit_clipped"] for info in infos)
    code, _, err = cli("demos", "--task", "basketball", "--episodes", 3, "--out", out, "--no-progress-bar")
    assert code == 2 and "argument --out" in err  # checked before any work, saying what is in the way
    assert "already exists and holds a complete dataset (3 basketball demonstrations, seed 1)" in err


def test_hockey_hits_all_swing_at_the_same_step():
    # Whole-step differences in swing timing split the demonstrations into clusters that a 2-D generator lays out
    # as separate latent patches; every scripted hit therefore swings through the puck at the same control step.
    from sb3_genrl.envs.hockey import HOCKEY_SWING_START, sample_hit

    rng = np.random.default_rng(3)
    fastest_steps = {int(np.argmin(sample_hit(rng)[:, 5])) for _ in range(200)}
    assert len(fastest_steps) == 1
    assert HOCKEY_SWING_START <= fastest_steps.pop() < HOCKEY_SWING_START + 6  # inside the 6-step forward swing


def test_basketball_throws_all_swing_at_the_same_steps():
    # One family of throws with one timing: every base throw moves the shoulder on the same 4 control steps, with
    # the elbow in a fixed proportion, so the demonstrations differ only in yaw and strength (and perturbations).
    from sb3_genrl.envs.basketball import (
        BASKETBALL_ELBOW_SHARE,
        BASKETBALL_STRENGTH,
        BASKETBALL_SWING_STEPS,
        BASKETBALL_THROW_START,
        BASKETBALL_YAW,
        sample_throw,
    )

    rng = np.random.default_rng(3)
    throws = np.stack([sample_throw(rng) for _ in range(200)])
    swing_steps = {tuple(np.flatnonzero(throw[:, 1])) for throw in throws}
    assert swing_steps == {tuple(range(BASKETBALL_THROW_START, BASKETBALL_THROW_START + BASKETBALL_SWING_STEPS))}
    np.testing.assert_allclose(throws[:, :, 3], BASKETBALL_ELBOW_SHARE * throws[:, :, 1])
    strengths, yaws = throws[:, :, 1].sum(axis=1), throws[:, :, 0].sum(axis=1)
    assert BASKETBALL_STRENGTH[0] <= strengths.min() and strengths.max() <= BASKETBALL_STRENGTH[1]
    assert np.abs(yaws).max() <= BASKETBALL_YAW and yaws.min() < -1.5 and yaws.max() > 1.5


def test_every_maker_of_demonstrations_lives_in_the_demonstrations_package() -> None:
    # the arm tasks', the Fetch tasks', any env's recorder, its horizon, the replay of a dataset and the one entry of
    # every task are its modules, their public names re-exported by it
    makers = (arm, fetch, recorder, horizon, replay, tasks)
    for module in makers:
        assert module.__name__.startswith("sb3_genrl.envs.demonstrations.")
    for name in demonstrations_package.__all__:
        assert any(getattr(module, name, None) is getattr(demonstrations_package, name) for module in makers), name
    assert demonstrations_package.perturbation is arm.perturbation and fetch.perturbation is arm.perturbation
    assert demonstrations_package.make_arrays is fetch.make_arrays
    assert demonstrations_package.record_demonstrations is recorder.record_demonstrations
    # the task side holds no recorder, and the former module is gone
    assert not {"record_demonstrations", "smooth_noise", "DEFAULT_NOISE", "expert_name"} & set(vars(external))
    assert importlib.util.find_spec("sb3_genrl.envs.fetch_demonstrations") is None
