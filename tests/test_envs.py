"""The hockey and basketball tasks: API contracts, meaningful physics, fast path == step path, bad input."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from sb3_genrl.envs import TASKS
from sb3_genrl.envs.basketball import BasketballEnv, scripted_throw
from sb3_genrl.envs.hockey import HockeyEnv, scripted_hit
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_genrl  # noqa: F401  (registers the tasks)

# SB3 recommends actions normalised to [-1, 1]; ours are joint position changes in radians, on purpose.
ALLOWED_SB3_WARNINGS = ("We recommend you to use a symmetric and normalized Box action space",)


@pytest.fixture(scope="module")
def hockey():
    return HockeyEnv()


@pytest.fixture(scope="module")
def basketball():
    return BasketballEnv()


def play_steps(env, trajectory, goal, seed=0):
    env.reset(seed=seed, options={"goal": goal})
    total, info, steps = 0.0, {}, 0
    for action in trajectory:
        _, reward, terminated, truncated, info = env.step(action)
        total += reward
        steps += 1
        assert not truncated
        if terminated:
            break
    return total, info, steps


@pytest.mark.parametrize("task", ["hockey", "basketball"])
def test_check_env_without_warnings(task):
    env = gym.make(TASKS[task].env_id).unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    assert [str(w.message) for w in caught] == []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env)
    unexpected = [str(w.message) for w in caught if not str(w.message).startswith(ALLOWED_SB3_WARNINGS)]
    assert unexpected == []


def test_registered_ids_and_spaces():
    hockey = gym.make("GenRL/Hockey-v0")
    basketball = gym.make("GenRL/Basketball-v0")
    assert hockey.spec.max_episode_steps == 69 and basketball.spec.max_episode_steps == 78
    assert hockey.observation_space.shape == (16,) and hockey.action_space.shape == (7,)
    obs, info = hockey.reset(seed=3)
    np.testing.assert_allclose(obs[:2], info["goal"], rtol=1e-6)


def test_goal_sampling_regions(hockey, basketball):
    rng = np.random.default_rng(0)
    goals = np.array([hockey.sample_goal(rng) for _ in range(2000)])
    assert goals[:, 0].min() >= 0.65 and goals[:, 0].max() <= 1.3
    assert goals[:, 1].min() >= -0.4 and goals[:, 1].max() <= 0.4
    assert np.ptp(goals[:, 0]) > 0.6 and np.ptp(goals[:, 1]) > 0.75
    baskets = np.array([basketball.sample_goal(rng) for _ in range(2000)])
    radius, angle = np.linalg.norm(baskets, axis=1), np.arctan2(baskets[:, 1], baskets[:, 0])
    assert radius.min() >= 1.0 and radius.max() <= 8.0 and radius.max() > 7.9
    assert angle.min() >= -np.pi / 2 and angle.max() <= np.pi / 2 and np.ptp(angle) > 3.0


def test_seeding_reproduces_goals():
    a, b = HockeyEnv(), HockeyEnv()
    np.testing.assert_array_equal(a.reset(seed=7)[0], b.reset(seed=7)[0])
    assert not np.array_equal(a.reset(seed=7)[0], a.reset(seed=8)[0])


def test_stronger_hit_sends_puck_further(hockey):
    distances = []
    for strength in (0.7, 1.0, 1.3):
        _, info = hockey.play_trajectory(scripted_hit(strength=strength), np.array([1.0, 0.0]))
        distances.append(info["reached"][0])
        assert info["table_contacts"] == 0 and not info["unstable"]
    start = hockey.initial_state_object_xy()[0]
    assert distances[0] > start + 0.2, "a hit must send the puck forward"
    assert distances[0] < distances[1] < distances[2]


def test_hit_direction_sets_puck_direction(hockey):
    ys = [hockey.play_trajectory(scripted_hit(direction=d), np.array([1.0, 0.0]))[1]["reached"][1] for d in (-0.4, 0.0, 0.4)]
    assert ys[0] > 0.1 and abs(ys[1]) < 0.05 and ys[2] < -0.1


def test_rewards_are_minus_documented_distances(hockey, basketball):
    goal = np.array([0.9, 0.1])
    reward, info = hockey.play_trajectory(scripted_hit(), goal)
    assert reward == pytest.approx(-np.linalg.norm(info["reached"] - goal))
    basket = np.array([3.0, 0.5])
    reward, info = basketball.play_trajectory(scripted_throw(), basket)
    assert info["crossings"] >= 1
    assert reward == pytest.approx(-np.linalg.norm(info["reached"] - basket))


def test_throw_lands_ball_metres_away(basketball):
    _, info = basketball.play_trajectory(scripted_throw(), np.array([3.0, 0.0]))
    assert info["crossings"] >= 1 and info["reached"][0] > 2.0
    _, info = basketball.play_trajectory(scripted_throw(yaw=0.6), np.array([3.0, 0.0]))
    assert info["reached"][1] > 1.0, "turning the base must turn the throw"


def test_ball_that_never_crosses_gets_worst_reward(basketball):
    reward, info = basketball.play_trajectory(np.zeros((78, 7)), np.array([3.0, 0.0]))
    assert info["crossings"] == 0 and reward == basketball.worst_reward


def test_blade_pushed_into_table_counts_contacts(hockey):
    trajectory = np.zeros((69, 7))
    trajectory[10:16, 1] = 0.05  # lean the shoulder forward: the stick is pressed down onto the table
    _, info = hockey.play_trajectory(trajectory, np.array([1.0, 0.0]))
    assert info["table_contacts"] >= 40
    _, info = hockey.play_trajectory(np.zeros((69, 7)), np.array([1.0, 0.0]))
    assert info["table_contacts"] == 0


@pytest.mark.parametrize(
    "make, trajectory", [(HockeyEnv, scripted_hit(strength=1.2, direction=0.3)), (BasketballEnv, scripted_throw(yaw=-0.4))]
)
def test_fast_path_equals_step_path(make, trajectory):
    env = make()
    goal = env.sample_goal(np.random.default_rng(1))
    step_reward, step_info, _ = play_steps(env, trajectory, goal)
    fast_reward, fast_info = env.play_trajectory(trajectory, goal)
    assert step_reward == fast_reward
    assert step_info.keys() == fast_info.keys()
    for key, value in step_info.items():
        np.testing.assert_array_equal(value, fast_info[key])
    rewards, infos = env.play_trajectories(np.stack([trajectory] * 3), goal, n_threads=2)
    assert np.all(rewards == fast_reward)


def test_batch_in_threads_matches_single(hockey):
    rng = np.random.default_rng(0)
    batch = np.stack([scripted_hit(strength=s, direction=d) for s, d in rng.uniform([0.6, -0.4], [1.3, 0.4], (6, 2))])
    goals = np.array([hockey.sample_goal(rng) for _ in range(6)])
    one, _ = hockey.play_trajectories(batch, goals, n_threads=1)
    two, _ = hockey.play_trajectories(batch, goals, n_threads=2, chunk=4)
    np.testing.assert_array_equal(one, two)


def test_joint_limits_clip_and_report(hockey):
    trajectory = np.zeros((69, 7))
    trajectory[:, 6] = 0.2  # 13.8 rad of wrist roll requested, the joint stops at 2.9
    _, info = hockey.play_trajectory(trajectory, np.array([1.0, 0.0]))
    assert info["joint_limit_clipped"] and info["clipped_steps"] > 40
    env = HockeyEnv()
    env.reset(seed=0)
    for action in trajectory:
        obs, *_ = env.step(action)
    assert obs[2 + 6] == pytest.approx(2.9, abs=0.05)


def test_bad_input_raises_clear_errors(hockey):
    with pytest.raises(ValueError, match=r"shape \(B, 69, 7\)"):
        hockey.play_trajectories(np.zeros((2, 68, 7)), np.zeros(2))
    with pytest.raises(ValueError, match="non-finite"):
        bad = np.zeros((69, 7))
        bad[3, 2] = np.nan
        hockey.play_trajectory(bad, np.zeros(2))
    hockey.reset(seed=0)
    with pytest.raises(ValueError, match="non-finite"):
        hockey.step(np.full(7, np.inf))
    with pytest.raises(ValueError, match=r"shape \(7,\)"):
        hockey.step(np.zeros(6))
    from sb3_genrl.envs import make_task

    with pytest.raises(ValueError, match="unknown task 'golf'"):
        make_task("golf")


def test_unstable_simulation_ends_with_worst_reward():
    env = HockeyEnv()
    env.model.opt.timestep = 0.2  # far beyond what the stiff position servos tolerate
    reward, info = env.play_trajectory(scripted_hit(), np.array([1.0, 0.0]))
    assert info["unstable"] and reward == env.worst_reward and np.isfinite(reward)
    reward, info, steps = play_steps(env, scripted_hit(), np.array([1.0, 0.0]))
    assert info["unstable"] and reward == env.worst_reward and steps < 69


def test_rgb_array_render():
    env = gym.make("GenRL/Hockey-v0", render_mode="rgb_array", width=64, height=48)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8 and frame.std() > 5
    env.close()


def test_episode_frames_every_other_step_are_every_steps_frames_at_even_steps():
    env = gym.make("GenRL/Hockey-v0", render_mode="rgb_array", width=32, height=24).unwrapped
    goal = env.sample_goal(np.random.default_rng(0))
    trajectory = scripted_hit()
    every_step = env.episode_frames(trajectory, goal)
    every_other = env.episode_frames(trajectory, goal, every=2)
    # the first frame, then the 2nd, 4th, ... control step's of the motion, then those of the settle phase
    played = min(len(trajectory), len(every_step) - 1)
    expected = [every_step[0], *every_step[2 : played + 1 : 2], *every_step[played + 2 :: 2]]
    assert len(every_step) > 60 and len(every_other) == len(expected)
    for got, want in zip(every_other, expected, strict=True):
        np.testing.assert_array_equal(got, want)
    env.close()


def test_throw_family_spans_the_basket_region_smoothly(basketball):
    # The expert's strengths reach past the near (1 m) and far (8 m) edges of the region at the extreme yaws too,
    # and the landing distance grows smoothly with the strength: no fold, no jump between nearby strengths.
    from sb3_genrl.envs.basketball import BASKETBALL_STRENGTH, BASKETBALL_YAW

    strengths = np.linspace(*BASKETBALL_STRENGTH, 12)
    for yaw in (-BASKETBALL_YAW, 0.0, BASKETBALL_YAW):
        _, infos = basketball.play_trajectories(
            np.stack([scripted_throw(strength=s, yaw=yaw) for s in strengths]), np.zeros(2), allow_outside_region=True
        )  # (the goal plays no role)
        reached = np.array([info["reached"] for info in infos])
        assert all(info["crossings"] >= 1 and not info["joint_limit_clipped"] for info in infos)
        radius, bearing = np.linalg.norm(reached, axis=1), np.arctan2(reached[:, 1], reached[:, 0])
        assert radius[0] < 1.0 and radius[-1] > 8.0
        steps = np.diff(radius)
        assert np.all(steps > 0.2) and np.all(steps < 1.0)
        np.testing.assert_allclose(bearing[radius > 1.0], yaw, atol=np.radians(2))


def test_play_trajectories_refuses_a_chunk_or_thread_count_that_is_not_a_positive_integer(hockey):
    batch, goal = np.stack([scripted_hit(strength=s) for s in (0.8, 1.0, 1.2)]), np.array([1.0, 0.0])
    for name, value in (("chunk", -1), ("chunk", 0), ("chunk", 1.5), ("n_threads", 0), ("n_threads", 2.5), ("n_threads", "2")):
        with pytest.raises(ValueError, match=f"{name} must be a positive integer, got {value!r}"):
            hockey.play_trajectories(batch, goal, **{name: value})
    rewards, infos = hockey.play_trajectories(batch, goal, chunk=2)
    assert len(infos) == 3
    np.testing.assert_array_equal(rewards, [hockey.play_trajectory(t, goal)[0] for t in batch])


def test_goals_outside_the_goal_region_or_of_wrong_length_are_refused(hockey, basketball):
    batch = np.stack([scripted_hit()] * 2)
    for bad in ([1.0], [1.0, 0.0, 0.0], [[1.0, 0.0]], [[1.0], [1.0]]):
        with pytest.raises(ValueError, match=r"goals must have shape \(2,\) or \(2, 2\)"):
            hockey.play_trajectories(batch, np.array(bad))
    with pytest.raises(ValueError, match=r"options\['goal'\] must have shape \(2,\)"):
        hockey.reset(options={"goal": [1.0]})
    for env, outside in ((hockey, [0.5, 0.0]), (hockey, [1.0, 0.41]), (basketball, [-1.0, 0.0])):
        with pytest.raises(ValueError, match="outside the goal region"):
            env.reset(options={"goal": outside})
        with pytest.raises(ValueError, match="outside the goal region"):
            env.play_trajectories(np.zeros((2, env.horizon, 7)), np.array([env.goal_low, outside]))
    with pytest.raises(ValueError, match="outside the goal region"):
        hockey.play_trajectory(scripted_hit(), np.array([0.5, 0.0]))
    corner = np.array([0.65, 0.4], dtype=np.float32)  # float32 goals on the region's edge are inside
    assert hockey.reset(options={"goal": corner})[1]["goal"].tolist() == corner.astype(np.float64).tolist()
    # Hindsight goals (the points demonstrations reached) may lie outside the region when asked for.
    reward, info = hockey.play_trajectory(scripted_hit(), np.array([0.5, 0.0]), allow_outside_region=True)
    assert reward == pytest.approx(-np.linalg.norm(info["reached"] - [0.5, 0.0]))
    hockey.reset(options={"goal": [0.5, 0.0], "allow_outside_region": True})
    assert hockey.goal.tolist() == [0.5, 0.0]


def test_hindsight_goal_is_the_point_reached_and_rewards_zero(hockey, basketball):
    # The relabelled goal is one the same trajectory solves: replayed for it, the reward is 0 (its distance to itself).
    for env, trajectory, goal in (
        (hockey, scripted_hit(strength=1.1, direction=0.2), np.array([1.0, 0.0])),
        (basketball, scripted_throw(yaw=0.3), np.array([3.0, 0.0])),
    ):
        reward, info = env.play_trajectory(trajectory, goal)
        context, relabelled_reward = env.hindsight(info)
        assert context.dtype == np.float32 and context.shape == (2,) and relabelled_reward == 0.0
        np.testing.assert_allclose(context, info["reached"], atol=1e-6)
        assert reward < -0.05  # the original goal was missed
        replayed, _ = env.play_trajectory(trajectory, context.astype(np.float64), allow_outside_region=True)
        assert replayed == pytest.approx(0.0, abs=1e-6)


def test_no_hindsight_goal_without_a_crossing_or_for_an_unstable_simulation(basketball):
    _, info = basketball.play_trajectory(np.zeros((78, 7)), np.array([3.0, 0.0]))
    assert info["crossings"] == 0 and basketball.hindsight(info) is None
    env = HockeyEnv()
    env.model.opt.timestep = 0.2  # unstable, as above
    _, info = env.play_trajectory(scripted_hit(), np.array([1.0, 0.0]))
    assert info["unstable"] and env.hindsight(info) is None


def test_basketball_refuses_goals_inside_its_bounding_box_but_outside_its_half_annulus(basketball):
    from sb3_genrl.envs.basketball import in_goal_region

    for outside in ([0.0, 0.0], [0.5, 0.0], [7.9, 7.9], [0.6, -0.6]):  # too near, too far, behind the robot's reach
        assert not in_goal_region(np.array(outside))[0]
        with pytest.raises(ValueError, match=r"outside the goal region \(radius in \[1.0, 8.0\] m"):
            basketball.reset(options={"goal": outside})
        with pytest.raises(ValueError, match="outside the goal region"):
            basketball.play_trajectory(np.zeros((basketball.horizon, 7)), np.array(outside))
    edge = np.array([8 * np.cos(np.pi / 4), 8 * np.sin(np.pi / 4)], dtype=np.float32)  # float32 goals on the rim pass
    for inside in (edge, [1.0, 0.0], [0.0, 8.0], [0.0, -1.0]):
        assert basketball.reset(options={"goal": inside})[1]["goal"].tolist() == np.asarray(inside, np.float64).tolist()
    reward, _ = basketball.play_trajectory(np.zeros((basketball.horizon, 7)), np.array([0.0, 0.0]), allow_outside_region=True)
    assert np.isfinite(reward)
