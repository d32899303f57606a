"""The goal-conditioned tasks: env checkers, and compute_reward against the plain tasks' own rewards."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from sb3_genrl.envs import TASKS, get_task
from sb3_genrl.envs.basketball import BasketballEnv, BasketballGoalEnv, scripted_throw
from sb3_genrl.envs.hockey import HockeyEnv, HockeyGoalEnv, scripted_hit
from stable_baselines3.common.env_checker import check_env as sb3_check_env

ALLOWED_SB3_WARNINGS = ("We recommend you to use a symmetric and normalized Box action space",)
CASES = {
    "hockey": (HockeyGoalEnv, HockeyEnv, [scripted_hit(strength=s, direction=d) for s, d in ((0.8, -0.2), (1.2, 0.3))]),
    # strengths 1.0 and 1.2 bounce the ball back up through the rim's height: 2 and 3 crossings
    "basketball": (BasketballGoalEnv, BasketballEnv, [scripted_throw(strength=s, yaw=0.3) for s in (0.6, 1.0, 1.2)]),
}


def test_every_task_has_its_goal_variant_registered():
    arm_tasks = {name: spec for name, spec in TASKS.items() if spec.demonstrations is None}  # Fetch: goal envs already
    for name, spec in arm_tasks.items():
        env = gym.make(spec.goal_env_id)
        assert isinstance(env.unwrapped, spec.env_class) and env.spec.max_episode_steps == spec.horizon
        assert sorted(env.observation_space.spaces) == ["achieved_goal", "desired_goal", "observation"]
        assert hasattr(env.unwrapped, "compute_reward"), name
    assert set(arm_tasks) == set(CASES)


@pytest.mark.parametrize("task", sorted(CASES))
def test_env_checkers_pass(task):
    env = gym.make(get_task(task).goal_env_id).unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    assert [str(w.message) for w in caught] == []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env)
    assert [str(w.message) for w in caught if not str(w.message).startswith(ALLOWED_SB3_WARNINGS)] == []


def play(env, trajectory, goal):
    """Step through a trajectory; the observations and the last step's reward and info."""
    observations = [env.reset(options={"goal": goal, "allow_outside_region": True})[0]]
    rewards = []
    for action in trajectory:
        obs, reward, terminated, _, info = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        if terminated:
            break
    return observations, np.array(rewards), info


@pytest.mark.parametrize("task", sorted(CASES))
def test_compute_reward_equals_the_plain_tasks_reward(task):
    goal_class, plain_class, trajectories = CASES[task]
    env, plain = goal_class(), plain_class()
    rng = np.random.default_rng(0)
    crossings = []
    for trajectory in trajectories:
        goal = plain.sample_goal(rng)
        observations, rewards, info = play(env, trajectory, goal)
        _, plain_rewards, plain_info = play(plain, trajectory, goal)
        assert len(rewards) == len(plain_rewards) == plain.horizon and info["terminal"]
        np.testing.assert_array_equal(rewards[:-1], 0.0)
        assert rewards[-1] == pytest.approx(plain_rewards[-1], abs=1e-12)
        np.testing.assert_array_equal(observations[-1]["achieved_goal"], plain_info["reached"])
        crossings.append(plain_info.get("crossings", 1))

        # Relabelled goals (the terminal achieved goal, goals near it, on the line from the robot through it, where
        # a bouncing ball's other crossings lie, and anywhere): the plain task played for each is the reference.
        final = observations[-1]["achieved_goal"]
        relabelled = np.concatenate(
            [
                final[None],
                final + rng.normal(0, 0.3, (4, 2)),
                final / np.linalg.norm(final) * np.linspace(0.5, 12.0, 8)[:, None],
                np.array([plain.sample_goal(rng) for _ in range(5)]),
            ]
        )
        batch = env.compute_reward(np.repeat(final[None], len(relabelled), 0), relabelled, [info] * len(relabelled))
        reference, _ = plain.play_trajectories(
            np.repeat(trajectory[None], len(relabelled), 0), relabelled, allow_outside_region=True
        )  # relabelled goals lie anywhere
        np.testing.assert_allclose(batch, reference, rtol=0, atol=1e-12)
        assert batch[0] == 0.0
        assert env.compute_reward(final, relabelled[3], info) == batch[3]
        # Before the end every reward is 0, whatever the goal.
        middle = observations[30]
        assert env.compute_reward(middle["achieved_goal"], relabelled[3], {"terminal": False}) == 0.0
    if task == "basketball":
        assert max(crossings) >= 2  # some throw crosses the rim's height more than once


@pytest.mark.parametrize("task", sorted(CASES))
def test_object_paths_match_the_step_path(task):
    goal_class, plain_class, trajectories = CASES[task]
    env = goal_class()
    goals = np.array([[1.0, 0.1], [3.0, -1.0]] if task == "hockey" else [[3.0, -1.0], [5.0, 2.0]])
    paths, infos = env.object_paths(np.stack(trajectories[:2]), goals)
    for trajectory, goal, path, info in zip(trajectories[:2], goals, paths, infos, strict=True):
        observations, rewards, step_info = play(env, trajectory, goal)
        np.testing.assert_array_equal(path, np.array([obs["achieved_goal"] for obs in observations]))
        assert info["terminal"] and env.compute_reward(path[-1], goal, info) == rewards[-1]
        assert np.array_equal(observations[5]["observation"][-1], np.float32(1 - 5 / env.horizon))


def test_compute_reward_bad_input():
    env = HockeyGoalEnv()
    with pytest.raises(ValueError, match="copy_info_dict"):
        env.compute_reward(np.zeros((2, 2)), np.ones((2, 2)), [{}, {}])
    with pytest.raises(ValueError, match="B infos"):
        env.compute_reward(np.zeros((2, 2)), np.ones((2, 2)), [{"terminal": True}])
    # An unstable episode scores the worst reward for every goal.
    assert env.compute_reward(np.zeros(2), np.zeros(2), {"terminal": True, "unstable": True}) == env.worst_reward
