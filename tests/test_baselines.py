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

from sb3_genrl.callbacks import read_episodes


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
    episodes = read_episodes(tmp_path / "episodes.csv")
    assert len(episodes["return"]) == summary["episodes_played"]
    assert np.all(episodes["table_contacts"] >= 0) and np.all(episodes["return"] <= 0)
    for name in ("learning_curve.csv", "learning_curve.png", f"{algorithm}_policy.zip", "summary.json"):
        assert (tmp_path / name).exists()
    assert any((tmp_path / "tensorboard").iterdir())
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
