"""A task from outside the package (sb3_genrl.envs.external): an expert's demonstrations recorded on an env the
package does not ship (sb3_genrl.envs.demonstrations.recorder), kept only when their open-loop replay succeeds, a
generator trained on them and a GenRL policy trained through the public path."""

import functools
import json
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import HANG_S
from gymnasium import spaces
from sb3_genrl.envs import external, metaworld
from sb3_genrl.envs.demonstrations import (
    expert_horizon,
    make_demonstrations,
    play_episode,
    record_demonstrations,
    recorder,
    smooth_noise,
    task_demonstrations,
)
from sb3_genrl.envs.external import (
    HELD_OUT_RESETS,
    HELD_OUT_SEED,
    Task,
    check_reproducible_reset,
    evaluate_success,
    load_expert,
    make_task_env,
    resolve_task,
)

import sb3_genrl
from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.cli.commands import _outside_env_maker
from sb3_genrl.data import dataset_info, load_actions, load_arrays, read_metadata
from sb3_genrl.generative import load, train_generator
from sb3_genrl.genrl.demonstrations import DemonstrationCallback
from sb3_genrl.run.train import _make_env, _resolve_env_id
from sb3_genrl.study.quickstart import (
    OUTSIDE_DEMO_STEPS,
    OUTSIDE_POLICY_STEPS,
    QUICKSTART_PRESET,
    outside_demo_episodes,
    outside_task_settings,
)

HORIZON = 20
STEP = 0.1  # metres moved per unit of action and step
SHOVE_STEP = 10  # the step at which a replay of a left-hand goal is shoved


class PointGoalEnv(gym.Env):
    """A point mass that must end within 5 cm of a goal drawn from the reset seed (not a task of the package).

    Observation: goal (2), position (2). Action: velocity in [-1, 1]^2, ``STEP`` m a unit. Reward: minus the distance.
    ``info["is_success"]``: within 5 cm. With ``shove``, every play of a goal left of the start (x < 0) after its first
    is shoved 0.3 m in x at step ``SHOVE_STEP``: a disturbance the closed-loop expert corrects when it meets it, but that
    an open-loop replay of the first play's actions meets uncorrected.
    """

    metadata = {"render_modes": []}

    def __init__(self, shove: bool = False) -> None:
        self.observation_space = spaces.Box(-2.0, 2.0, shape=(4,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.shove = shove
        self.plays: dict[tuple[float, float], int] = {}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.goal = self.np_random.uniform(-0.8, 0.8, size=2)
        self.position, self.t = np.zeros(2), 0
        return self._obs(), {}

    def _obs(self):
        return np.concatenate([self.goal, self.position]).astype(np.float32)

    def step(self, action):
        self.position = self.position + STEP * np.clip(action, -1.0, 1.0)
        self.t += 1
        if self.t == SHOVE_STEP:
            key = tuple(self.goal)
            self.plays[key] = self.plays.get(key, 0) + 1
            if self.shove and self.goal[0] < 0 and self.plays[key] > 1:
                self.position = self.position + np.array([0.3, 0.0])
        distance = float(np.linalg.norm(self.position - self.goal))
        return self._obs(), -distance, False, False, {"is_success": distance < 0.05}


class UnseededEnv(PointGoalEnv):
    """Draws its goal from a generator that ``reset(seed=...)`` does not reseed."""

    def __init__(self) -> None:
        super().__init__()
        self.draws = np.random.default_rng(0)

    def reset(self, *, seed=None, options=None):
        observation, info = super().reset(seed=seed)
        self.goal = self.draws.uniform(-0.8, 0.8, size=2)
        return self._obs(), info


class SilentEnv(PointGoalEnv):
    """Reports its success under another key."""

    def step(self, action):
        observation, reward, terminated, truncated, info = super().step(action)
        return observation, reward, terminated, truncated, {"solved": info["is_success"]}


gym.register("TestExternal/PointGoal-v0", entry_point=PointGoalEnv, max_episode_steps=HORIZON)
gym.register("TestExternal/Silent-v0", entry_point=SilentEnv, max_episode_steps=HORIZON)
gym.register("TestExternal/PointGoalShove-v0", entry_point=PointGoalEnv, kwargs={"shove": True}, max_episode_steps=HORIZON)


def point_expert(observation: np.ndarray) -> np.ndarray:
    """Closes half the distance to the goal at each step."""
    return np.clip(0.5 * (observation[:2] - observation[2:]) / STEP, -1.0, 1.0)


class LockedExpert:
    """:func:`point_expert` holding a lock: an expert that cannot be pickled."""

    def __init__(self) -> None:
        self.lock = threading.Lock()

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        with self.lock:
            return point_expert(observation)


def far_goal_refusing_expert(observation: np.ndarray) -> np.ndarray:
    """:func:`point_expert`, but raising on a goal far right of the start (x > 0.6)."""
    if observation[0] > 0.6:
        raise ValueError(f"goal x {observation[0]:.3f} is out of this expert's reach")
    return point_expert(observation)


def fleeing_expert(observation: np.ndarray) -> np.ndarray:
    """Moves away from the goal: never succeeds."""
    return -point_expert(observation)


def goal_of(reset_seed: int) -> np.ndarray:
    env = PointGoalEnv()
    env.reset(seed=reset_seed)
    return env.goal


def test_record_demonstrations_keeps_those_whose_open_loop_replay_succeeds(tmp_path):
    calm = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 30, tmp_path / "calm", seed=3, noise=0.6)
    shoved = record_demonstrations("TestExternal/PointGoalShove-v0", point_expert, 10, tmp_path / "shoved", seed=3, noise=0.6)
    calm_info, info = dataset_info(calm), dataset_info(shoved)
    # A deterministic env replays every closed-loop success; the perturbation makes some expert episodes fail.
    assert calm_info["failed_open_loop"] == 0 and calm_info["failed_closed_loop"] > 0
    assert calm_info["tried"] == 30 + calm_info["failed_closed_loop"]
    # The closed-loop plays are the same in both envs (a first play is never shoved): of the calm env's kept episodes,
    # the shoved env keeps those of goals right of the start, and drops and counts the others, whose replay fails.
    right = [s for s in calm_info["reset_seeds"] if goal_of(s)[0] >= 0]
    assert len(right) >= 10
    assert info["reset_seeds"] == right[:10]
    left_before = [s for s in calm_info["reset_seeds"][: calm_info["reset_seeds"].index(right[9])] if goal_of(s)[0] < 0]
    assert info["failed_open_loop"] == len(left_before) > 0
    assert info["tried"] == 10 + info["failed_open_loop"] + info["failed_closed_loop"]
    assert info["kept_share"] == pytest.approx(10 / info["tried"])
    assert info["horizon"] == HORIZON and info["task"] == "TestExternal/PointGoalShove-v0"
    # The stored actions, replayed open loop in a fresh env from their reset seeds, succeed; the observations are
    # the closed-loop episode's.
    arrays = load_arrays(shoved)
    assert arrays["actions"].shape == (10, HORIZON, 2) and arrays["observations"].shape == (10, HORIZON + 1, 4)
    for reset_seed, actions, observations in zip(info["reset_seeds"], arrays["actions"], arrays["observations"], strict=True):
        env = gym.make("TestExternal/PointGoal-v0")
        observation, _ = env.reset(seed=reset_seed)
        np.testing.assert_array_equal(observation, observations[0])
        for action in actions:
            observation, _, _, _, step_info = env.step(action)
        np.testing.assert_array_equal(observation, observations[-1])
        assert step_info["is_success"]


def shifting_expert(observation: np.ndarray) -> np.ndarray:
    """:func:`point_expert` that first shifts the goal in its observation in place (as Meta-World's door-open-v3
    policy shifts the handle's position)."""
    observation[0] -= 0.05
    return point_expert(observation + np.array([0.05, 0.0, 0.0, 0.0], dtype=np.float32))


def test_an_expert_that_changes_its_observation_in_place_changes_no_recorded_observation(tmp_path):
    demos = record_demonstrations("TestExternal/PointGoal-v0", shifting_expert, 6, tmp_path / "demos", seed=3)
    info, arrays = dataset_info(demos), load_arrays(demos)
    assert info["episodes"] == 6 and info["failed_open_loop"] == 0  # each replay starts where its play started
    for reset_seed, observations in zip(info["reset_seeds"], arrays["observations"], strict=True):
        env = gym.make("TestExternal/PointGoal-v0")
        np.testing.assert_array_equal(env.reset(seed=reset_seed)[0], observations[0])


def test_record_demonstrations_is_the_same_whatever_the_number_of_worker_processes(tmp_path):
    paths = {
        n_threads: record_demonstrations(
            "TestExternal/PointGoalShove-v0",
            point_expert,
            12,
            tmp_path / f"{n_threads}",
            seed=3,
            noise=0.6,
            n_threads=n_threads,
        )
        for n_threads in (1, 2)
    }
    one = load_arrays(paths[1])
    metadata = read_metadata(paths[1])
    del metadata["genrl"]["seconds"]
    # Episodes fail both ways, so the kept ones are not a simple prefix of the episodes the workers played.
    assert metadata["genrl"]["failed_open_loop"] > 0 and metadata["genrl"]["failed_closed_loop"] > 0
    two = load_arrays(paths[2])
    assert two.keys() == one.keys()
    for key, array in one.items():
        np.testing.assert_array_equal(two[key], array, err_msg=key)
    other = read_metadata(paths[2])
    del other["genrl"]["seconds"]
    assert other == metadata


def test_an_expert_that_cannot_be_pickled_plays_in_this_process(tmp_path):
    expert = LockedExpert()
    path = record_demonstrations("TestExternal/PointGoal-v0", expert, 6, tmp_path / "locked", seed=2, n_threads=2)
    reference = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 6, tmp_path / "plain", seed=2, n_threads=1)
    np.testing.assert_array_equal(load_actions(path), load_actions(reference))
    assert dataset_info(path)["reset_seeds"] == dataset_info(reference)["reset_seeds"]


def test_an_error_in_a_worker_process_names_its_episode(tmp_path):
    seeds = [int(np.random.default_rng([0, k]).integers(2**31)) for k in range(40)]
    first = next(k for k, reset_seed in enumerate(seeds) if goal_of(reset_seed)[0] > 0.6)
    assert first > 0  # the check before any work (episode 0's first step) passes
    with pytest.raises(RuntimeError, match=rf"episode {first} of TestExternal/PointGoal-v0 .*out of this expert's reach"):
        record_demonstrations("TestExternal/PointGoal-v0", far_goal_refusing_expert, 30, tmp_path / "out", n_threads=2)
    assert not (tmp_path / "out").exists()


def test_a_script_without_a_main_guard_is_told_to_add_one(tmp_path):
    script, out = tmp_path / "unguarded.py", tmp_path / "out"
    script.write_text(
        f"import sys\nsys.path.insert(0, {str(Path(__file__).parent)!r})\nfrom test_external import point_expert\n"
        "from sb3_genrl.envs.demonstrations import record_demonstrations\n"
        f"record_demonstrations('TestExternal/PointGoal-v0', point_expert, 2, {str(out)!r}, n_threads=2)\n"
    )
    done = subprocess.run(
        [sys.executable, script], capture_output=True, text=True, env=os.environ | {"MUJOCO_GL": "egl"}, timeout=HANG_S
    )
    guard = 'a script must call record_demonstrations or expert_horizon under `if __name__ == "__main__":`'
    assert done.returncode != 0 and guard in done.stderr
    # The worker says why it stopped (before it claims the folder the script holds), and the script names the episodes.
    assert "RuntimeError: the worker processes that play the episodes (n_threads > 1" in done.stderr
    assert "is in use by another process" not in done.stderr
    assert "a worker process ended abruptly while it played episodes 0 to 0 of TestExternal/PointGoal-v0" in done.stderr
    assert not out.exists()


def test_record_demonstrations_gives_up_after_the_same_first_tries_in_worker_processes(tmp_path):
    for n_threads in (1, 2):
        with pytest.raises(RuntimeError, match=r"none of the first 200 demonstrations .* \(200 failed closed loop, 0 failed"):
            record_demonstrations("TestExternal/PointGoal-v0", fleeing_expert, 2, tmp_path / "out", n_threads=n_threads)
        assert not (tmp_path / "out").exists()


def test_record_demonstrations_is_a_prefix_of_a_larger_set(tmp_path):
    small = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 4, tmp_path / "small", seed=1)
    large = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 8, tmp_path / "large", seed=1)
    np.testing.assert_array_equal(load_actions(small), load_actions(large)[:4])


def test_demonstrations_train_a_generator_and_a_genrl_policy(tmp_path):
    path = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 40, tmp_path / "demos", seed=0)
    generator = train_generator(path, preset="VAE1", epochs=5, batch_size=16, eval_every=5, seed=0)
    assert (generator.horizon, generator.action_dim) == (HORIZON, 2)
    model = GenRL(
        LatentActionWrapper(make_task_env("TestExternal/PointGoal-v0"), generator), n_steps=16, batch_size=16, seed=0
    )
    model.learn(total_timesteps=32)
    assert model.num_timesteps == 32
    # the env's info["is_success"] reached SB3's success rate: one entry a finished episode
    assert len(model.ep_success_buffer) == 32


def test_an_env_without_episode_length_needs_a_horizon(tmp_path):
    with pytest.raises(ValueError, match=r"declares no episode length .*horizon="):
        record_demonstrations(PointGoalEnv, point_expert, 2, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    path = record_demonstrations(PointGoalEnv, point_expert, 2, tmp_path / "out", horizon=12)
    assert load_actions(path).shape == (2, 12, 2) and dataset_info(path)["horizon"] == 12
    with pytest.raises(ValueError, match=r"horizon 30 is longer than .*\(20 steps\)"):
        record_demonstrations("TestExternal/PointGoal-v0", point_expert, 2, tmp_path / "other", horizon=30)


def test_an_env_whose_seeded_resets_differ_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"reset\(seed=\d+\) gave two different observations"):
        record_demonstrations(UnseededEnv, point_expert, 2, tmp_path / "out", horizon=HORIZON)
    assert not (tmp_path / "out").exists()
    check_reproducible_reset(PointGoalEnv(), 5)  # the seeded env passes


def test_success_key_is_configurable_and_its_absence_refused(tmp_path):
    with pytest.raises(ValueError, match=r"reports no success: its step's info has no 'is_success' or 'success'"):
        record_demonstrations(SilentEnv, point_expert, 2, tmp_path / "out", horizon=HORIZON)
    assert not (tmp_path / "out").exists()
    path = record_demonstrations(SilentEnv, point_expert, 2, tmp_path / "out", horizon=HORIZON, success_key="solved")
    assert dataset_info(path)["success_key"] == "solved"


def test_bad_expert_and_noise_are_refused_before_any_work(tmp_path):
    with pytest.raises(ValueError, match=r"the expert returned .*shape \(3,\).*expected 2 finite numbers"):
        record_demonstrations("TestExternal/PointGoal-v0", lambda observation: np.zeros(3), 2, tmp_path / "out")
    with pytest.raises(ValueError, match="noise"):
        record_demonstrations("TestExternal/PointGoal-v0", point_expert, 2, tmp_path / "out", noise=-0.1)

    def raising(observation):
        raise RuntimeError("boom")

    def two_arguments(observation, info):
        return np.zeros(2)

    for expert, message in (
        (raising, r"the expert raised RuntimeError: boom \(it is called as expert\(observation\) -> action\)"),
        (two_arguments, r"the expert raised TypeError: .*missing 1 required positional argument: 'info'"),
        (lambda observation: None, "the expert returned None; expected an action of the env's action space"),
    ):
        with pytest.raises(ValueError, match=message):
            record_demonstrations("TestExternal/PointGoal-v0", expert, 2, tmp_path / "out")
    with pytest.raises(ValueError, match="has no expert of the package's"):
        record_demonstrations("TestExternal/PointGoal-v0", None, 2, tmp_path / "out")
    for n_threads in (0, 1.5, True):
        with pytest.raises(ValueError, match=rf"n_threads must be an integer >= 1, got {n_threads!r}"):
            record_demonstrations("TestExternal/PointGoal-v0", point_expert, 2, tmp_path / "out", n_threads=n_threads)
    assert not (tmp_path / "out").exists()


def test_smooth_noise_heights_are_bounded_by_the_noise_scale():
    heights = np.array([0.5, 0.0])
    for k in range(50):
        noise = smooth_noise(HORIZON, np.random.default_rng(k), heights)
        assert noise.shape == (HORIZON, 2) and np.all(noise[:, 1] == 0.0)
        assert np.abs(noise[:, 0]).max() <= 4 * 0.5  # at most 4 bumps, each at most 0.5 high


def test_task_names_and_experts_resolve_or_are_refused():
    assert resolve_task("TestExternal/PointGoal-v0").env_id == "TestExternal/PointGoal-v0"
    assert resolve_task("test_external:TestExternal/PointGoal-v0").env_id == "TestExternal/PointGoal-v0"
    assert resolve_task("hockey").env_id == "GenRL/Hockey-v0"
    with pytest.raises(ValueError, match="unknown task 'NoSuch-v0'"):
        resolve_task("NoSuch-v0")
    with pytest.raises(ValueError, match="unknown Meta-World task 'no-such-v3'"):
        resolve_task("metaworld/no-such-v3")
    assert load_expert("test_external:point_expert") is point_expert
    for spec, message in (
        ("no_such_module:f", "cannot import the module 'no_such_module'"),
        ("test_external:no_such", "has no attribute 'no_such'"),
        ("test_external:HORIZON", "is a int, not a callable"),
        ("point_expert", "module:function"),
    ):
        with pytest.raises(ValueError, match=message):
            load_expert(spec)


def test_genrl_demos_horizon_expert_records_as_long_as_the_experts_success_takes_to_settle(cli, tmp_path):
    demos = tmp_path / "demos"
    arguments = ("--expert", "test_external:point_expert", "--episodes", 4, "--no-progress-bar")
    code, out, err = cli("demos", "--task", "TestExternal/PointGoal-v0", *arguments, "--horizon", "expert", "--out", demos)
    assert code == 0, err
    found = expert_horizon("TestExternal/PointGoal-v0", point_expert, seed=0)  # the command's seed, 0 by default
    assert dataset_info(demos)["horizon"] == found["horizon"] < HORIZON
    assert f"horizon: {found['horizon']} steps, where the expert's success settles" in out
    assert f"4 demonstrations of TestExternal/PointGoal-v0 ({found['horizon']} steps)" in out
    # refused before any work: a horizon read from an expert for replayed actions, a word other than "expert"
    code, _, err = cli(
        "demos", "--task", "TestExternal/PointGoal-v0", "--from", demos, "--horizon", "expert", "--out", tmp_path / "r"
    )
    assert code == 2 and "--horizon expert reads the horizon from an expert" in err, err
    code, _, err = cli(
        "demos", "--task", "TestExternal/PointGoal-v0", *arguments, "--horizon", "auto", "--out", tmp_path / "a"
    )
    assert code == 2 and "--horizon" in err and "auto" in err, err
    assert not (tmp_path / "r").exists() and not (tmp_path / "a").exists()


def test_genrl_demos_and_train_policy_take_a_task_the_package_does_not_register(cli, tmp_path):
    demos = tmp_path / "demos"
    code, out, err = cli(
        "demos", "--task", "TestExternal/PointGoalShove-v0", "--expert", "test_external:point_expert", "--noise", 0.6,
        "--episodes", 12, "--seed", 3, "--out", demos, "--no-progress-bar",
    )  # fmt: skip
    assert code == 0, err
    info = dataset_info(demos)
    assert info["failed_open_loop"] > 0 and info["expert"] == "test_external:point_expert"
    assert f"12 demonstrations of TestExternal/PointGoalShove-v0 (20 steps) kept of {info['tried']} tried" in out
    assert f"{info['failed_open_loop']} failed when replayed open loop" in out
    code, _, err = cli(
        "train-generator", "--data", demos, "--preset", "vae-fetch", "--epochs", 3, "--batch-size", 8, "--eval-every", 3,
        "--out", tmp_path / "vae.pt", "--no-progress-bar",
    )  # fmt: skip
    assert code == 0, err
    code, out, err = cli(
        "train-policy", "--task", "test_external:TestExternal/PointGoal-v0", "--generator", tmp_path / "vae.pt",
        "--data", demos, "--episodes", 32, "--batch-episodes", 16, "--checkpoint-every", 0, "--out", tmp_path / "policy",
        "--no-progress-bar",
    )  # fmt: skip
    assert code == 0, err
    assert load(tmp_path / "vae.pt", device="cpu").latent_dim == 10  # the quickstart's preset for such a task
    summary = json.loads((tmp_path / "policy" / "summary.json").read_text())
    assert summary["task"] == "TestExternal/PointGoal-v0" and summary["episodes"] == 32
    assert re.search(r"success: [0-9.]+ of the last episodes played \(info\['is_success'\]", out), out
    silent = (
        "train-policy", "--task", "TestExternal/Silent-v0", "--generator", tmp_path / "vae.pt", "--data", demos,
        "--episodes", 16, "--batch-episodes", 16, "--checkpoint-every", 0, "--out", tmp_path / "silent", "--no-progress-bar",
    )  # fmt: skip
    # a task from outside the package refits its mean to the pulls that solved their own reset, which needs the success
    code, out, err = cli(*silent)
    assert code == 2 and "needs every pull's info['is_success']" in err and "--success-key" in err, err
    assert not (tmp_path / "silent").exists()  # refused before its run folder is made
    leave_out = '{"hindsight_kwargs": null, "success_kl_floor": null}'
    assert f"--genrl-kwargs '{leave_out}'" in err
    code, out, err = cli(*silent, "--genrl-kwargs", leave_out)
    assert code == 0, err
    assert "success: the env reports no info['is_success']" in out
    code, out, err = cli(
        "train-policy", "--task", "TestExternal/Silent-v0", "--generator", tmp_path / "vae.pt", "--data", demos,
        "--episodes", 16, "--batch-episodes", 16, "--checkpoint-every", 0, "--success-key", "solved",
        "--out", tmp_path / "solved", "--no-progress-bar",
    )  # fmt: skip
    assert code == 0, err
    assert re.search(r"success: [0-9.]+ of the last episodes played \(info\['is_success'\]", out), out
    assert json.loads((tmp_path / "solved" / "summary.json").read_text())["success_key"] == "solved"


def test_genrl_demos_refuses_bad_tasks_and_experts_before_any_work(cli, tmp_path, monkeypatch):
    (tmp_path / "failing_import.py").write_text('raise RuntimeError("the module\'s own error")\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "demos"
    for arguments, message in (
        (("--task", "NoSuch-v0", "--expert", "test_external:point_expert"), "unknown task 'NoSuch-v0'"),
        (("--task", "TestExternal/PointGoal-v0", "--expert", "test_external:nope"), "has no attribute 'nope'"),
        (("--task", "TestExternal/PointGoal-v0", "--expert", "no_such_module:f"), "with PYTHONPATH=. before the command"),
        (
            ("--task", "TestExternal/PointGoal-v0", "--expert", "failing_import:f"),
            "cannot import the module 'failing_import' (RuntimeError: the module's own error)",
        ),
        (("--task", "failing_import:X-v0", "--expert", "test_external:point_expert"), "(RuntimeError: the module's own"),
        (("--task", "TestExternal/PointGoal-v0"), "give its expert as --expert MODULE:FUNCTION"),
        (("--task", "hockey", "--horizon", "10"), "--horizon applies to demonstrations from an expert"),
        (("--task", "TestExternal/PointGoal-v0", "--expert", "test_external:point_expert", "--threads", "0"), "--threads"),
    ):
        code, _, err = cli("demos", *arguments, "--episodes", 2, "--out", out, "--no-progress-bar")
        assert code == 2 and message in err, (arguments, err)
        assert not out.exists()


def test_genrl_demos_plays_an_experts_episodes_in_the_worker_processes_asked_for(cli, tmp_path):
    code, out, err = cli(
        "demos", "--task", "TestExternal/PointGoalShove-v0", "--expert", "test_external:point_expert", "--noise", 0.6,
        "--episodes", 8, "--seed", 3, "--threads", 2, "--out", tmp_path / "demos", "--no-progress-bar",
    )  # fmt: skip
    assert code == 0, err
    reference = record_demonstrations(
        "TestExternal/PointGoalShove-v0", point_expert, 8, tmp_path / "reference", seed=3, noise=0.6, n_threads=1
    )
    np.testing.assert_array_equal(load_actions(tmp_path / "demos"), load_actions(reference))
    info = dataset_info(tmp_path / "demos")
    assert info["tried"] == dataset_info(reference)["tried"] and info["failed_open_loop"] > 0
    assert f"8 demonstrations of TestExternal/PointGoalShove-v0 (20 steps) kept of {info['tried']} tried" in out


@pytest.mark.skipif(not metaworld.installed(), reason=metaworld.INSTALL_HINT)
def test_a_metaworld_task_by_name_records_its_experts_demonstrations(tmp_path, monkeypatch):
    task = resolve_task("metaworld/reach-v3")
    assert task.env_id == "GenRL/metaworld-reach-v3" and task.make_expert is not None
    plays = []  # (closed loop, whether the env ends at a success, steps played) of each play

    def spied_play_episode(env, reset_seed, steps, expert, actions):
        played = play_episode(env, reset_seed, steps, expert, actions)
        plays.append((expert is not None, env.unwrapped.terminate_on_success, len(played["actions"])))
        return played

    monkeypatch.setattr(recorder, "play_episode", spied_play_episode)
    path = record_demonstrations("metaworld/reach-v3", None, 2, tmp_path / "reach", horizon=60, noise=0.1)
    # played closed loop in the training env to the horizon, replayed in the env GenRL plays, which ends at the first
    # success (the same outcome, fewer steps)
    closed_loop = [(ends, steps) for closed, ends, steps in plays if closed]
    replays = [(ends, steps) for closed, ends, steps in plays if not closed]
    assert len(replays) == 2 and closed_loop == [(False, 60)] * len(closed_loop)
    assert all(ends and steps < 60 for ends, steps in replays)
    info = dataset_info(path)
    assert info["env_id"] == "GenRL/metaworld-reach-v3" and info["expert"].endswith("MetaWorldExpert")
    assert load_actions(path).shape == (2, 60, 4)
    # the kept actions replayed open loop from their reset seeds succeed at the last step
    env = make_task_env("metaworld/reach-v3", horizon=60)
    for reset_seed, actions in zip(info["reset_seeds"], load_actions(path), strict=True):
        env.reset(seed=reset_seed)
        for action in actions:
            _, _, _, _, step_info = env.step(action)
        assert step_info["is_success"]
    # recorded in Meta-World's training env, which runs on after a success: every demonstration holds the expert's
    # actions up to the horizon, not hold actions after its success (the env GenRL plays ends at the first success)
    arrays = load_arrays(path, keys=("actions", "terminations", "truncations"))
    assert not arrays["terminations"].any() and arrays["truncations"][:, -1].all()
    assert np.all(np.abs(arrays["actions"][:, -10:]).sum(axis=(1, 2)) > 0)
    env.reset(seed=info["reset_seeds"][0])
    ended = [env.step(action)[2] for action in load_actions(path)[0]]
    assert any(ended)  # the same actions in the env GenRL plays: it ends at their first success


def test_train_policy_truncates_the_env_to_the_demonstrations_horizon(cli, tmp_path):
    demos = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 12, tmp_path / "demos", horizon=12)
    generator = train_generator(demos, preset="VAE1", epochs=2, batch_size=8, eval_every=2, out=tmp_path / "vae.pt")
    assert generator.horizon == 12
    arguments = (
        "--generator",
        tmp_path / "vae.pt",
        "--data",
        demos,
        "--episodes",
        16,
        "--batch-episodes",
        16,
        "--checkpoint-every",
        0,
        "--no-progress-bar",
    )
    code, _, err = cli(
        "train-policy", "--task", "TestExternal/PointGoal-v0", "--horizon", 30, *arguments, "--out", tmp_path / "p"
    )
    assert code == 2 and "horizon 30 is longer than TestExternal/PointGoal-v0's episodes (20 steps)" in err
    assert not (tmp_path / "p").exists()
    code, _, err = cli(
        "train-policy", "--task", "TestExternal/PointGoal-v0", "--horizon", 12, *arguments, "--out", tmp_path / "p"
    )
    assert code == 0, err
    assert json.loads((tmp_path / "p" / "summary.json").read_text())["horizon"] == 12
    # the run's env: 12 steps played, none held
    env = LatentActionWrapper(_make_env("TestExternal/PointGoal-v0", 12), generator)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(generator.latent_dim, dtype=np.float32))
    assert (info["steps_played"], info["hold_steps"], info["ended"]) == (12, 0, True)
    # without --horizon, the demonstrations' own: the same run
    code, _, err = cli("train-policy", "--task", "TestExternal/PointGoal-v0", *arguments, "--out", tmp_path / "d")
    assert code == 0, err
    assert json.loads((tmp_path / "d" / "summary.json").read_text())["horizon"] == 12
    same, given = (GenRL.load(tmp_path / run / "genrl_policy.zip", device="cpu").policy for run in ("d", "p"))
    assert all(torch.equal(a, b) for a, b in zip(same.state_dict().values(), given.state_dict().values(), strict=True))


def test_quickstart_of_an_outside_task_with_an_expert_reports_its_held_out_success(cli, tmp_path, monkeypatch):
    task, out = "test_external:TestExternal/PointGoal-v0", tmp_path / "quick"
    # the default count of demonstrations: as many as fit the quickstart's budget of demonstration steps
    monkeypatch.setattr("sb3_genrl.study.quickstart.OUTSIDE_DEMO_STEPS", 96)
    arguments = (
        "quickstart", "--task", task, "--expert", "test_external:point_expert", "--out", out,
        "--epochs", 2, "--episodes", 64, "--no-progress-bar", "--device", "cpu",
    )  # fmt: skip
    code, printed, err = cli(*arguments)
    assert code == 0, err
    # No horizon given: the shortest at which the expert's success settles, found before the demonstrations, recorded
    # and used by every stage. The point expert needs at most 12 of the env's 20 steps (the horizon's own tests:
    # test_horizon.py).
    found = json.loads((out / "horizon.json").read_text())
    horizon = found["horizon"]
    assert found["settled"] and found["best"] == 1.0 and found["expert"] == "test_external:point_expert"
    assert horizon == expert_horizon(task, point_expert)["horizon"] < HORIZON and f"horizon: {horizon} steps" in printed
    info = dataset_info(out / "demonstrations")
    demonstrations = 96 // horizon
    assert info["episodes"] == demonstrations and info["horizon"] == horizon
    assert info["expert"] == "test_external:point_expert"
    policy = json.loads((out / "policy" / "summary.json").read_text())
    assert policy["task"] == "TestExternal/PointGoal-v0" and policy["episodes"] == 64 and policy["horizon"] == horizon
    # The held-out success is the saved policy's, played again here on the documented reset seeds 2**31, 2**31 + 1, ...
    summary = json.loads((out / "summary.json").read_text())
    model = GenRL.load(out / "policy" / "genrl_policy.zip", device="cpu")
    played = evaluate_success(model, task, resets=HELD_OUT_RESETS, horizon=horizon)
    assert summary["held_out_success"] == played["success_rate"] and summary["held_out_resets"] == HELD_OUT_RESETS == 200
    assert summary["held_out_seeds"] == [HELD_OUT_SEED, HELD_OUT_SEED + 200] and HELD_OUT_SEED == 2**31
    # the time of each stage and of the held-out score, and the package that wrote it
    assert list(summary["stage_seconds"]) == ["horizon", "demonstrations", "generator", "evaluation", "policy", "score"]
    assert summary["provenance"]["sb3_genrl"] == sb3_genrl.__version__ and "git_commit" in summary["provenance"]
    assert max(info["reset_seeds"]) < HELD_OUT_SEED  # no demonstration starts from a held-out reset
    report = (out / "report.md").read_text()
    assert f"{demonstrations} perturbed episodes of the expert `test_external:point_expert`, {horizon} steps each" in report
    assert f"200 held-out seeded resets (reset seeds {2**31} to {2**31 + 199}" in report
    assert f"deterministic: **{summary['held_out_success']:.1%}**" in report
    # A rerun resumes without work (the horizon read back, not searched again); one with another horizon is refused
    # before any, naming it.
    code, printed, err = cli(*arguments)
    assert code == 0 and all(f"{stage}: already there" in printed for stage in ("demonstrations", "generator", "policy"))
    assert "horizon:" not in printed
    code, _, err = cli(*arguments, "--horizon", horizon + 1)
    assert code == 2 and f"horizon {horizon} (recorded) vs {horizon + 1} (this run)" in err, err


def test_a_long_outside_task_gets_fewer_demonstrations_and_episodes_in_the_quickstart():
    # as many as fit the quickstart's budgets of steps, below the counts a short task gets
    assert outside_demo_episodes(89) == outside_demo_episodes(OUTSIDE_DEMO_STEPS // 1000) == 1000
    assert outside_demo_episodes(500) == OUTSIDE_DEMO_STEPS // 500 < outside_demo_episodes(400) < 1000
    assert outside_demo_episodes(10**6) == 4  # the fewest precision and recall take
    task = resolve_task("test_external:TestExternal/PointGoal-v0")
    assert outside_task_settings(task)[:2] == outside_task_settings(task, OUTSIDE_POLICY_STEPS // 3000)[:2] == (3000, 64)
    assert outside_task_settings(task, 500)[0] == OUTSIDE_POLICY_STEPS // 500 < 3000
    assert outside_task_settings(task, 10**6)[0] == 64  # one iteration


def test_the_quickstart_api_gives_an_outside_task_its_own_counts(quickstart_settings, tmp_path):
    task = "test_external:TestExternal/PointGoal-v0"
    made = quickstart_settings(tmp_path / "quick", task=task, expert=point_expert, horizon=HORIZON)
    # as the command line does: not the package tasks' 4000
    assert made["demonstrations"]["episodes"] == outside_demo_episodes(HORIZON) == 1000
    # its generator keeps the checkpoint that reconstructs the held-out demonstrations best, after at least 4800
    # minibatch steps; epochs given are trained as given
    assert made["generator"] == {
        "preset": QUICKSTART_PRESET, "epochs": 300, "eval_every": 10, "seed": 0, "selection": "reconstruction",
        "min_steps": 4800, "even_batches": True,
    }  # fmt: skip
    made = quickstart_settings(tmp_path / "quick", task=task, expert=point_expert, horizon=HORIZON, epochs=7)
    assert (made["generator"]["epochs"], made["generator"]["min_steps"]) == (7, 0)


def test_quickstart_refuses_an_expert_for_a_package_task_and_an_outside_task_without_one(cli, tmp_path):
    out = tmp_path / "quick"
    for arguments, message in (
        (("--task", "hockey", "--expert", "test_external:point_expert"), "expert applies to a task from outside the package"),
        (("--task", "hockey", "--horizon", 10), "horizon applies to a task from outside the package"),
        (("--task", "TestExternal/PointGoal-v0"), "give its expert (expert=, --expert MODULE:FUNCTION)"),
        (("--task", "TestExternal/PointGoal-v0", "--expert", "test_external:point_expert", "--horizon", 30), "horizon 30"),
    ):
        code, _, err = cli("quickstart", *arguments, "--out", out, "--no-progress-bar")
        assert code == 2 and message in err, (arguments, err)
        assert not out.exists()


@pytest.mark.slow
@pytest.mark.skipif(not metaworld.installed(), reason=metaworld.INSTALL_HINT)
def test_quickstart_of_a_metaworld_task_writes_its_report_and_a_policy_that_loads(cli, tmp_path, monkeypatch):
    out = tmp_path / "quick"
    # 8 held-out resets instead of 200 (each a Meta-World episode of up to 500 steps): the count is the point env's test's
    monkeypatch.setattr("sb3_genrl.study.quickstart.HELD_OUT_RESETS", 8)
    # and the horizon found from 8 of the expert's seeded resets instead of 100 (each an episode of 500 steps)
    monkeypatch.setattr("sb3_genrl.study.quickstart.expert_horizon", functools.partial(expert_horizon, resets=8))
    code, printed, err = cli(
        "quickstart", "--task", "metaworld/reach-v3", "--out", out, "--demo-episodes", 4, "--epochs", 2,
        "--episodes", 64, "--no-progress-bar", "--device", "cpu",
    )  # fmt: skip
    assert code == 0, err
    # Meta-World's defaults: demonstrations of its scripted expert as long as its success takes to settle (reach-v3's
    # within 100 of the env's 500 steps), and its generator preset
    info = dataset_info(out / "demonstrations")
    found = json.loads((out / "horizon.json").read_text())
    horizon = found["horizon"]
    assert info["horizon"] == horizon < 100 and found["resets"] == 8 and info["expert"].endswith(":MetaWorldExpert")
    assert json.loads((out / "vae.stage.json").read_text())["preset"] == metaworld.GENERATOR_PRESET
    summary = json.loads((out / "summary.json").read_text())
    success = [key for key in summary if "success" in key]
    assert success and all(isinstance(summary[key], float) and 0.0 <= summary[key] <= 1.0 for key in success)
    assert f"**{summary['held_out_success']:.1%}**" in (out / "report.md").read_text()
    assert f"held-out seeded resets is {summary['held_out_success']:.1%}" in printed and summary["held_out_resets"] == 8
    model = GenRL.load(out / "policy" / "genrl_policy.zip", device="cpu")
    env = make_task_env("metaworld/reach-v3", horizon=horizon)
    context, _ = env.reset(seed=0)
    action, _ = model.predict(context, deterministic=True)
    assert action.shape == (model.generator.latent_dim,) and model.generator.horizon == horizon


def test_genrl_evaluate_takes_an_outside_task_and_plays_its_prior_rollout_as_long_as_the_data(cli, tmp_path):
    demos = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 12, tmp_path / "demos", horizon=12)
    code, _, err = cli(
        "train-generator", "--data", demos, "--preset", "VAE1", "--epochs", 2, "--batch-size", 8, "--eval-every", 2,
        "--out", tmp_path / "vae.pt", "--no-progress-bar",
    )  # fmt: skip
    assert code == 0, err
    code, printed, err = cli(
        "evaluate", tmp_path / "vae.pt", "--data", demos, "--task", "test_external:TestExternal/PointGoal-v0", "--n", 8,
        "--dwpr-n", 8, "--contexts", 3, "--draws", 2, "--device", "cpu", "--out", tmp_path / "evaluation",
    )  # fmt: skip
    assert code == 0, err
    assert "is a task from outside the package: the prior rollout plays its 3 x 2 episodes" in printed
    row = json.loads((tmp_path / "evaluation" / "results.json").read_text())[0]
    assert row["prior_episodes"] == 6 and 0.0 <= row["prior_success"] <= 1.0
    # the rollout's env ends with the data's 12-step trajectories: none of the env's 20 steps is held after them
    env = LatentActionWrapper(_outside_env_maker("TestExternal/PointGoal-v0", demos)(), load(tmp_path / "vae.pt"))
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(env.generator.latent_dim, dtype=np.float32))
    assert (info["steps_played"], info["hold_steps"]) == (12, 0)


def test_train_policy_of_an_outside_task_starts_from_its_demonstrations(cli, tmp_path):
    demos = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 24, tmp_path / "demos", seed=1)
    generator = train_generator(demos, preset="VAE1", epochs=60, batch_size=8, eval_every=60, out=tmp_path / "vae.pt")
    arguments = ("--generator", tmp_path / "vae.pt", "--episodes", 16, "--batch-episodes", 16, "--checkpoint-every", 0)
    code, _, err = cli("train-policy", "--task", "TestExternal/PointGoal-v0", *arguments, "--out", tmp_path / "none")
    assert code == 2 and "genrl train-policy --data DIR" in err and not (tmp_path / "none").exists()
    errors = {}
    for name, extra in (("fitted", ("--data", demos)), ("defaults", ("--library-defaults",))):
        code, _, err = cli(
            "train-policy", "--task", "TestExternal/PointGoal-v0", *arguments, *extra, "--out", tmp_path / name,
            "--no-progress-bar",
        )  # fmt: skip
        assert code == 0, err
        model = GenRL.load(tmp_path / name / "genrl_policy.zip", device="cpu")
        contexts, latents = DemonstrationCallback(demos, keep=False).pulls(
            generator, model.observation_space, model.latent_clip
        )
        means = model.predict(contexts.numpy(), deterministic=True)[0]
        errors[name] = float(np.abs(means - latents.numpy()).mean())
    # the entry-less task's settings fit the policy's mean to the demonstrations' latent codes before the first
    # iteration; GenRL's defaults alone start from a mean near 0
    assert errors["fitted"] < 0.5 * errors["defaults"], errors
    # and search around that fit with a spread kept at 0.37 prior standard deviations; GenRL's own starts at 1.0
    spreads = {name: GenRL.load(tmp_path / name / "genrl_policy.zip", device="cpu").policy.log_std for name in errors}
    assert torch.equal(spreads["fitted"], torch.full_like(spreads["fitted"], -1.0))
    assert not torch.equal(spreads["defaults"], spreads["fitted"])
    # and refit the mean to the pulls that solved their own reset, without relabelling (the env reports no
    # info["hindsight"]; history 1 would refuse it at the first pull)
    fitted = GenRL.load(tmp_path / "fitted" / "genrl_policy.zip", device="cpu")
    assert fitted.hindsight_kwargs == {"history": 0, "refit_every": 256, "refit_start": 512} and fitted.refits is not None
    assert fitted.success_kl_floor == 0.1  # and scale the KL bound by the batch's failed share
    assert GenRL.load(tmp_path / "defaults" / "genrl_policy.zip", device="cpu").success_kl_floor is None


gym.register("TestExternal/PointGoalOwn-v0", entry_point=PointGoalEnv, max_episode_steps=HORIZON)


class UnboundedPointGoalEnv(PointGoalEnv):
    """Declares an unbounded observation box, as Gymnasium-Robotics' Fetch tasks do."""

    def __init__(self) -> None:
        super().__init__()
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(4,), dtype=np.float32)


gym.register("TestExternal/PointGoalUnbounded-v0", entry_point=UnboundedPointGoalEnv, max_episode_steps=HORIZON)


def test_the_demonstrations_scale_the_policys_unbounded_contexts_once_and_the_policy_keeps_them(tmp_path):
    task = "TestExternal/PointGoalUnbounded-v0"
    demos = record_demonstrations(task, point_expert, 24, tmp_path / "demos", seed=1)
    generator = train_generator(demos, preset="VAE1", epochs=5, batch_size=8, eval_every=5, out=tmp_path / "vae.pt")
    model = GenRL(LatentActionWrapper(gym.make(task), generator), generator, n_steps=8, seed=0, device="cpu")
    callback = DemonstrationCallback(demos, fit_steps=20, keep=False, scale_contexts=True)
    contexts = callback.pulls(generator, model.observation_space, model.latent_clip)[0].numpy().astype(np.float64)
    model.learn(8, callback=callback)
    scaler = model.policy.features_extractor
    # the goal (which the demonstrations vary) centred on their mean and scaled by their standard deviation; the
    # start position (the same in every one) only centred
    assert np.ptp(contexts[:, :2], axis=0).min() > 0.5 and np.ptp(contexts[:, 2:], axis=0).max() == 0
    np.testing.assert_allclose(scaler.centre.numpy(), contexts.mean(axis=0), atol=1e-6)
    np.testing.assert_allclose(scaler.half_width.numpy(), [*contexts[:, :2].std(axis=0, ddof=1), 1.0, 1.0], rtol=1e-5)
    features = scaler(torch.as_tensor(contexts, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(features[:, :2].mean(axis=0), 0.0, atol=1e-5)
    np.testing.assert_allclose(features[:, :2].std(axis=0, ddof=1), 1.0, rtol=1e-5)
    # the policy's value head reads the same features (one extractor), and the scale is saved with the policy
    assert model.policy.vf_features_extractor is scaler
    model.save(tmp_path / "model")
    loaded = GenRL.load(tmp_path / "model", device="cpu")
    for name in ("centre", "half_width"):
        assert torch.equal(getattr(loaded.policy.features_extractor, name), getattr(scaler, name))
    np.testing.assert_array_equal(
        loaded.predict(contexts, deterministic=True)[0], model.predict(contexts, deterministic=True)[0]
    )
    # a run that goes on keeps its scale, even given other demonstrations
    scale = scaler.centre.clone(), scaler.half_width.clone()
    other = record_demonstrations(task, point_expert, 12, tmp_path / "other", seed=7)
    model.learn(8, callback=DemonstrationCallback(other, keep=False, scale_contexts=True), reset_num_timesteps=False)
    assert torch.equal(scaler.centre, scale[0]) and torch.equal(scaler.half_width, scale[1])
    # without the setting, an unbounded context passes unscaled
    plain = GenRL(LatentActionWrapper(gym.make(task), generator), generator, n_steps=8, seed=0, device="cpu")
    plain.learn(8, callback=DemonstrationCallback(demos, fit_steps=20, keep=False))
    assert not plain.policy.features_extractor.centre.any() and (plain.policy.features_extractor.half_width == 1).all()


def quiet_expert():
    """Makes :func:`point_expert` (a task's ``make_expert``)."""
    return point_expert


def unperturbed_maker(episodes, out_dir, *, seed, n_threads, progress_bar):
    """A task's own demonstration maker: the point expert unperturbed, from the reset seeds of ``seed + 1``."""
    return record_demonstrations(
        "TestExternal/PointGoalOwn-v0", point_expert, episodes, out_dir, seed=seed + 1, noise=0.0, n_threads=1
    )


@pytest.fixture
def named_tasks(monkeypatch):
    """The tasks named with register() in this test only."""
    monkeypatch.setattr(external, "_NAMED", {})
    return external


def test_the_package_tasks_and_a_users_make_their_demonstrations_through_the_one_entry(tmp_path, named_tasks):
    # the package's task: its TaskSpec's maker, the same dataset as make_demonstrations'
    made = make_demonstrations("hockey", 3, tmp_path / "made", seed=4, n_threads=1, progress_bar=False)
    entered = task_demonstrations("hockey", 3, tmp_path / "entered", seed=4, n_threads=1)
    for key, value in load_arrays(made).items():
        np.testing.assert_array_equal(load_arrays(entered)[key], value, err_msg=key)
    with pytest.raises(ValueError, match="noise applies to demonstrations recorded from an expert, not to hockey's own"):
        task_demonstrations("hockey", 3, tmp_path / "noisy", noise=0.1)
    # a user's task named with its own maker: made with it, by name; given an expert, recorded from the expert
    named_tasks.register(Task("point-own", "TestExternal/PointGoalOwn-v0", make_demonstrations=unperturbed_maker))
    own = task_demonstrations("point-own", 5, tmp_path / "own", seed=2)
    mine = unperturbed_maker(5, tmp_path / "mine", seed=2, n_threads=1, progress_bar=False)
    np.testing.assert_array_equal(load_actions(own), load_actions(mine))
    recorded = task_demonstrations("point-own", 5, tmp_path / "recorded", expert=point_expert, seed=2, n_threads=1)
    assert dataset_info(recorded)["noise"] == 0.3 and not np.array_equal(load_actions(recorded), load_actions(mine))


def test_a_task_named_with_register_takes_the_commands_by_its_name(cli, tmp_path, named_tasks, monkeypatch):
    task = named_tasks.register(Task("point", "TestExternal/PointGoal-v0", make_expert=quiet_expert, horizon=12))
    assert named_tasks.register(task) is task  # again: the same task
    assert resolve_task("point") is resolve_task("TestExternal/PointGoal-v0") is task
    assert _resolve_env_id("point") == ("TestExternal/PointGoal-v0", "point")
    for other, message in (
        (Task("hockey", "TestExternal/PointGoalShove-v0"), "'hockey' already names another task"),
        (Task("point", "TestExternal/PointGoalShove-v0"), "'point' already names another task"),
        (Task("metaworld/point", "TestExternal/PointGoalShove-v0"), "are Meta-World's tasks"),
        (Task("nowhere", "NoSuch-v0"), "not a registered Gymnasium id"),
    ):
        with pytest.raises(ValueError, match=message):
            named_tasks.register(other)
    with pytest.raises(ValueError, match="make_expert must be callable"):
        Task("point", "TestExternal/PointGoal-v0", make_expert=point_expert(np.zeros(4)))
    # genrl demos by the name: the task's own expert, no --expert
    code, printed, err = cli(
        "demos", "--task", "point", "--episodes", 6, "--threads", 1, "--out", tmp_path / "d", "--no-progress-bar"
    )
    assert code == 0, err
    expected = record_demonstrations("TestExternal/PointGoal-v0", point_expert, 6, tmp_path / "e", n_threads=1)
    np.testing.assert_array_equal(load_actions(tmp_path / "d"), load_actions(expected))
    assert "6 demonstrations of point (20 steps) kept of" in printed
    # a module that names its task when imported: module:name, as module:Id for a Gymnasium id
    (tmp_path / "my_point_tasks.py").write_text(
        "from sb3_genrl.envs.external import Task, register\n"
        "from test_external import quiet_expert\n"
        "register(Task('point-mod', 'TestExternal/PointGoalShove-v0', make_expert=quiet_expert))\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    code, printed, err = cli(
        "demos", "--task", "my_point_tasks:point-mod", "--episodes", 2, "--threads", 1, "--out", tmp_path / "m",
        "--no-progress-bar",
    )  # fmt: skip
    assert code == 0, err
    assert dataset_info(tmp_path / "m")["env_id"] == "TestExternal/PointGoalShove-v0"
    # a named task with its own maker and neither an expert nor a horizon: the quickstart says what it needs
    named_tasks.register(Task("point-own", "TestExternal/PointGoalOwn-v0", make_demonstrations=unperturbed_maker))
    code, _, err = cli("quickstart", "--task", "point-own", "--out", tmp_path / "q", "--no-progress-bar")
    assert code == 2 and "makes its own demonstrations and has no expert to find a horizon" in err, err
    code, _, err = cli("demos", "--task", "point-own", "--noise", 0.1, "--out", tmp_path / "n", "--no-progress-bar")
    assert code == 2 and "--noise applies to demonstrations from an expert (--expert), not to point-own's own" in err, err
    assert not (tmp_path / "q").exists() and not (tmp_path / "n").exists()


def test_genrl_baseline_sac_learns_an_outside_task_from_its_demonstrations_and_resumes(cli, tmp_path, monkeypatch):
    from sb3_genrl.baselines.outside import evaluate_step_policy
    from stable_baselines3 import SAC

    from sb3_genrl.run import checkpoint

    demos, out = tmp_path / "demos", tmp_path / "sac"
    record_demonstrations("TestExternal/PointGoal-v0", point_expert, 6, demos, seed=1, n_threads=1)
    arguments = (
        "baseline", "sac", "--task", "test_external:TestExternal/PointGoal-v0", "--demos", demos, "--episodes", 5,
        "--checkpoint-every", 2, "--seed", 1, "--device", "cpu", "--out", out, "--no-progress-bar",
    )  # fmt: skip
    watch = checkpoint.EpisodeCheckpoint._on_rollout_start

    def killed(callback):  # a stop 5 steps into the 4th episode of 20 steps
        watch(callback)
        if callback.model.num_timesteps == 3 * HORIZON + 5:
            raise KeyboardInterrupt

    monkeypatch.setattr(checkpoint.EpisodeCheckpoint, "_on_rollout_start", killed)
    code, _, err = cli(*arguments)
    assert code == 130 and "rerun the same command to resume" in err, err
    assert json.loads((out / "checkpoint" / "state.json").read_text())["episodes"] == 2
    monkeypatch.undo()
    code, printed, err = cli(*arguments)  # the same command: resumed from episode 2
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["resumed_at_episodes"] == [2] and summary["episodes_played"] == 5 and summary["horizon"] == HORIZON
    assert summary["settings"] == {"policy": "MlpPolicy", "learning_starts": 0}
    assert summary["demo_transitions"] == 6 * HORIZON
    # scored closed loop on the held-out seeded resets GenRL's policies are scored on, as played here again
    model = SAC.load(out / "sac_policy.zip", device="cpu")
    assert model.num_timesteps == 5 * HORIZON
    again = evaluate_step_policy(
        lambda observation: model.predict(observation, deterministic=True)[0], "TestExternal/PointGoal-v0", horizon=HORIZON
    )
    assert summary["final_eval"] == again and again["resets"] == HELD_OUT_RESETS and again["seeds"][0] == HELD_OUT_SEED
    assert f"success on {HELD_OUT_RESETS} held-out seeded resets {again['success_rate']:.3f}" in printed
    # the expert itself, through the same scoring, solves them all: the score reads the env's success
    assert evaluate_step_policy(point_expert, "TestExternal/PointGoal-v0", horizon=HORIZON, resets=20)["success_rate"] == 1.0
    # what an outside task cannot take, refused before any work
    for algorithm, message in (("ppo", "takes sac and sac-no-prefill there"), ("latent-ppo", "needs a generator")):
        code, _, err = cli("baseline", algorithm, *arguments[2:-3], "--out", tmp_path / algorithm)
        assert code == 2 and message in err, err
        assert not (tmp_path / algorithm).exists()
    code, _, err = cli("baseline", "sac", "--task", "fetch-push", "--demos", demos, "--episodes", 2, "--out", tmp_path / "f")
    assert code == 2 and "genrl baseline takes a task on the package's arm" in err, err


gym.register(
    "TestExternal/PointGoalDict-v0",
    entry_point=lambda: gym.wrappers.TransformObservation(
        PointGoalEnv(), lambda observation: {"obs": observation}, gym.spaces.Dict({"obs": PointGoalEnv().observation_space})
    ),
    max_episode_steps=HORIZON,
)


def test_a_task_with_a_dict_context_is_refused_by_the_quickstart_before_any_stage(tmp_path):
    from sb3_genrl.genrl.demonstrations import demonstration_contexts
    from sb3_genrl.study.quickstart import quickstart

    with pytest.raises(ValueError, match=r"needs a Box context .* its observation space is Dict\('obs'"):
        quickstart(tmp_path / "q", task="TestExternal/PointGoalDict-v0", expert=lambda observation: np.zeros(2))
    assert not (tmp_path / "q").exists()
    # The callback's own check (genrl train-policy --data on such a task) names the reason, not another task's data.
    space = gym.make("TestExternal/PointGoalDict-v0").observation_space
    with pytest.raises(ValueError, match=r"demonstrations start GenRL on a Box context .* leave the demonstrations out"):
        demonstration_contexts(np.zeros((3, 4)), np.full((3, 2), np.nan), space)


def test_a_generator_longer_than_the_envs_episodes_is_refused_when_the_wrapper_is_built():
    from conftest import LinearGenerator

    from sb3_genrl import LatentActionWrapper

    with pytest.raises(ValueError, match=rf"horizon T = {HORIZON + 5} .* end after {HORIZON} \(its max_episode_steps\)"):
        LatentActionWrapper(gym.make("TestExternal/PointGoal-v0"), LinearGenerator(horizon=HORIZON + 5))
    longer = gym.make("TestExternal/PointGoal-v0", max_episode_steps=HORIZON + 5)  # the fix the message names
    assert LatentActionWrapper(longer, LinearGenerator(horizon=HORIZON + 5)).generator.horizon == HORIZON + 5
    LatentActionWrapper(gym.make("TestExternal/PointGoal-v0"), LinearGenerator(horizon=HORIZON - 2))  # shorter: held
