"""PPO with behaviour cloning, SAC with a prefilled replay buffer, and the comparison of runs."""

import json

import numpy as np
import pytest
import torch as th
from sb3_genrl.baselines.bc import behaviour_cloning, imitation_loss
from sb3_genrl.baselines.prefill import prefill_replay_buffer
from sb3_genrl.baselines.train import train_baseline
from sb3_genrl.envs.hockey import HockeyEnv, scripted_hit
from stable_baselines3 import PPO, SAC

from sb3_genrl.curves import MONITOR_FILE, read_monitor


def demo_transitions(n_episodes: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Scripted hits played step by step, each labelled with the goal it reached (as the demonstration sets are)."""
    env = HockeyEnv()
    rng = np.random.default_rng(seed)
    keys = ("observations", "actions", "rewards", "next_observations", "dones")
    out = {key: [] for key in keys}
    for _ in range(n_episodes):
        trajectory = scripted_hit(strength=rng.uniform(0.8, 1.2), direction=rng.uniform(-0.4, 0.4))
        _, info = env.play_trajectory(trajectory, np.array([1.0, 0.0]))
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


def test_behaviour_cloning_lowers_loss_and_imitates(demos):
    model = PPO("MlpPolicy", HockeyEnv(), seed=0, device="cpu")
    obs = th.as_tensor(demos["observations"])
    act = th.as_tensor(demos["actions"])
    with th.no_grad():
        before = imitation_loss(model.policy, obs, act).item()
        untrained_mse = ((model.policy.get_distribution(obs).distribution.mean - act) ** 2).mean().item()
    history = behaviour_cloning(model.policy, demos["observations"], demos["actions"], epochs=60, batch_size=256)
    with th.no_grad():
        after = imitation_loss(model.policy, obs, act).item()
        cloned_mse = ((model.policy.get_distribution(obs).distribution.mean - act) ** 2).mean().item()
    assert history[-1] < history[0] and after < before - 1.0
    assert cloned_mse < 0.25 * untrained_mse

    # The first demonstration, action by action along its own states: the cloned policy's mean reproduces it far
    # better than an untrained policy's.
    first = slice(0, 69)
    untrained = PPO("MlpPolicy", HockeyEnv(), seed=1, device="cpu")
    with th.no_grad():
        errors = [((m.policy.get_distribution(obs[first]).distribution.mean - act[first]) ** 2).sum().item()
                  for m in (model, untrained)]
    assert errors[0] < 0.25 * errors[1]


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
@pytest.mark.parametrize("algorithm", ["ppo", "sac"])
def test_baselines_run_end_to_end(algorithm, demos, tmp_path):
    summary = train_baseline(algorithm, "hockey", episodes=20, out_dir=tmp_path, demos=demos, demo_episodes=10,
                             bc_epochs=2, eval_episodes=2, window=5, device="cpu")
    assert summary["episodes_played"] >= 20 and summary["demo_transitions"] == 10 * 69
    episodes = read_monitor(tmp_path / MONITOR_FILE)
    assert len(episodes["return"]) == summary["episodes_played"] and np.all(episodes["length"] == 69)
    assert np.all(episodes["table_contacts"] >= 0) and np.all(episodes["return"] <= 0)
    # The return of a hockey episode is its terminal reward: minus the distance it reports (Monitor keeps 6
    # decimals), or the worst reward of an unstable simulation.
    assert np.all(np.isclose(episodes["return"], -episodes["distance"], atol=1e-6) | (episodes["return"] == -5.0))
    for name in ("learning_curve.csv", "learning_curve.png", f"{algorithm}_policy.zip", "summary.json"):
        assert (tmp_path / name).exists()
    assert any((tmp_path / "logs").glob("events.out.tfevents.*")) and (tmp_path / "logs" / "progress.csv").exists()
    if algorithm == "ppo":
        assert "bc_mean_reward" in json.loads((tmp_path / "summary.json").read_text())


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
    arrays = {"observations": np.concatenate([episodes["observations"], episodes["next_observations"][:, -1:]], axis=1),
              "actions": episodes["actions"], "rewards": episodes["rewards"].astype(np.float64),
              "terminations": episodes["dones"].astype(bool), "truncations": np.zeros((n, horizon), dtype=bool),
              "reached": np.zeros((n, 2)), "sampled_goals": np.zeros((n, 2))}
    return write_dataset(path, arrays, dataset_id=f"genrl/{task}-v0", genrl={"task": task, "horizon": horizon},
                         observation_space=spaces.Box(-np.inf, np.inf, (16,), np.float32),
                         action_space=spaces.Box(-0.5, 0.5, (7,), np.float32))


def test_baselines_refuse_another_tasks_demonstrations(demos, tmp_path, capsys):
    from sb3_genrl.cli import main

    hockey = _dataset_of(demos, tmp_path / "hockey_demos", "hockey")
    basketball = _dataset_of(demos, tmp_path / "basketball_demos", "basketball")
    for algorithm, task, dataset, other in (("ppo", "hockey", basketball, "basketball"),
                                            ("sac", "basketball", hockey, "hockey")):
        out = tmp_path / f"{algorithm}_run"
        assert main(["baseline", algorithm, "--task", task, "--demos", str(dataset), "--episodes", "1",
                     "--out", str(out)]) == 2
        error = capsys.readouterr().err
        assert str(dataset) in error and repr(other) in error and repr(task) in error, error
        assert not (out / "summary.json").exists()
    # The dataset of the task itself is accepted: its transitions are the ones the baseline is given.
    summary = train_baseline("sac", "hockey", episodes=1, out_dir=tmp_path / "sac_ok", demos=hockey, device="cpu",
                             window=1)
    assert summary["demo_transitions"] == len(demos["observations"])
