"""Meta-World, the optional extra: installed beside this package's MuJoCo, fixed for it only in the package's own env
classes, seeded resets, all 50 tasks by name, and the scripted experts closed loop and replayed open loop."""

import pathlib
import re
import subprocess
import sys
import tomllib
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from conftest import HANG_S
from gymnasium.utils.env_checker import check_env
from sb3_genrl.envs import metaworld as mw

ROOT = pathlib.Path(__file__).resolve().parents[1]
needs_metaworld = pytest.mark.skipif(not mw.installed(), reason=mw.INSTALL_HINT)
EXPERT_TASKS = ("reach-v3", "push-v3", "pick-place-v3")


def _test_command() -> str:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    return [line for line in readme.splitlines() if line.startswith("python3.11")][1]


def test_readme_test_command_installs_metaworld_without_its_dependencies_after_the_package():
    command = _test_command()
    install = f".venv/bin/pip install -q --no-deps metaworld=={mw.METAWORLD_VERSION}"
    assert install in command
    assert command.index(install) > command.index('.venv/bin/pip install -q -e ".[test,docs,robotics,zoo,metaworld]"')
    assert command.count("metaworld==") == 1  # never through a resolver, which would replace mujoco
    extra = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    assert not any(requirement.startswith(("metaworld", "mujoco")) for requirement in extra["metaworld"])


def test_unknown_task_names_are_refused_with_the_list():
    for make in (mw.make_metaworld_env, mw.metaworld_expert, mw.metaworld_env_id):
        with pytest.raises(ValueError, match=r"unknown Meta-World task 'push'; expected one of \[.*'push-v3'"):
            make("push")


def test_without_metaworld_no_ids_are_registered_and_making_an_env_says_how_to_install_it(monkeypatch):
    monkeypatch.setattr(mw, "installed", lambda: False)
    assert mw.register_metaworld_envs() == ()
    with pytest.raises(ImportError, match=re.escape("pip install --no-deps metaworld==3.1.1")):
        mw.make_metaworld_env("push-v3")


@needs_metaworld
def test_metaworld_installed_leaves_this_packages_mujoco_pin_in_place():
    pin = next(
        requirement.removeprefix("mujoco==")
        for requirement in tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["dependencies"]
        if requirement.startswith("mujoco==")
    )
    script = (
        "import importlib.metadata, metaworld, mujoco, sb3_genrl, sys; "
        "print(mujoco.__version__, importlib.metadata.version('mujoco'), importlib.metadata.version('metaworld'))"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=HANG_S)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == [pin, pin, mw.METAWORLD_VERSION]
    assert pin == "4.0.1"


@needs_metaworld
def test_import_sb3_genrl_registers_the_ids_without_importing_metaworld():
    script = (
        "import sys, gymnasium, sb3_genrl; "
        "print('metaworld' in sys.modules, sum(i.startswith('GenRL/metaworld-') for i in gymnasium.registry))"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=HANG_S)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["False", "50"]


@needs_metaworld
def test_upstream_mocap_welds_fail_on_this_mujoco_and_the_fix_writes_the_weld_mujoco_compiles():
    from metaworld.env_dict import ALL_V3_ENVIRONMENTS
    from metaworld.sawyer_xyz_env import SawyerMocapBase

    broadcast = r"could not broadcast input array from shape \(11,\) into shape \(12,\)"
    with pytest.raises(ValueError, match=broadcast):  # Meta-World's own class, unchanged by the package
        ALL_V3_ENVIRONMENTS["reach-v3"]()
    env = mw.make_metaworld_env("reach-v3").unwrapped
    assert env.model.eq_data.shape[1] == mujoco.mjNEQDATA == 12
    with pytest.raises(ValueError, match=broadcast):
        SawyerMocapBase.reset_mocap_welds(env)
    weld = env.model.eq_type == mujoco.mjtEq.mjEQ_WELD
    assert weld.sum() == 1
    env.model.eq_data[weld] = np.nan
    env.reset_mocap_welds()
    # the same weld written in MJCF, compiled by MuJoCo: anchor 0, relative pose (0, 0, 0, -1, 0, 0, 0), torque scale 5
    compiled = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body name='a' mocap='true'/><body name='b'><freejoint/><geom size='0.1'/></body>"
        "</worldbody><equality><weld body1='a' body2='b' anchor='0 0 0' relpose='0 0 0 -1 0 0 0' torquescale='5'/>"
        "</equality></mujoco>"
    )
    np.testing.assert_array_equal(env.model.eq_data[weld], compiled.eq_data)


@needs_metaworld
@pytest.mark.filterwarnings("ignore:.*maximum and minimum values are equal")  # constant goal coordinates of 7 tasks
def test_every_task_is_made_by_name_and_resets_and_steps():
    from metaworld.env_dict import ALL_V3_ENVIRONMENTS, MT10_V3
    from metaworld.sawyer_xyz_env import SawyerXYZEnv

    assert mw.TASK_NAMES == tuple(ALL_V3_ENVIRONMENTS) and len(mw.TASK_NAMES) == 50
    assert mw.MT10_TASK_NAMES == tuple(MT10_V3)
    assert mw.MAX_EPISODE_STEPS == SawyerXYZEnv.max_path_length == 500
    for name in mw.TASK_NAMES:
        env = mw.make_metaworld_env(name)
        assert env.spec.id == mw.metaworld_env_id(name) == f"GenRL/metaworld-{name}"
        assert env.spec.max_episode_steps == 500
        observation, _ = env.reset(seed=0)
        assert observation.shape == (39,) and observation in env.observation_space, name
        assert np.any(observation[-3:] != 0), name  # the goal is observed
        observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert observation in env.observation_space and np.isfinite(reward), name
        assert info["is_success"] == info["success"] and not terminated and not truncated, name
        env.close()


@needs_metaworld
def test_reset_with_one_seed_gives_one_task_and_other_seeds_other_tasks():
    env = mw.make_metaworld_env("push-v3")
    first, _ = env.reset(seed=3)
    for _ in range(20):
        env.step(env.action_space.sample())
    env.reset()  # an unseeded reset in between
    again, _ = env.reset(seed=3)
    np.testing.assert_array_equal(again, first)
    np.testing.assert_array_equal(mw.make_metaworld_env("push-v3").reset(seed=3)[0], first)  # another env
    positions = {tuple(env.reset(seed=seed)[0][[4, 5, 6, 36, 37, 38]]) for seed in range(5)}  # object and goal
    assert len(positions) == 5


@needs_metaworld
def test_env_passes_gymnasiums_env_checker():
    env = mw.make_metaworld_env("push-v3")
    # Meta-World's own design: unbounded object coordinates and a seed() method
    allowed = ("observation space minimum value is -infinity", "maximum value is infinity", "`seed` function is dropped")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    unexpected = [str(warning.message) for warning in caught if not any(text in str(warning.message) for text in allowed)]
    assert unexpected == []


@needs_metaworld
def test_registered_ids_take_metaworlds_arguments_and_refuse_others():
    env = gym.make("GenRL/metaworld-reach-v3", render_mode="rgb_array", width=32, height=24)
    env.reset(seed=0)
    assert env.render().shape == (24, 32, 3)
    with pytest.raises(ValueError, match=r"unknown argument\(s\) \['widht'\] of Meta-World task 'reach-v3'"):
        mw.make_metaworld_env("reach-v3", widht=32)


def _episode(env: gym.Env, seed: int, policy) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """One whole episode from ``reset(seed=seed)``: the actions, the observations after them, ``is_success``, and
    whether it ended terminated."""
    observation, _ = env.reset(seed=seed)
    actions, observations, successes = [], [], []
    terminated = truncated = False
    while not (terminated or truncated):
        action = policy(observation, len(actions))
        observation, _, terminated, truncated, info = env.step(action)
        actions.append(action)
        observations.append(observation)
        successes.append(info["is_success"])
    return np.array(actions), np.array(observations), np.array(successes), terminated


@needs_metaworld
@pytest.mark.parametrize("name", EXPERT_TASKS)
def test_expert_solves_a_seeded_reset_and_its_actions_replayed_open_loop_give_the_same_episode(name):
    env, expert = mw.make_metaworld_env(name), mw.metaworld_expert(name)
    actions, observations, successes, terminated = _episode(env, 0, lambda observation, step: expert(observation))
    # Meta-World's evaluation protocol: the episode ends (terminated) at its first success, within the 500 steps
    assert terminated and len(actions) < 500 and successes[-1] == 1.0 and not successes[:-1].any()
    assert all(action in env.action_space for action in actions)
    replayed_actions, replayed, replayed_successes, _ = _episode(env, 0, lambda observation, step: actions[step])
    np.testing.assert_array_equal(replayed, observations)  # the same episode, bit for bit
    np.testing.assert_array_equal(replayed_successes, successes)


@needs_metaworld
def test_without_termination_at_success_the_episode_runs_to_the_limit_as_metaworlds_training_env():
    # handle-press-v3's expert presses the handle down, and its task is solved only for a while
    expert = mw.metaworld_expert("handle-press-v3")
    actions, observations, successes, terminated = _episode(
        mw.make_metaworld_env("handle-press-v3"), 0, lambda observation, step: expert(observation)
    )
    env = mw.make_metaworld_env("handle-press-v3", terminate_on_success=False)
    all_actions, all_observations, all_successes, all_terminated = _episode(
        env, 0, lambda observation, step: expert(observation)
    )
    assert not all_terminated and len(all_actions) == 500  # truncated by the time limit only
    np.testing.assert_array_equal(all_observations[: len(observations)], observations)  # the same steps up to the end
    # is_success: solved at some step so far (Meta-World's measure), so it stays True after the first success, while
    # Meta-World's own success of the step does not
    assert all_successes[len(successes) - 1 :].all() and not all_successes[: len(successes) - 1].any()
    env.reset(seed=0)
    now = [env.step(action)[4]["success"] for action in all_actions]
    assert now[len(successes) - 1] == 1.0 and min(now[len(successes) :]) == 0.0
    with pytest.raises(ValueError, match="terminate_on_success must be True or False, got 'no'"):
        mw.make_metaworld_env("reach-v3", terminate_on_success="no")


@needs_metaworld
def test_the_step_that_ends_an_episode_at_its_success_earns_the_top_reward_and_the_training_env_metaworlds():
    # pick-place-v3 gives 10 only within 5 cm of the goal and counts a success within 7 cm: its expert's first success
    # earns less than 10 in Meta-World's reward
    expert = mw.metaworld_expert("pick-place-v3")
    ending, training = (
        mw.make_metaworld_env("pick-place-v3"),
        mw.make_metaworld_env("pick-place-v3", terminate_on_success=False),
    )
    actions, _, _, terminated = _episode(ending, 0, lambda observation, step: expert(observation))
    assert terminated
    rewards = {}
    for name, env in (("ending", ending), ("training", training)):
        env.reset(seed=0)
        rewards[name] = np.array([env.step(action)[1] for action in actions])
    np.testing.assert_array_equal(rewards["ending"][:-1], rewards["training"][:-1])  # Meta-World's before the end
    assert rewards["ending"][-1] == mw.SOLVED_REWARD == 10.0
    assert 0.0 < rewards["training"][-1] < 10.0  # Meta-World's own reward of the step: a near miss could earn as much
    assert rewards["ending"][:-1].max() < 10.0


@needs_metaworld
def test_the_door_open_expert_leaves_the_callers_observation_alone():
    env, expert = mw.make_metaworld_env("door-open-v3"), mw.metaworld_expert("door-open-v3")
    observation, _ = env.reset(seed=0)
    before = observation.copy()
    expert(observation)  # Meta-World's policy shifts the handle's position in the array it is given
    np.testing.assert_array_equal(observation, before)
