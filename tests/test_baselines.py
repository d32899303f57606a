"""PPO with behaviour cloning, SAC with a prefilled replay buffer, and the comparison of runs."""

import json
import os

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from sb3_genrl.baselines import FEEDBACK_BASELINES
from sb3_genrl.baselines.bc import STD_RANGE, actor_mean, fit_actor, split_episodes
from sb3_genrl.baselines.compare import compare_runs
from sb3_genrl.baselines.evaluation import evaluate_trained, load_trained
from sb3_genrl.baselines.feedback import (
    add_time_feature,
    evaluate_feedback_policy,
    held_out_goals,
    make_feedback_env,
    open_loop_rewards,
)
from sb3_genrl.baselines.her import goal_episodes
from sb3_genrl.baselines.hyperparameters import baseline_settings
from sb3_genrl.baselines.models import normalized_policy, ppo_with_behaviour_cloning, sac_her_with_demonstrations
from sb3_genrl.baselines.normalization import STD_FLOOR, NormalizedFlatten
from sb3_genrl.baselines.prefill import prefill_replay_buffer
from sb3_genrl.baselines.train import train_baseline
from sb3_genrl.envs.demonstrations import make_demonstrations
from sb3_genrl.envs.hockey import HOCKEY_HORIZON, HockeyEnv, scripted_hit
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.policies import ActorCriticPolicy

from sb3_genrl.cli import main
from sb3_genrl.curves import MONITOR_FILE, read_monitor
from sb3_genrl.hyperparams import EVAL_GOAL_SEED


def demo_transitions(n_episodes: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Scripted hits played step by step, each labelled with the goal it reached (as the demonstration sets are)."""
    env = HockeyEnv()
    rng = np.random.default_rng(seed)
    keys = ("observations", "actions", "rewards", "next_observations", "dones")
    out = {key: [] for key in keys}
    for _ in range(n_episodes):
        # float32, as the demonstration generator stores and simulates them
        trajectory = scripted_hit(strength=rng.uniform(0.8, 1.2), direction=rng.uniform(-0.4, 0.4)).astype(np.float32)
        _, info = env.play_trajectory(trajectory, np.zeros(2), allow_outside_region=True)
        obs, _ = env.reset(options={"goal": info["reached"], "allow_outside_region": True})
        for action in trajectory:
            next_obs, reward, terminated, _, _ = env.step(action)
            for key, value in zip(keys, (obs, action, reward, next_obs, terminated), strict=True):
                out[key].append(value)
            obs = next_obs
    return {key: np.asarray(value, dtype=np.float32) for key, value in out.items()}


@pytest.fixture(scope="module")
def demos():
    return demo_transitions(12)


def test_normalisation_statistics_are_saved_and_reloaded_with_the_model(demos, tmp_path):
    transitions = add_time_feature(demos, HOCKEY_HORIZON)
    model = PPO(
        "MlpPolicy",
        make_feedback_env("hockey"),
        seed=0,
        device="cpu",
        policy_kwargs=normalized_policy(baseline_settings("ppo", "hockey")[1], transitions["observations"]),
    )
    model.save(tmp_path / "model.zip")
    loaded = PPO.load(tmp_path / "model.zip", device="cpu")
    # Statistics computed here, independently: float64 mean and std, std floored.
    observations = transitions["observations"].astype(np.float64)
    mean, std = observations.mean(axis=0), np.maximum(observations.std(axis=0), STD_FLOOR)
    extractor = loaded.policy.features_extractor
    assert isinstance(extractor, NormalizedFlatten)
    np.testing.assert_allclose(extractor.mean.numpy(), mean, rtol=1e-6)
    np.testing.assert_allclose(extractor.std.numpy(), std, rtol=1e-6)
    batch = transitions["observations"][::50]
    with th.no_grad():
        features = extractor(th.as_tensor(batch)).numpy()
    np.testing.assert_allclose(features, np.clip((batch - mean) / std, -10, 10), rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(loaded.predict(batch, deterministic=True)[0], model.predict(batch, deterministic=True)[0])


def test_early_stopping_stops_on_a_rising_heldout_loss():
    # The held-out actions are the negated training actions: fitting the training set raises the held-out loss.
    rng = np.random.default_rng(0)
    observations = rng.normal(size=(512, 4)).astype(np.float32)
    actions = np.tanh(observations[:, :2] @ np.array([[0.3, -0.2], [0.1, 0.4]], dtype=np.float32))
    th.manual_seed(0)
    policy = ActorCriticPolicy(
        gym.spaces.Box(-10, 10, (4,), np.float32),
        gym.spaces.Box(-1, 1, (2,), np.float32),
        lr_schedule=lambda _: 1e-3,
        net_arch=[32, 32],
    )
    record = fit_actor(
        policy,
        (observations, actions),
        (observations, -actions),
        max_epochs=100,
        patience=4,
        batch_size=64,
        learning_rate=3e-3,
    )
    losses = record["heldout_loss"]
    assert record["epochs"] == record["best_epoch"] + 4 < 100
    assert losses[record["best_epoch"] - 1] == min(losses) and losses[-1] > min(losses)
    # The best epoch's weights are restored: the held-out loss recomputed now is the best one.
    with th.no_grad():
        mean = actor_mean(policy, th.as_tensor(observations)).numpy()
    residuals = -actions - mean
    assert np.mean(residuals**2) == pytest.approx(min(losses), rel=1e-5)
    np.testing.assert_allclose(policy.log_std.exp().detach().numpy(), np.clip(residuals.std(axis=0), *STD_RANGE), rtol=1e-4)


@pytest.mark.slow
def test_behaviour_cloning_reproduces_heldout_demonstrations_open_loop():
    transitions = add_time_feature(demo_transitions(40, seed=1), HOCKEY_HORIZON)
    model, record = ppo_with_behaviour_cloning(
        make_feedback_env("hockey"),
        transitions,
        task="hockey",
        seed=0,
        device="cpu",
        bc_kwargs={"holdout": 0.1, "batch_size": 64, "patience": 20},
    )
    assert record["heldout_episodes"] == 4 and record["best_epoch"] > 1
    _, heldout = split_episodes(transitions["dones"], 0.1, seed=0)
    observations = transitions["observations"][heldout].reshape(4, HOCKEY_HORIZON, -1)
    actions = transitions["actions"][heldout].reshape(4, HOCKEY_HORIZON, 7)
    with th.no_grad():
        cloned = actor_mean(model.policy, th.as_tensor(observations.reshape(-1, observations.shape[-1]))).numpy()
    cloned = cloned.reshape(actions.shape)
    # The cloned policy's actions along each held-out demonstration's own states, played open loop, against the
    # arm holding still (each demonstration reached its goal exactly).
    goals = observations[:, 0, :2]
    env = HockeyEnv()
    cloned_rewards, _ = env.play_trajectories(cloned, goals)
    zero_rewards, _ = env.play_trajectories(np.zeros_like(cloned), goals)
    assert np.mean((cloned - actions) ** 2) < 0.05 * np.mean(actions**2)  # the zero action's error is 1x
    assert np.all(cloned_rewards > zero_rewards) and np.mean(-cloned_rewards) < 0.25 * np.mean(-zero_rewards)


def test_prefilled_buffer_holds_exactly_the_demonstrations(demos):
    model = SAC("MlpPolicy", HockeyEnv(), buffer_size=5000, learning_starts=0, seed=0, device="cpu")
    n = prefill_replay_buffer(model, demos)
    buffer = model.replay_buffer
    assert n == len(demos["observations"]) == buffer.size()
    np.testing.assert_array_equal(buffer.observations[:n, 0], demos["observations"])
    np.testing.assert_array_equal(buffer.next_observations[:n, 0], demos["next_observations"])
    np.testing.assert_allclose(model.policy.unscale_action(buffer.actions[:n, 0]), demos["actions"], atol=1e-6)
    np.testing.assert_array_equal(buffer.rewards[:n, 0], demos["rewards"])
    np.testing.assert_array_equal(buffer.dones[:n, 0], demos["dones"])
    assert not buffer.observations[n:].any()
    with pytest.raises(ValueError, match="do not fit"):
        prefill_replay_buffer(SAC("MlpPolicy", HockeyEnv(), buffer_size=10, device="cpu"), demos)
    with pytest.raises(ValueError, match="lack"):
        prefill_replay_buffer(model, {"observations": demos["observations"]})


@pytest.mark.slow
@pytest.mark.parametrize("algorithm", FEEDBACK_BASELINES)
def test_baselines_run_end_to_end(algorithm, demos, tmp_path):
    change = {"n_steps": 128} if algorithm == "ppo" else {"gamma": 0.95}  # a user's change to the zoo's settings
    summary = train_baseline(
        algorithm,
        "hockey",
        episodes=12,
        out_dir=tmp_path,
        demos=demos,
        demo_episodes=10,
        bc_kwargs={"max_epochs": 2},
        eval_goals=2,
        window=5,
        algorithm_kwargs=change,
        device="cpu",
    )
    assert summary["episodes_played"] >= 12 and summary["demo_transitions"] == 10 * 69
    episodes = read_monitor(tmp_path / MONITOR_FILE)
    assert len(episodes["return"]) == summary["episodes_played"] and np.all(episodes["length"] == 69)
    assert np.all(episodes["table_contacts"] >= 0) and np.all(episodes["return"] <= 0)
    # The return of a hockey episode is its terminal reward: minus the distance it reports (Monitor keeps 6
    # decimals), or the worst reward of an unstable simulation.
    assert np.all(np.isclose(episodes["return"], -episodes["distance"], atol=1e-6) | (episodes["return"] == -5.0))
    # The process' CPU seconds at each episode's end: never decreasing, and measured from the run's start.
    assert np.all(np.diff(episodes["cpu_seconds"]) >= 0) and episodes["cpu_seconds"][-1] > 0
    assert episodes["cpu_seconds"][-1] <= summary["learn_seconds"] * os.cpu_count() + 1
    for name in ("learning_curve.csv", "learning_curve.png", f"{algorithm}_policy.zip", "summary.json"):
        assert (tmp_path / name).exists()
    assert any((tmp_path / "logs").glob("events.out.tfevents.*")) and (tmp_path / "logs" / "progress.csv").exists()
    assert json.loads((tmp_path / "summary.json").read_text()) == json.loads(json.dumps(summary)) and "settings" in summary
    # The final evaluation: the saved policy, deterministic, one goal at a time on a fresh env (the goal-conditioned
    # task for SAC + HER), against the summary's, which stepped the held-out goals together.
    model = load_trained(algorithm, tmp_path / f"{algorithm}_policy.zip", "hockey")
    ((name, value),) = change.items()
    assert getattr(model, name) == value and summary["settings"][name] == value
    distances, unstable, unmoved = [], 0, 0
    for goal in held_out_goals("hockey", 2, EVAL_GOAL_SEED):
        env = gym.make("GenRL/HockeyGoal-v0") if algorithm == "sac-her" else make_feedback_env("hockey")
        obs, _ = env.reset(options={"goal": goal})
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(model.predict(obs, deterministic=True)[0])
            done = terminated or truncated
        distances.append((-reward, info.get("table_contacts", 0)))
        unstable += info["unstable"]
        unmoved += bool(np.linalg.norm(info["reached"] - env.unwrapped.initial_state_object_xy()) < 0.01)
    final = summary["final_eval"]
    assert final["goals"] == 2 and final["goal_seed"] == EVAL_GOAL_SEED
    health = summary["training_health"]  # from the run's own SB3 logs (SAC without prefill is still warming up)
    assert ("approx_kl_median" in health) == (algorithm == "ppo")
    assert ("critic_loss_max" in health) == (algorithm in ("sac", "sac-her"))
    # The summary's mean is that of the batched evaluation's goals, each of which the goal stepped alone matches:
    # batched and single forward passes differ in float32 rounding, which 69 closed-loop steps, the stick's hit and
    # the table contacts amplify (up to 2% here, a 5% tolerance); another goal, observation or env would be metres off.
    batched = -np.asarray(
        evaluate_feedback_policy(model, "hockey", goals=2, seed=EVAL_GOAL_SEED, goal_conditioned=algorithm == "sac-her")[
            "rewards"
        ],
        dtype=float,
    )
    assert final["mean_distance"] == pytest.approx(float(np.mean(batched)), rel=1e-9)
    for (distance, _), together in zip(distances, batched, strict=True):
        assert distance == pytest.approx(together, rel=5e-2)
    assert abs(final["table_contacts"] - np.mean([c for _, c in distances])) <= 1 and final["unstable"] == unstable
    assert final["object_unmoved"] == unmoved
    if algorithm == "ppo":
        bc, first = summary["bc"], summary["first_batch"]
        assert bc["epochs"] == 2 and bc["deterministic_distance"] > 0 and bc["sampled_distance"] > 0
        assert first["episodes"] == 128 // 69 and first["mean_distance"] > 0  # PPO's first rollout: n_steps
        cloned = PPO.load(tmp_path / "bc_policy.zip", device="cpu")
        np.testing.assert_allclose(cloned.policy.log_std.exp().detach().numpy(), bc["action_std"], rtol=1e-5)


class _HoldStill:
    """A policy that never moves the arm (zero joint-position changes)."""

    def predict(self, observations, deterministic=True):
        n = len(observations["observation"]) if isinstance(observations, dict) else len(observations)
        return np.zeros((n, 7), dtype=np.float32), None


@pytest.mark.parametrize("algorithm", ["ppo", "sac-her"])
def test_the_final_evaluation_of_an_arm_holding_still(algorithm):
    # The puck stays where it rests, so every goal is unmoved and scores its distance from the puck's start.
    final = evaluate_trained(algorithm, _HoldStill(), "hockey", goals=5, seed=3)
    start = HockeyEnv().initial_state_object_xy()
    expected = np.linalg.norm(held_out_goals("hockey", 5, 3) - start, axis=1)
    assert final["object_unmoved"] == 5 and final["unstable"] == 0 and final["table_contacts"] == 0
    assert final["mean_distance"] == pytest.approx(expected.mean(), abs=1e-4)
    assert final["median_distance"] == pytest.approx(np.median(expected), abs=1e-4)
    if algorithm == "ppo":  # goals given, one off the task's region
        goals = np.array([[1.0, 0.1], [2.0, 1.5]], dtype=np.float32)
        played = evaluate_feedback_policy(_HoldStill(), "hockey", goals=goals, allow_outside_region=True)
        np.testing.assert_allclose(-played["rewards"], np.linalg.norm(goals - start, axis=1), atol=1e-4)


def test_open_loop_rewards_play_the_actions_as_the_env_does():
    trajectory = scripted_hit(strength=1.0, direction=0.2).astype(np.float32)
    env = HockeyEnv()
    _, info = env.play_trajectory(trajectory, np.zeros(2), allow_outside_region=True)
    outside = info["reached"] + np.array([0.0, 2.0])  # a goal off the task's region
    inside = np.array([1.0, 0.1])
    rewards = open_loop_rewards(
        "hockey", np.stack([trajectory, trajectory]), np.stack([info["reached"], outside]), allow_outside_region=True
    )
    np.testing.assert_allclose(rewards, [0.0, -2.0], atol=1e-5)  # reached exactly / 2 m beside it
    assert open_loop_rewards("hockey", trajectory[None], inside[None])[0] == pytest.approx(
        -np.linalg.norm(info["reached"] - inside), abs=1e-5
    )
    with pytest.raises(ValueError, match="outside the goal region"):
        open_loop_rewards("hockey", trajectory[None], outside[None])


class _Killed(Exception):
    """Stands for the process being killed."""


def _killed_in_episode(monkeypatch, episode: int) -> None:
    """Make a SAC run on hockey stop (raise :class:`_Killed`) 10 steps into its ``episode``-th episode (69 steps each)."""
    from sb3_genrl.run import checkpoint

    watch = checkpoint.EpisodeCheckpoint._on_rollout_start

    def killed(callback):
        watch(callback)
        if callback.model.num_timesteps == (episode - 1) * 69 + 10:
            raise _Killed

    monkeypatch.setattr(checkpoint.EpisodeCheckpoint, "_on_rollout_start", killed)


def _open_in_this_process(path) -> bool:
    """Whether this process holds ``path`` open (Linux: its /proc/self/fd links)."""
    target = os.path.realpath(path)
    return any(os.path.realpath(f"/proc/self/fd/{fd}") == target for fd in os.listdir("/proc/self/fd"))


@pytest.mark.parametrize("algorithm", ["sac", "sac-her"])
def test_a_stopped_off_policy_run_resumes_from_its_checkpoint(algorithm, demos, tmp_path, monkeypatch):
    _killed_in_episode(monkeypatch, 4)
    run = {
        "episodes": 5,
        "out_dir": tmp_path,
        "demos": demos,
        "demo_episodes": 10,
        "checkpoint_every": 2,
        "device": "cpu",
        "seed": 1,
        "window": 5,
    }
    with pytest.raises(_Killed):
        train_baseline(algorithm, "hockey", **run)
    assert not _open_in_this_process(tmp_path / MONITOR_FILE)  # the stopped run's env was closed
    state = json.loads((tmp_path / "checkpoint" / "state.json").read_text())
    assert state["episodes"] == 2 and state["steps"] == 2 * 69  # the last checkpoint: every 2 episodes
    before = read_monitor(tmp_path / MONITOR_FILE)
    assert len(before["return"]) == 3 and not (tmp_path / "summary.json").exists()
    with pytest.raises(ValueError, match=r"holds another run \(it differs in seed\)"):
        train_baseline(algorithm, "hockey", **(run | {"seed": 2}))
    monkeypatch.undo()

    summary = train_baseline(algorithm, "hockey", **run)
    assert not _open_in_this_process(tmp_path / MONITOR_FILE)
    after = read_monitor(tmp_path / MONITOR_FILE)
    # The rows up to the checkpoint are kept, the third episode is played again, and the budget is met exactly.
    assert len(after["return"]) == 5 == summary["episodes_played"]
    np.testing.assert_array_equal(after["return"][:2], before["return"][:2])
    assert summary["resumed_at_episodes"] == [2] and summary["setup_seconds"] == state["summary"]["setup_seconds"]
    assert np.all(np.diff(after["time"]) >= 0) and np.all(np.diff(after["cpu_seconds"]) >= 0)  # the clocks go on
    assert not (tmp_path / "checkpoint").exists()  # a finished run removes its checkpoint
    assert (tmp_path / "logs" / "progress.until_episode_2.csv").exists()
    env = gym.make("GenRL/HockeyGoal-v0") if algorithm == "sac-her" else None  # SB3 loads HER with its env
    assert SAC.load(tmp_path / f"{algorithm}_policy.zip", env=env, device="cpu").num_timesteps == 5 * 69


def test_a_checkpoint_interrupted_while_written_leaves_the_previous_one_whole(demos, tmp_path, monkeypatch):
    save_buffer = SAC.save_replay_buffer

    def disk_full_at_the_second_checkpoint(model, path):
        if model.num_timesteps == 4 * 69:  # the model of the checkpoint at episode 4 is written, its buffer not
            raise OSError(28, "No space left on device")
        save_buffer(model, path)

    monkeypatch.setattr(SAC, "save_replay_buffer", disk_full_at_the_second_checkpoint)
    run = {
        "episodes": 5,
        "out_dir": tmp_path,
        "demos": demos,
        "demo_episodes": 10,
        "checkpoint_every": 2,
        "device": "cpu",
        "seed": 1,
        "window": 5,
        "eval_goals": 2,
    }
    with pytest.raises(OSError, match="No space left"):
        train_baseline("sac", "hockey", **run)
    state = json.loads((tmp_path / "checkpoint" / "state.json").read_text())
    assert state["episodes"] == 2 and sorted(state["files"]) == ["buffer", "model"]
    assert sorted(path.name for path in (tmp_path / "checkpoint").iterdir()) == sorted(
        ["state.json", *state["files"].values()]
    )
    assert SAC.load(tmp_path / "checkpoint" / state["files"]["model"], device="cpu").num_timesteps == 2 * 69
    monkeypatch.undo()
    summary = train_baseline("sac", "hockey", **run)  # resumed from episode 2: the budget is met exactly
    assert summary["resumed_at_episodes"] == [2] and summary["episodes_played"] == 5
    assert SAC.load(tmp_path / "sac_policy.zip", device="cpu").num_timesteps == 5 * 69


def test_a_run_resumed_twice_from_one_checkpoint_keeps_its_early_log(demos, tmp_path, monkeypatch):
    _killed_in_episode(monkeypatch, 6)
    run = {
        "episodes": 6,
        "out_dir": tmp_path,
        "demos": demos,
        "demo_episodes": 10,
        "checkpoint_every": 5,
        "device": "cpu",
        "seed": 1,
        "window": 3,
        "eval_goals": 2,
    }
    with pytest.raises(_Killed):
        train_baseline("sac-no-prefill", "hockey", **run)
    early = (tmp_path / "logs" / "progress.csv").read_text()
    assert "rollout/ep_rew_mean" in early  # SAC logs every 4 episodes
    for _ in range(2):  # resumed from episode 5 and killed again at once, twice
        with pytest.raises(_Killed):
            train_baseline("sac-no-prefill", "hockey", **run)
        assert (tmp_path / "logs" / "progress.until_episode_5.csv").read_text() == early


def test_a_sac_run_with_the_largest_seed_resumes(demos, tmp_path, monkeypatch):
    _killed_in_episode(monkeypatch, 3)
    run = {
        "episodes": 3,
        "out_dir": tmp_path,
        "demos": demos,
        "demo_episodes": 10,
        "checkpoint_every": 2,
        "device": "cpu",
        "seed": 2**32 - 1,
        "window": 3,
        "eval_goals": 2,
    }
    with pytest.raises(_Killed):
        train_baseline("sac-no-prefill", "hockey", **run)
    monkeypatch.undo()
    summary = train_baseline("sac-no-prefill", "hockey", **run)  # seed + 2 episodes is past 32 bits
    assert summary["resumed_at_episodes"] == [2] and summary["episodes_played"] == 3


def test_a_baseline_rerun_never_leaves_a_summary_beside_another_runs_cloned_policy(demos, tmp_path, monkeypatch):
    from sb3_genrl.baselines import train as baseline_train

    run = {
        "episodes": 2,
        "out_dir": tmp_path,
        "demos": demos,
        "demo_episodes": 10,
        "eval_goals": 2,
        "window": 2,
        "algorithm_kwargs": {"n_steps": 128},
        "device": "cpu",
    }
    first = train_baseline("ppo", "hockey", bc_kwargs={"max_epochs": 2}, **run)
    cloned = (tmp_path / "bc_policy.zip").read_bytes()
    again = train_baseline("ppo", "hockey", bc_kwargs={"max_epochs": 2}, **run)  # finished: nothing done
    assert again == json.loads(json.dumps(first))
    assert (tmp_path / "bc_policy.zip").read_bytes() == cloned

    def killed(*args, **kwargs):
        raise _Killed

    monkeypatch.setattr(baseline_train, "_learn", killed)  # stopped after behaviour cloning, before PPO
    with pytest.raises(ValueError, match=r"holds another run \(it differs in settings\)"):
        train_baseline("ppo", "hockey", bc_kwargs={"max_epochs": 3}, **run)
    assert (tmp_path / "bc_policy.zip").read_bytes() == cloned and json.loads((tmp_path / "summary.json").read_text())
    with pytest.raises(_Killed):
        train_baseline("ppo", "hockey", bc_kwargs={"max_epochs": 3}, overwrite=True, **run)
    assert (tmp_path / "bc_policy.zip").read_bytes() != cloned  # the new run's cloned policy, and no old summary
    assert not (tmp_path / "summary.json").exists() and not (tmp_path / "ppo_policy.zip").exists()


def test_demonstrations_enter_the_her_buffer_as_episodes(demos):
    episodes = goal_episodes("hockey", demos)
    assert episodes["observation"].shape == (12, 70, 15) and episodes["achieved_goal"].shape == (12, 70, 2)
    # Each demonstration reached its own goal: the terminal achieved goal is the goal, the reward 0.
    np.testing.assert_allclose(episodes["achieved_goal"][:, -1], episodes["desired_goal"][:, -1], atol=1e-6)
    model = sac_her_with_demonstrations(
        gym.make("GenRL/HockeyGoal-v0"), episodes, task="hockey", steps=100, seed=0, device="cpu"
    )
    buffer = model.replay_buffer
    assert buffer.size() == 12 * 69 and np.all(buffer.ep_length[: 12 * 69, 0] == 69)
    np.testing.assert_array_equal(buffer.observations["observation"][:69, 0], episodes["observation"][0, :-1])
    np.testing.assert_array_equal(buffer.next_observations["achieved_goal"][:69, 0], episodes["achieved_goal"][0, 1:])
    np.testing.assert_allclose(model.policy.unscale_action(buffer.actions[:69, 0]), episodes["actions"][0], atol=1e-6)
    assert buffer.infos[68, 0]["terminal"] and not buffer.infos[67, 0]["terminal"]
    # Relabelled samples: a terminal transition scores 0 against its own final goal, any other transition 0 too.
    samples = buffer.sample(2048)
    rewards, terminal = samples.rewards[:, 0].numpy(), samples.dones[:, 0].numpy() > 0
    final = np.all(
        np.isclose(
            samples.observations["desired_goal"].numpy(), samples.next_observations["achieved_goal"].numpy(), atol=1e-6
        ),
        axis=1,
    )
    assert np.all(rewards[~terminal] == 0) and np.sum(terminal & final) > 5
    assert np.all(np.abs(rewards[terminal & final]) < 1e-6)


def test_sac_her_through_the_cli(tmp_path):
    dataset = make_demonstrations("hockey", 4, tmp_path / "demos", progress_bar=False)
    code = main(
        [
            "baseline",
            "sac-her",
            "--task",
            "hockey",
            "--demos",
            str(dataset),
            "--episodes",
            "3",
            "--out",
            str(tmp_path / "run"),
            "--device",
            "cpu",
            "--no-progress-bar",
        ]
    )
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert code == 0 and summary["algorithm"] == "sac-her" and summary["episodes_played"] >= 3
    assert summary["demo_transitions"] == 4 * 69 and summary["settings"]["goal_selection_strategy"] == "final"


def test_baseline_bad_input(tmp_path, demos):
    with pytest.raises(ValueError, match="unknown baseline"):
        train_baseline("dqn", "hockey", episodes=1, out_dir=tmp_path, demos=demos)
    with pytest.raises(ValueError, match="needs demonstrations"):
        train_baseline("ppo", "hockey", episodes=1, out_dir=tmp_path)
    with pytest.raises(ValueError, match="unknown task"):
        train_baseline("ppo", "golf", episodes=1, out_dir=tmp_path, demos=demos)
    with pytest.raises(ValueError, match="demo_episodes"):
        train_baseline("ppo", "hockey", episodes=1, out_dir=tmp_path, demos=demos, demo_episodes=100)


def _dataset_of(demos: dict[str, np.ndarray], path, task: str, horizon: int = 69):
    """The transitions as a dataset on disk that records ``task`` (the episodes themselves are hockey hits)."""
    from gymnasium import spaces

    from sb3_genrl.data import write_dataset

    n = len(demos["observations"]) // horizon
    episodes = {key: value.reshape(n, horizon, *value.shape[1:]) for key, value in demos.items()}
    arrays = {
        "observations": np.concatenate([episodes["observations"], episodes["next_observations"][:, -1:]], axis=1),
        "actions": episodes["actions"],
        "rewards": episodes["rewards"].astype(np.float64),
        "terminations": episodes["dones"].astype(bool),
        "truncations": np.zeros((n, horizon), dtype=bool),
        "reached": np.zeros((n, 2)),
        "sampled_goals": np.zeros((n, 2)),
    }
    return write_dataset(
        path,
        arrays,
        dataset_id=f"genrl/{task}-v0",
        genrl={"task": task, "horizon": horizon},
        observation_space=spaces.Box(-np.inf, np.inf, (16,), np.float32),
        action_space=spaces.Box(-0.5, 0.5, (7,), np.float32),
    )


def test_baselines_refuse_another_tasks_demonstrations(demos, tmp_path, capsys):
    from sb3_genrl.cli import main

    hockey = _dataset_of(demos, tmp_path / "hockey_demos", "hockey")
    basketball = _dataset_of(demos, tmp_path / "basketball_demos", "basketball")
    for algorithm, task, dataset, other in (
        ("ppo", "hockey", basketball, "basketball"),
        ("sac", "basketball", hockey, "hockey"),
    ):
        out = tmp_path / f"{algorithm}_run"
        assert (
            main(["baseline", algorithm, "--task", task, "--demos", str(dataset), "--episodes", "1", "--out", str(out)]) == 2
        )
        error = capsys.readouterr().err
        assert str(dataset) in error and repr(other) in error and repr(task) in error, error
        assert not (out / "summary.json").exists()
    # The dataset of the task itself is accepted: its transitions are the ones the baseline is given.
    summary = train_baseline("sac", "hockey", episodes=1, out_dir=tmp_path / "sac_ok", demos=hockey, device="cpu", window=1)
    assert summary["demo_transitions"] == len(demos["observations"])


def test_the_baselines_run_with_the_zoo_entries_of_their_yml_files():
    from torch import nn

    # rl-zoo3's ppo.yml HalfCheetah-v4, sac.yml HalfCheetah-v3 (&mujoco-defaults) and FetchReach-v1, as published
    # (hyperparams/*.yml say where each entry comes from and what changed); both tasks the same.
    for task in ("hockey", "basketball"):
        ppo, ppo_policy = baseline_settings("ppo", task)
        assert ppo == {
            "n_steps": 512,
            "batch_size": 64,
            "gamma": 0.98,
            "learning_rate": 2.0633e-05,
            "ent_coef": 0.000401762,
            "clip_range": 0.1,
            "n_epochs": 20,
            "gae_lambda": 0.92,
            "max_grad_norm": 0.8,
            "vf_coef": 0.58096,
        }
        assert ppo_policy == {
            "log_std_init": -2,
            "ortho_init": False,
            "activation_fn": nn.ReLU,
            "net_arch": {"pi": [256, 256], "vf": [256, 256]},
        }
        zoo_sac = {
            "learning_rate": 3e-4,
            "batch_size": 256,
            "tau": 0.005,
            "gamma": 0.99,
            "train_freq": 1,
            "gradient_steps": 1,
            "ent_coef": "auto",
            "learning_starts": 10_000,
        }
        assert baseline_settings("sac-no-prefill", task) == (zoo_sac, {"net_arch": [256, 256]})
        assert baseline_settings("sac", task) == (zoo_sac | {"learning_starts": 0}, {"net_arch": [256, 256]})
        assert baseline_settings("sac-her", task) == (
            {"learning_rate": 1e-3, "batch_size": 256, "gamma": 0.99, "ent_coef": "auto", "learning_starts": 0},
            {"net_arch": [64, 64]},
        )
        assert (
            baseline_settings("latent-ppo", task)[0]
            == baseline_settings("latent-trpo", task)[0]
            == {"n_steps": 64, "batch_size": 64}
        )
        assert baseline_settings("latent-sac", task)[0] == {"learning_starts": 64}


def test_changes_to_the_zoo_settings_are_checked_and_recorded():
    from sb3_genrl.baselines.hyperparameters import check_algorithm_kwargs, settings_record

    defaults = settings_record("hockey")
    changed = settings_record("hockey", {"ppo": {"target_kl": 0.02}, "sac": {"gamma": 1}})
    assert changed["ppo"] == defaults["ppo"] | {"target_kl": 0.02} and "target_kl" not in defaults["ppo"]
    assert changed["sac"] == defaults["sac"] | {"gamma": 1} and changed["sac-her"] == defaults["sac-her"]
    assert check_algorithm_kwargs("latent-trpo", {"target_kl": 0.02}) == {"target_kl": 0.02}
    assert check_algorithm_kwargs("ppo", None) == {}
    with pytest.raises(ValueError, match="has no setting 'gama'"):
        check_algorithm_kwargs("sac", {"gama": 1})
    with pytest.raises(ValueError, match="has no setting 'seed'"):  # set by the run itself
        check_algorithm_kwargs("ppo", {"seed": 1})
    with pytest.raises(ValueError, match="JSON values"):
        check_algorithm_kwargs("ppo", {"target_kl": object()})
    with pytest.raises(ValueError, match="unknown baseline 'genrl'"):
        settings_record("hockey", {"genrl": {"gamma": 1}})


def test_training_health_reads_every_progress_file_and_flags_divergence(tmp_path):
    from sb3_genrl.baselines.evaluation import DIVERGED, training_health

    assert training_health(tmp_path) == {"warnings": []}  # no logs: nothing to say
    logs = tmp_path / "logs"
    logs.mkdir()
    header = "time/total_timesteps,train/critic_loss,train/ent_coef\n"
    # A resumed run: the rows before its checkpoints are kept in progress.until_episode_K.csv, read in K's order.
    (logs / "progress.until_episode_20.csv").write_text(
        header + "".join(f"{i},{v},0.5\n" for i, v in enumerate([2, 4, 3, 5, 1]))
    )
    (logs / "progress.until_episode_3.csv").write_text(header + "0,,0.9\n1,1,0.8\n")  # no loss before learning starts
    (logs / "progress.csv").write_text(header + "9,7,0.2\n")
    health = training_health(tmp_path)
    early = float(np.median([1, 2, 4, 3, 5, 1, 7]))  # the first 10 losses, in order
    assert health["critic_loss_early"] == early and health["critic_loss_max"] == 7 and health["warnings"] == []
    assert (health["ent_coef_first"], health["ent_coef_max"], health["ent_coef_last"]) == (0.9, 0.9, 0.2)
    (logs / "progress.csv").write_text(header + f"9,{DIVERGED * early * 1.01},0.2\n")
    assert "the critic diverged" in training_health(tmp_path)["warnings"][0]
    for path in logs.iterdir():
        path.unlink()
    (logs / "progress.csv").write_text("train/approx_kl,train/clip_fraction\n0.01,0.1\n3,0.9\n5,0.95\n")
    health = training_health(tmp_path)
    assert health["approx_kl_median"] == 3 and health["approx_kl_max"] == 5 and health["clip_fraction_median"] == 0.9
    assert "far beyond its trust region" in health["warnings"][0]


def test_compare_refuses_a_named_run_of_another_task_naming_it(tmp_path):
    def run(name: str, task: str, algorithm: str):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "summary.json").write_text(json.dumps({"task": task, "algorithm": algorithm}))
        (folder / "learning_curve.csv").write_text("episodes,mean_reward\n16,-0.5\n32,-0.4\n")
        return folder

    hockey, basketball = run("genrl", "hockey", "genrl"), run("ppo", "basketball", "ppo")
    out = tmp_path / "out"
    for task, message in (
        ("hockey", f"runs of another task than 'hockey': {basketball} (basketball); leave them out"),
        (None, f"the runs are of several tasks (hockey: {hockey}; basketball: {basketball}); compare one task's runs"),
    ):
        with pytest.raises(ValueError) as error:
            compare_runs([hockey, basketball], out, task=task)
        assert message in str(error.value) and not out.exists()
        task_option = [] if task is None else ["--task", task]
        assert main(["compare", *task_option, "--runs", str(hockey), str(basketball), "--out", str(out)]) == 2
        assert not out.exists()
    assert compare_runs([hockey], out, task="hockey").read_text().count("| GenRL | 1 |") == 1


def test_compare_counts_each_run_once_as_a_seed(tmp_path):
    def run(name: str, seed: int):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "summary.json").write_text(json.dumps({"task": "hockey", "algorithm": "genrl", "seed": seed}))
        (folder / "learning_curve.csv").write_text("episodes,mean_reward\n16,-0.5\n32,-0.4\n")
        return folder

    first, same_seed, second = run("a", 0), run("b", 0), run("c", 1)
    out = tmp_path / "out"
    for runs, message in (
        ([first, first], f"{first} is given twice"),
        ([first, tmp_path / "." / "a"], "is given twice"),
        ([first, same_seed], f"{first} and {same_seed} are both genrl with seed 0"),
    ):
        with pytest.raises(ValueError, match=message):
            compare_runs(runs, out)
        assert not out.exists()
    assert compare_runs([first, second], out).read_text().count("| GenRL | 2 |") == 1
    made = (out / "comparison.csv").read_bytes()  # the command replaces a comparison only with --overwrite
    assert main(["compare", "--runs", str(first), "--out", str(out)]) == 2 and (out / "comparison.csv").read_bytes() == made
    assert main(["compare", "--runs", str(first), "--out", str(out), "--overwrite"]) == 0
    assert (out / "comparison.csv").read_bytes() != made


@pytest.mark.parametrize(
    "algorithm, episodes, n_envs, per_update",
    [("latent-ppo", 64, 64, {"n_steps": 1}), ("latent-sac", 96, 16, {"gradient_steps": -1, "learning_starts": 64})],
)
def test_latent_baselines_play_an_updates_episodes_together_and_the_result_does_not_depend_on_the_cores(
    algorithm, episodes, n_envs, per_update, hockey_generator, tmp_path
):
    """With no n_envs, a latent-space baseline on a task with a fast path plays an update's episodes in one threaded
    call (PPO: its 64 steps as 64 envs of one step; SAC: 16 envs, one gradient step per episode); the saved policy is
    the same, bit for bit, on 1 simulation thread and on 2, whatever torch's thread count (the run trains on one and
    gives the caller's back)."""
    runs = []
    for threads in (1, 2):
        th.set_num_threads(threads)
        runs.append(
            train_baseline(
                algorithm,
                "hockey",
                episodes=episodes,
                out_dir=tmp_path / str(threads),
                seed=3,
                generator=hockey_generator,
                eval_goals=4,
                device="cpu",
                n_threads=threads,
            )
        )
        assert th.get_num_threads() == threads
    for run in runs:
        assert run["n_envs"] == n_envs and per_update.items() <= run["settings"].items()
        assert run["episodes_played"] == episodes
    model_class = PPO if algorithm == "latent-ppo" else SAC
    policies = [
        model_class.load(tmp_path / str(threads) / f"{algorithm}_policy.zip").policy.state_dict() for threads in (1, 2)
    ]
    assert policies[0].keys() == policies[1].keys()
    for name, tensor in policies[0].items():
        assert th.equal(tensor, policies[1][name]), name
    assert runs[0]["final_eval"] == runs[1]["final_eval"]


def test_one_env_keeps_a_latent_baselines_own_settings_and_a_bad_n_envs_is_refused(hockey_generator, tmp_path):
    run = {"episodes": 4, "generator": hockey_generator, "eval_goals": 2, "device": "cpu"}
    single = train_baseline("latent-trpo", "hockey", out_dir=tmp_path / "one", n_envs=1, **run)
    assert single["n_envs"] == 1 and single["settings"] == baseline_settings("latent-trpo", "hockey")[0]
    assert single["episodes_played"] == 64  # one update of its 64 steps, one episode each
    with pytest.raises(ValueError, match=r"holds another run \(it differs in n_envs"):  # not the finished one
        train_baseline("latent-trpo", "hockey", out_dir=tmp_path / "one", n_envs=2, **run)
    with pytest.raises(ValueError, match=r"n_envs \(3\) must divide latent-ppo's n_steps \(64\)"):
        train_baseline("latent-ppo", "hockey", out_dir=tmp_path / "three", n_envs=3, **run)
    with pytest.raises(ValueError, match="n_envs is for the latent-space baselines"):
        train_baseline("sac", "hockey", episodes=1, out_dir=tmp_path / "sac", demos={}, n_envs=2)
    assert not (tmp_path / "three").exists() and not (tmp_path / "sac").exists()


@pytest.mark.parametrize(
    ("algorithm", "change", "message"),
    [
        ("ppo", {"gamma": 2}, r"ppo's gamma must be a number in \[0, 1\], got 2"),
        ("ppo", {"gamma": "x"}, r"ppo's gamma must be a number in \[0, 1\], got 'x'"),
        ("ppo", {"target_kl": -1}, r"ppo's target_kl must be a number in \(0, inf\), or null, got -1"),
        ("ppo", {"clip_range": -1}, r"ppo's clip_range must be a number in \(0, inf\), got -1"),
        ("ppo", {"n_steps": "x"}, r"ppo's n_steps must be an integer >= 1, got 'x'"),
        ("ppo", {"n_epochs": 0}, r"ppo's n_epochs must be an integer >= 1, got 0"),
        ("latent-ppo", {"batch_size": 0}, r"latent-ppo's batch_size must be an integer >= 1, got 0"),
        ("ppo", {"learning_rate": float("nan")}, r"ppo's learning_rate must be a number in \(0, inf\), got nan"),
        ("ppo", {"ent_coef": "auto"}, r"ppo's ent_coef must be a number >= 0"),
        ("sac", {"ent_coef": "auto_x"}, r"sac's ent_coef must be a number >= 0 \(SAC: also 'auto'"),
        ("sac", {"train_freq": [1, "epoch"]}, r"sac's train_freq must be an integer >= 1, or \[an integer"),
        ("latent-trpo", {"line_search_shrinking_factor": 1}, r"line_search_shrinking_factor must be a number in \(0, 1\)"),
    ],
)
def test_a_change_to_a_baselines_settings_outside_what_sb3_accepts_is_refused(algorithm, change, message):
    from sb3_genrl.baselines.hyperparameters import check_algorithm_kwargs

    with pytest.raises(ValueError, match=message):
        check_algorithm_kwargs(algorithm, change)


def test_the_values_sb3_accepts_pass_the_check():
    from sb3_genrl.baselines.hyperparameters import check_algorithm_kwargs

    for algorithm, change in (
        ("ppo", {"gamma": 1, "gae_lambda": 0.9, "target_kl": None, "clip_range": 0.1, "ent_coef": 0.0, "n_epochs": 3}),
        ("sac", {"ent_coef": "auto"}),
        ("sac", {"ent_coef": "auto_0.1", "train_freq": [1, "episode"], "gradient_steps": -1, "tau": 1.0}),
        ("latent-trpo", {"target_kl": 0.02, "cg_max_steps": 10, "sde_sample_freq": -1}),
    ):
        assert check_algorithm_kwargs(algorithm, change) == change


def test_genrl_baseline_refuses_a_bad_change_before_its_run_folder(tmp_path, cli, hockey_generator):
    out = tmp_path / "run"
    code, _, err = cli(
        "baseline", "latent-ppo", "--task", "hockey", "--generator", hockey_generator, "--episodes", 64,
        "--algorithm-kwargs", '{"gamma": 2}', "--out", out,
    )  # fmt: skip
    assert code == 2 and "latent-ppo's gamma must be a number in [0, 1], got 2" in err and not out.exists()


def test_a_comparison_does_not_depend_on_the_order_its_runs_are_given_in(tmp_path):
    def run(name: str, algorithm: str, seed: int, rewards: tuple[float, float]):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "summary.json").write_text(json.dumps({"task": "hockey", "algorithm": algorithm, "seed": seed}))
        (folder / "learning_curve.csv").write_text(f"episodes,mean_reward\n16,{rewards[0]}\n32,{rewards[1]}\n")
        return folder

    runs = [
        run("ppo1", "ppo", 1, (-0.71, -0.33)),
        run("genrl1", "genrl", 1, (-0.5, -0.1)),
        run("latent0", "latent-trpo", 0, (-0.9, -0.8)),
        run("ppo0", "ppo", 0, (-0.7, -0.3)),
        run("genrl0", "genrl", 0, (-0.6, -0.2)),
    ]
    tables = []
    for index, order in enumerate((runs, runs[::-1], runs[2:] + runs[:2])):
        compare_runs(order, tmp_path / f"out{index}")
        tables.append((tmp_path / f"out{index}" / "comparison.csv").read_text())
    assert tables[0] == tables[1] == tables[2]
    assert [line.split(",")[0] for line in tables[0].splitlines()[1:]] == ["GenRL", "PPO (BC)", "TRPO on latent"]
