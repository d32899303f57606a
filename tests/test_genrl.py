"""Tests of sb3_genrl.genrl: GenRL on a toy contextual bandit with a known optimum, save/load, seeding, train_policy."""

from __future__ import annotations

import copy
import csv
import itertools
import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from conftest import (
    ContextReachEnv,
    FastReachEnv,
    LinearGenerator,
    ReachEnv,
    load_linear_generator,
    optimal_latent,
)
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.cli import main as cli_main
from sb3_genrl.genrl import genrl as genrl_module
from sb3_genrl.genrl import train_policy
from sb3_genrl.genrl.policies import BoxScaler

GOALS = np.array([[0.5, -0.3], [-0.6, 0.4], [0.0, 0.6], [0.3, 0.3]], dtype=np.float32)
TOY_ID = "GenRLTest/FastReach-v0"
TOY_TASK_ID = "GenRLTest/FastReachTask-v0"


@pytest.mark.parametrize("e_step", ["trpo", "kl_penalty"])
def test_converges_to_known_optimum(e_step):
    model = GenRL(FastReachEnv(), LinearGenerator(), e_step=e_step, seed=0)
    before = np.array([model.predict(goal, deterministic=True)[0] for goal in GOALS])
    model.learn(4800)  # 75 EM iterations of N = 64 episodes (the KL-penalty E-step is 0.06-0.17 off after 50)
    after = np.array([model.predict(goal, deterministic=True)[0] for goal in GOALS])
    optimum = np.array([optimal_latent(goal) for goal in GOALS])
    assert np.abs(before - optimum).max() > 0.5
    np.testing.assert_allclose(after, optimum, atol=0.15)
    assert model.logger.name_to_value["train/mean_reward"] > -0.25  # about -1.7 for the initial policy


def test_train_logs_and_kl_bound():
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, target_kl=0.02)
    model.learn(128)
    logs = model.logger.name_to_value
    for key in ("mean_reward", "max_reward", "kl", "entropy", "value_loss", "policy_objective", "line_search_success",
                "step_size", "accepted_fraction"):
        assert np.isfinite(logs[f"train/{key}"]), key
    assert 0 < logs["train/kl"] < 0.02
    assert logs["train/max_reward"] >= logs["train/mean_reward"]


def test_constructor_forms_and_defaults():
    generator = LinearGenerator()
    for model in (
        GenRL(FastReachEnv(), generator),
        GenRL("MlpPolicy", FastReachEnv(), generator=generator),
        GenRL("MlpPolicy", FastReachEnv(), generator),
        GenRL(env=FastReachEnv(), generator=generator),
        GenRL(LatentActionWrapper(FastReachEnv(), generator)),
        GenRL(DummyVecEnv([lambda: LatentActionWrapper(FastReachEnv(), generator)] * 2)),
    ):
        assert model.generator is generator
        assert model.n_steps == 64 and model.e_step == "trpo"
        assert th.exp(model.policy.log_std).detach().cpu().numpy() == pytest.approx([1.0, 1.0])  # the prior's std
    uniform = GenRL(ContextReachEnv(), LinearGenerator(prior="uniform"))
    assert th.exp(uniform.policy.log_std).detach().cpu().numpy() == pytest.approx([3**-0.5] * 2, rel=1e-5)
    assert uniform.action_space.high.tolist() == [1.0, 1.0]
    gym.register(TOY_ID, entry_point=FastReachEnv) if TOY_ID not in gym.registry else None
    vec_env = GenRL(TOY_ID, generator).env
    assert vec_env.get_attr("generator") == [generator] and isinstance(vec_env.envs[0].unwrapped, FastReachEnv)


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="generator is needed"):
        GenRL(FastReachEnv())
    with pytest.raises(ValueError, match="LatentActionWrapper"):
        GenRL(DummyVecEnv([FastReachEnv]), LinearGenerator())
    with pytest.raises(ValueError, match="e_step"):
        GenRL(FastReachEnv(), LinearGenerator(), e_step="adam")
    with pytest.raises(TypeError, match="twice"):
        GenRL(FastReachEnv(), LinearGenerator(), generator=LinearGenerator())
    with pytest.raises(ValueError, match=r"\(2, 5, 2\).*\(2, 7, 2\)"):
        GenRL(LatentActionWrapper(FastReachEnv(episode_length=7), LinearGenerator(horizon=7)), LinearGenerator())


def test_works_with_step_by_step_env_and_n_envs():
    env = DummyVecEnv([lambda: LatentActionWrapper(ReachEnv(), LinearGenerator(), context=lambda obs: obs[:2],
                                                   context_space=ContextReachEnv.context_space)] * 2)
    model = GenRL(env, e_step="kl_penalty", n_steps=16, seed=1).learn(64)
    assert model.num_timesteps == 64 and model.rollout_buffer.buffer_size * model.n_envs == 32


def test_same_seed_same_run():
    runs = []
    for _ in range(2):
        model = GenRL(FastReachEnv(), LinearGenerator(), seed=7).learn(192)
        runs.append((th.nn.utils.parameters_to_vector(model.policy.parameters()).detach(),
                     model.rollout_buffer.actions.copy()))
    th.testing.assert_close(runs[0][0], runs[1][0], rtol=0, atol=0)
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    other = GenRL(FastReachEnv(), LinearGenerator(), seed=8).learn(192)
    assert not np.array_equal(other.rollout_buffer.actions, runs[0][1])


def test_save_load_predict_round_trip(tmp_path, monkeypatch):
    generator = LinearGenerator()
    model = GenRL(FastReachEnv(), generator, seed=0).learn(128)
    expected = model.predict(GOALS, deterministic=True)[0]
    model.save(tmp_path / "policy.zip")
    # An in-memory generator is saved beside the model and restored with sb3_genrl.generative.load.
    assert (tmp_path / "policy.generator.pt").exists()
    monkeypatch.setattr(genrl_module, "_load_generator", load_linear_generator)
    loaded = GenRL.load(tmp_path / "policy.zip")
    np.testing.assert_array_equal(loaded.predict(GOALS, deterministic=True)[0], expected)
    assert loaded.predict_trajectory(GOALS[0]).shape == (5, 2)
    np.testing.assert_allclose(loaded.predict_trajectory(GOALS[0]), generator.decode(expected[0])[0], rtol=1e-6)
    assert loaded.predict_trajectory(GOALS).shape == (4, 5, 2)
    # generator= overrides, a raw env is wrapped, and training goes on.
    override = GenRL.load(tmp_path / "policy.zip", env=FastReachEnv(), generator=generator)
    assert override.generator is generator
    np.testing.assert_array_equal(override.predict(GOALS, deterministic=True)[0], expected)
    override.learn(64, reset_num_timesteps=False)
    assert override.num_timesteps == 192


def test_load_without_generator_still_predicts(tmp_path):
    model = GenRL(FastReachEnv(), _UnsavableGenerator(), seed=0)
    model.save(tmp_path / "policy")
    loaded = GenRL.load(tmp_path / "policy")
    assert loaded.predict(GOALS[0], deterministic=True)[0].shape == (2,)
    with pytest.raises(ValueError, match="generator"):
        loaded.predict_trajectory(GOALS[0])


class _UnsavableGenerator(LinearGenerator):
    def save(self, path: str) -> None:
        raise NotImplementedError


def test_generator_path_is_kept(tmp_path, monkeypatch):
    generator_file = tmp_path / "gen.npz"
    LinearGenerator().save(str(generator_file))
    monkeypatch.setattr(genrl_module, "_load_generator", load_linear_generator)
    model = GenRL(FastReachEnv(), str(generator_file), seed=0)
    assert model.generator_path == str(generator_file)
    model.save(tmp_path / "policy.zip")
    assert not (tmp_path / "policy.generator.pt").exists()
    assert GenRL.load(tmp_path / "policy.zip").generator_path == str(generator_file)


@pytest.fixture
def fast_reach_task():
    """FastReachEnv as a registered task (the registry is how train_policy resolves tasks)."""
    from sb3_genrl.envs import TASKS, TaskSpec, register_task

    spec = TaskSpec(name="fast-reach", env_id=TOY_TASK_ID, env_class=FastReachEnv, horizon=5, goal_low=np.full(2, -0.8),
                    goal_high=np.full(2, 0.8), in_goal_region=lambda points: np.ones(len(points), dtype=bool),
                    cell_size=0.1, sample_expert=lambda rng: np.zeros((5, 7)), perturbation_scales=np.zeros(7),
                    is_valid=lambda info: True)
    register_task(spec)
    yield spec
    TASKS.pop(spec.name)
    gym.registry.pop(spec.env_id)


def test_train_policy_writes_curve_model_and_logs(fast_reach_task, tmp_path, capsys):
    from sb3_genrl.curves import read_monitor

    result = train_policy("fast-reach", LinearGenerator(), episodes=96, seed=0, out_dir=tmp_path, batch_episodes=32)
    assert result["episodes"] == 96 and result["iterations"] == 3
    # The Monitor file: one row per episode, its return the episode's reward.
    episodes = read_monitor(tmp_path / "episodes.monitor.csv")
    assert len(episodes["return"]) == 96 and np.all(episodes["length"] == 1) and np.all(episodes["return"] <= 0)
    # The learning curve: the mean and max reward of each iteration's 32 episodes, from the Monitor file.
    with open(result["csv_path"]) as file:
        rows = list(csv.DictReader(file))
    assert [float(row["episodes"]) for row in rows] == [32, 64, 96]
    np.testing.assert_allclose([float(row["mean_reward"]) for row in rows], episodes["return"].reshape(3, 32).mean(axis=1))
    np.testing.assert_allclose([float(row["max_reward"]) for row in rows], episodes["return"].reshape(3, 32).max(axis=1))
    assert result["best_mean_reward"] == max(float(row["mean_reward"]) for row in rows)
    # SB3's logger: one row per iteration's update, in progress.csv and in TensorBoard.
    with open(tmp_path / "logs" / "progress.csv") as file:
        progress = [row for row in csv.DictReader(file) if row.get("train/kl")]
    assert len(progress) == 3 and all(float(row["train/kl"]) >= 0 for row in progress)
    # GenRL's own mean reward of each iteration (from its rollout buffer) is the Monitor's, up to its 6 decimals.
    np.testing.assert_allclose([float(row["train/mean_reward"]) for row in progress],
                               [float(row["mean_reward"]) for row in rows], atol=1e-6)
    assert any((tmp_path / "logs").glob("events.out.tfevents.*"))
    assert (tmp_path / "learning_curve.png").stat().st_size > 0
    assert GenRL.load(result["model_path"], generator=LinearGenerator()).predict(GOALS[0])[0].shape == (2,)
    with pytest.raises(ValueError, match="unknown task"):
        train_policy("curling", LinearGenerator(), episodes=10, out_dir=tmp_path)
    # Besides the registry's tasks, any registered Gymnasium id (a user's own env) is accepted.
    if TOY_ID not in gym.registry:
        gym.register(TOY_ID, entry_point=FastReachEnv)
    own = train_policy(TOY_ID, LinearGenerator(), episodes=32, seed=0, out_dir=tmp_path / "own", batch_episodes=32)
    assert own["task"] == TOY_ID and own["iterations"] == 1 and len(read_monitor(own["episodes_csv_path"])["return"]) == 32
    argv = ["train-policy", "--task", "curling", "--generator", "x.pt", "--episodes", "8", "--out", str(tmp_path)]
    with pytest.raises(SystemExit) as exit_info:  # --task takes its choices from the registry
        cli_main(argv)
    assert exit_info.value.code == 2 and "invalid choice: 'curling'" in capsys.readouterr().err
    argv = ["train-policy", "--task", "fast-reach", "--generator", str(tmp_path / "missing.pt"), "--episodes", "8",
            "--out", str(tmp_path)]
    with pytest.raises(SystemExit):
        cli_main(argv)
    assert "missing.pt' does not exist" in capsys.readouterr().err


def test_train_policy_plays_several_envs_in_their_own_processes(fast_reach_task, tmp_path):
    """n_envs > 1: SubprocVecEnv under VecMonitor; every episode recorded, the run reproducible from its seed."""
    from sb3_genrl.curves import read_monitor

    runs = [train_policy("fast-reach", LinearGenerator(), episodes=64, seed=3, out_dir=tmp_path / name,
                         batch_episodes=32, n_envs=2) for name in ("a", "b")]
    assert runs[0]["episodes"] == 64 and runs[0]["iterations"] == 2 and runs[0]["n_envs"] == 2
    episodes = [read_monitor(run["episodes_csv_path"]) for run in runs]
    assert len(episodes[0]["return"]) == 64 and np.all(episodes[0]["length"] == 1)
    assert np.all(np.isfinite(episodes[0]["cpu_seconds"]))
    np.testing.assert_array_equal(episodes[0]["return"], episodes[1]["return"])
    assert GenRL.load(runs[0]["model_path"], generator=LinearGenerator()).n_steps == 16  # N = 16 steps x 2 envs
    with pytest.raises(ValueError, match=r"batch_episodes \(32\) must be a multiple of n_envs \(3\)"):
        train_policy("fast-reach", LinearGenerator(), episodes=64, out_dir=tmp_path / "c", batch_episodes=32, n_envs=3)
    assert not (tmp_path / "c").exists()


def test_several_envs_without_a_main_guard_fail_with_a_clear_error(hockey_generator, tmp_path):
    """A script that starts env processes at import time: both the env process and the script say what to do."""
    import subprocess
    import sys

    script = tmp_path / "no_guard.py"
    script.write_text("from sb3_genrl.genrl import train_policy\n"
                      f"train_policy('hockey', {hockey_generator!r}, episodes=4, batch_episodes=2, n_envs=2, "
                      f"out_dir={str(tmp_path / 'run')!r})\n")
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode != 0
    assert "RuntimeError: the 2 env processes did not start" in run.stderr
    assert 'under `if __name__ == "__main__":`' in run.stderr
    assert not (tmp_path / "run" / "model.zip").exists()


def test_on_paper_task_with_saved_generator(tmp_path):
    """A short run on the hockey task with an untrained beta-VAE saved to a file, then load -> predict_trajectory."""
    from sb3_genrl.generative import make_generator

    generator = make_generator("VAE1", horizon=69, action_dim=7, device="cpu")
    generator.save(str(tmp_path / "vae.pt"))
    model = GenRL("GenRL/Hockey-v0", str(tmp_path / "vae.pt"), n_steps=16, seed=0).learn(32)
    assert model.generator_path == str(tmp_path / "vae.pt") and model.env.get_attr("use_fast_path")[0]
    assert np.isfinite(model.logger.name_to_value["train/mean_reward"])
    model.save(tmp_path / "policy.zip")
    loaded = GenRL.load(tmp_path / "policy.zip", env=gym.make("GenRL/Hockey-v0"))
    goal = np.array([1.0, 0.1], dtype=np.float32)
    np.testing.assert_array_equal(loaded.predict(goal, deterministic=True)[0], model.predict(goal, deterministic=True)[0])
    assert loaded.predict_trajectory(goal).shape == (69, 7)


def test_a_generator_file_is_loaded_onto_the_models_device(tmp_path, monkeypatch):
    """GenRL(..., "vae.pt", device=D), GenRL.load(..., device=D) and load_policy(..., device=D) place the generator
    they load from a file on D."""
    import sb3_genrl.generative as generative
    from sb3_genrl.generative import make_generator
    from sb3_genrl.genrl.loading import load_policy

    make_generator("VAE1", horizon=69, action_dim=7, device="cpu").save(str(tmp_path / "vae.pt"))
    devices, real_load = [], generative.load
    monkeypatch.setattr(generative, "load", lambda path, device="auto": devices.append(str(device)) or real_load(path, device))
    model = GenRL("GenRL/Hockey-v0", str(tmp_path / "vae.pt"), n_steps=8, device="cpu")
    model.save(tmp_path / "policy.zip")
    loaded = GenRL.load(tmp_path / "policy.zip", device="cpu")
    safe = load_policy(tmp_path / "policy.zip", gym.make("GenRL/Hockey-v0"), device="cpu")
    assert devices == ["cpu", "cpu", "cpu"] and safe.generator.device == th.device("cpu")
    assert model.generator.device == model.device and loaded.generator.device == loaded.device == th.device("cpu")



def test_evaluate_on_goals_plays_the_deterministic_policy(tmp_path):
    from sb3_genrl.generative import make_generator
    from sb3_genrl.genrl import evaluate_on_goals

    generator = make_generator("VAE1", horizon=69, action_dim=7, device="cpu")
    model = GenRL("GenRL/Hockey-v0", generator, n_steps=8, seed=0)
    goals, rewards, infos = evaluate_on_goals(model, "hockey", goals=5, seed=7)
    # Independently: the goals from the same seed, each played step by step through the wrapped env.
    task = gym.make("GenRL/Hockey-v0").unwrapped
    rng = np.random.default_rng(7)
    np.testing.assert_array_equal(goals, np.array([task.sample_goal(rng) for _ in range(5)], dtype=np.float32))
    for goal, reward, info in zip(goals, rewards, infos, strict=True):
        task.reset(options={"goal": goal})
        for action in model.predict_trajectory(goal):
            _, step_reward, terminated, _, step_info = task.step(action)
        assert terminated and step_reward == pytest.approx(reward, abs=1e-9)
        assert step_info["table_contacts"] == info["table_contacts"]
    with pytest.raises(ValueError, match="unknown task"):
        evaluate_on_goals(model, "golf")


def test_interrupted_save_keeps_the_previous_policy_file(tmp_path, monkeypatch):
    from stable_baselines3.common import base_class

    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0)
    model.save(tmp_path / "policy")  # SB3 adds .zip
    before = (tmp_path / "policy.zip").read_bytes()
    real_save = base_class.save_to_zip_file

    def killed_save(save_path, *args, **kwargs):
        real_save(save_path, *args, **kwargs)
        with open(save_path, "r+b") as file:
            file.truncate(100)  # what a kill during the write leaves behind
        raise KeyboardInterrupt

    monkeypatch.setattr(base_class, "save_to_zip_file", killed_save)
    with pytest.raises(KeyboardInterrupt):
        model.save(tmp_path / "policy.zip")
    assert (tmp_path / "policy.zip").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["policy.generator.pt", "policy.zip"]


class FlattenBatchNormDropoutExtractor(BaseFeaturesExtractor):
    """Stable-Baselines3's test extractor (tests/test_train_eval_mode.py): batch norm, then dropout."""

    def __init__(self, observation_space: gym.Space) -> None:
        super().__init__(observation_space, get_flattened_obs_dim(observation_space))
        self.flatten = th.nn.Flatten()
        self.batch_norm = th.nn.BatchNorm1d(self._features_dim)
        self.dropout = th.nn.Dropout(0.5)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.dropout(self.batch_norm(self.flatten(observations)))


BATCH_NORM_DROPOUT = {"net_arch": [16, 16], "features_extractor_class": FlattenBatchNormDropoutExtractor}


def batch_norm_stats(model: GenRL) -> tuple[th.Tensor, th.Tensor]:
    batch_norm = model.policy.features_extractor.batch_norm
    return batch_norm.bias.detach().clone(), batch_norm.running_mean.clone()


def mean_reward_on_goals(model: GenRL) -> float:
    latents, _ = model.predict(GOALS, deterministic=True)
    rewards, _ = FastReachEnv().play_trajectories(LinearGenerator().decode(latents), GOALS)
    return float(np.mean(rewards))


@pytest.mark.parametrize("e_step", ["trpo", "kl_penalty"])
@pytest.mark.parametrize("seed", range(5))
def test_train_with_dropout_and_batch_norm(e_step, seed):
    """SB3's train/eval-mode test for GenRL: the E-step sees the policy in evaluation mode, training works."""
    model = GenRL(FastReachEnv(), LinearGenerator(), e_step=e_step, policy_kwargs=BATCH_NORM_DROPOUT, seed=seed)
    bias_before, running_mean_before = batch_norm_stats(model)
    before = mean_reward_on_goals(model)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no float() of a tensor that requires grad, no invalid distribution
        model.learn(1280)
    bias_after, running_mean_after = batch_norm_stats(model)
    assert not th.isclose(bias_before, bias_after).all() and not th.isclose(running_mean_before, running_mean_after).all()
    assert all(bool(th.isfinite(p).all()) for p in model.policy.parameters())
    assert before < -0.35 and mean_reward_on_goals(model) > -0.1  # the optimum is 0
    if e_step == "trpo":
        assert model.logger.name_to_value["train/kl"] < model.target_kl


def test_collect_rollouts_and_predict_leave_batch_norm_alone_and_predict_is_deterministic():
    model = GenRL(FastReachEnv(), LinearGenerator(), policy_kwargs=BATCH_NORM_DROPOUT, n_steps=64, seed=1)
    stats_before = batch_norm_stats(model)
    _, callback = model._setup_learn(total_timesteps=128)
    for _ in range(2):
        model.collect_rollouts(model.get_env(), callback, model.rollout_buffer, n_rollout_steps=model.n_steps)
    first, _ = model.predict(GOALS, deterministic=True)
    for _ in range(5):
        np.testing.assert_array_equal(model.predict(GOALS, deterministic=True)[0], first)
    for before, after in zip(stats_before, batch_norm_stats(model), strict=True):
        th.testing.assert_close(before, after, rtol=0, atol=0)


def test_trpo_e_step_rejects_non_positive_curvature():
    from sb3_genrl.genrl.e_step import trpo_e_step

    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=64).learn(64)
    data = next(model.rollout_buffer.get(batch_size=None))
    batch = (data.observations, data.actions, data.old_log_prob, (data.advantages - data.advantages.mean()))
    q = copy.deepcopy(model.policy)
    before = th.nn.utils.parameters_to_vector(q.parameters()).detach().clone()
    # A damping of -1000 makes F + damping I negative definite: the quadratic KL model has no positive curvature.
    stats = trpo_e_step(q, model.policy, batch, target_kl=0.01, cg_max_steps=15, cg_damping=-1000.0,
                        line_search_shrinking_factor=0.8, line_search_max_iter=10)
    assert stats["line_search_success"] == 0.0 and stats["step_size"] == 0.0 and np.isfinite(stats["policy_objective"])
    th.testing.assert_close(th.nn.utils.parameters_to_vector(q.parameters()).detach(), before, rtol=0, atol=0)


def test_trpo_e_step_rejects_candidates_whose_distribution_is_invalid():
    from sb3_genrl.genrl.e_step import trpo_e_step

    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0)
    observations = th.zeros(64, 2, device=model.device)
    with th.no_grad():
        pi = model.policy.get_distribution(observations)
        offsets = th.cat([th.full((32, 2), 0.1), th.full((32, 2), 2.0)]) * th.tensor([[1.0, -1.0]])
        actions = pi.distribution.mean + offsets.to(model.device)
        advantages = th.cat([th.ones(32), -th.ones(32)]).to(model.device)
        batch = (observations, actions, pi.log_prob(actions), advantages)
    # Actions near the mean are good, far ones bad: the natural step narrows the policy, and with a KL bound of
    # 1e6 every candidate's standard deviation underflows to 0, which torch.distributions refuses.
    q = copy.deepcopy(model.policy)
    stats = trpo_e_step(q, model.policy, batch, target_kl=1e6, cg_max_steps=15, cg_damping=0.1,
                        line_search_shrinking_factor=0.8, line_search_max_iter=10)
    assert stats["line_search_success"] == 0.0 and stats["accepted_fraction"] == 0.0
    for parameter, original in zip(q.parameters(), model.policy.parameters(), strict=True):
        th.testing.assert_close(parameter, original, rtol=0, atol=0)


def test_box_scaler_on_unbounded_observations_does_not_warn():
    from sb3_genrl.genrl.policies import BoxScaler

    space = gym.make("Reacher-v5").observation_space  # every bound infinite
    mixed = gym.spaces.Box(np.array([-np.inf, 0.0, -2.0], np.float32), np.array([np.inf, np.inf, 2.0], np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scaler = BoxScaler(space)
        observations = th.as_tensor(space.sample()[None])
        th.testing.assert_close(scaler(observations), observations)  # unbounded dimensions pass unchanged
        mixed_scaler = BoxScaler(mixed)
        out = mixed_scaler(th.tensor([[5.0, 3.0, 1.0]]))
    th.testing.assert_close(out, th.tensor([[5.0, 3.0, 0.5]]))


class _LogStdRecorder(BaseCallback):
    """The policy's log-std at the start of every rollout (after every update but the last) and at the end."""

    def __init__(self) -> None:
        super().__init__()
        self.values: list[np.ndarray] = []

    def _on_rollout_start(self) -> None:
        self.values.append(self.model.policy.log_std.detach().cpu().numpy().copy())

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        self.values.append(self.model.policy.log_std.detach().cpu().numpy().copy())


@pytest.mark.parametrize("e_step", ["trpo", "kl_penalty"])
def test_spread_moves_at_most_max_log_std_change_per_iteration(e_step):
    changes = {}
    for bound in (None, 0.01):
        recorder = _LogStdRecorder()
        GenRL(FastReachEnv(), LinearGenerator(), e_step=e_step, seed=0, n_steps=32,
              max_log_std_change=bound).learn(8 * 32, callback=recorder)
        changes[bound] = np.abs(np.diff(np.array(recorder.values), axis=0))
        assert len(changes[bound]) == 8
    assert changes[None].max() > 0.02  # unbounded, the spread moves faster than the bound allows
    assert changes[0.01].max() <= 0.01 + 1e-6
    assert changes[0.01].min() >= 0.01 - 1e-6  # and here the spread shrinks as fast as the bound lets it
    with pytest.raises(ValueError, match="max_log_std_change must be positive or None, got 0"):
        GenRL(FastReachEnv(), LinearGenerator(), max_log_std_change=0)


class _BatchRecorder(BaseCallback):
    """Each iteration's observations and returns, as collected."""

    def __init__(self) -> None:
        super().__init__()
        self.batches: list[tuple[np.ndarray, np.ndarray]] = []

    def _on_rollout_end(self) -> None:
        buffer = self.model.rollout_buffer
        self.batches.append((buffer.observations.reshape(-1, buffer.observations.shape[-1]).copy(),
                             buffer.returns.flatten().copy()))

    def _on_step(self) -> bool:
        return True


def test_value_memory_holds_the_last_value_history_batches():
    recorder = _BatchRecorder()
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, value_history=3)
    model.learn(5 * 16, callback=recorder)
    assert len(recorder.batches) == 5 and len(model._value_memory) == 3
    for (observations, returns), (expected_observations, expected_returns) in zip(
            model._value_memory, recorder.batches[-3:], strict=True):  # the same rows, in another order
        observations, returns = observations.cpu().numpy(), returns.cpu().numpy()
        order, expected_order = np.argsort(returns), np.argsort(expected_returns)
        np.testing.assert_allclose(observations[order], expected_observations[expected_order])
        np.testing.assert_allclose(returns[order], expected_returns[expected_order])


@pytest.mark.parametrize(("value_history", "expected"), [(1, 1.0), (2, 0.5)])
def test_value_function_is_the_least_squares_fit_over_the_remembered_batches(value_history, expected):
    # The same contexts with returns 0 in the remembered batch and 1 in the current one: the least-squares value is
    # 1 when only the current batch counts, and the mean 0.5 over both batches.
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, value_history=value_history,
                  n_critic_updates=2000)
    model.learn(16)
    observations = next(model.rollout_buffer.get(batch_size=None)).observations
    model._value_memory.clear()
    model._value_memory.append((observations, th.zeros(16, device=model.device)))
    model.rollout_buffer.returns[:] = 1.0
    model._fit_value_function()
    with th.no_grad():
        values = model.policy.predict_values(observations).flatten().cpu().numpy()
    assert abs(values.mean() - expected) < 0.02
    np.testing.assert_allclose(values, expected, atol=0.1)


def test_value_history_is_checked_and_not_saved(tmp_path):
    with pytest.raises(ValueError, match="value_history must be a positive integer, got 0"):
        GenRL(FastReachEnv(), LinearGenerator(), value_history=0)
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, value_history=4)
    model.learn(32)
    model.save(tmp_path / "model")
    loaded = GenRL.load(tmp_path / "model.zip", env=FastReachEnv(), generator=LinearGenerator())
    assert loaded.value_history == 4 and len(loaded._value_memory) == 0 and loaded._value_memory.maxlen == 4


def test_observation_batches_join_and_index_as_tensors_and_dicts():
    from sb3_genrl.genrl.value import concatenate, take

    first, second = th.arange(6.0).reshape(3, 2), th.arange(6.0, 10.0).reshape(2, 2)
    joined = concatenate([first, second])
    th.testing.assert_close(joined, th.arange(10.0).reshape(5, 2))
    th.testing.assert_close(take(joined, th.tensor([4, 0])), th.tensor([[8.0, 9.0], [0.0, 1.0]]))
    dicts = concatenate([{"goal": first, "t": th.zeros(3)}, {"goal": second, "t": th.ones(2)}])
    th.testing.assert_close(dicts["goal"], joined)
    th.testing.assert_close(take(dicts, th.tensor([3]))["t"], th.ones(1))


class _WeightRecorder(BaseCallback):
    """The policy's weights after each iteration (recorded before the next rollout, and at the end)."""

    def __init__(self) -> None:
        super().__init__()
        self.weights: list[dict[str, np.ndarray]] = []

    def _record(self) -> None:
        if self.model._n_updates > len(self.weights):
            self.weights.append({k: v.detach().cpu().numpy().copy() for k, v in self.model.policy.named_parameters()})

    def _on_rollout_start(self) -> None:
        self._record()

    def _on_training_end(self) -> None:
        self._record()

    def _on_step(self) -> bool:
        return True


def test_policy_averaging_is_the_start_corrected_moving_average_and_acts(tmp_path):
    from sb3_genrl.genrl.loading import load_policy

    recorder, decay = _WeightRecorder(), 0.7
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16, policy_averaging=decay)
    model.learn(6 * 16, callback=recorder)
    assert len(recorder.weights) == 6
    # Brute force: sum_i d^(n-i) theta_i / sum_i d^(n-i) over the iterates theta_1..6 (the initial policy excluded).
    factors = decay ** np.arange(5, -1, -1)
    for name, value in model.policy_average.named_parameters():
        expected = sum(f * w[name] for f, w in zip(factors, recorder.weights, strict=True)) / factors.sum()
        np.testing.assert_allclose(value.detach().cpu().numpy(), expected, rtol=1e-5, atol=1e-6)
    average_weight = model.policy_average.action_net.weight.detach().cpu().numpy()
    assert not np.allclose(average_weight, recorder.weights[-1]["action_net.weight"])
    # predict acts with the average, here and after saving and loading (with SB3's loader and without unpickling).
    averaged = model.policy_average.predict(GOALS, deterministic=True)[0]
    np.testing.assert_allclose(model.predict(GOALS, deterministic=True)[0], averaged)
    assert not np.allclose(model.policy.predict(GOALS, deterministic=True)[0], averaged)
    model.save(tmp_path / "model.zip")
    loaded = GenRL.load(tmp_path / "model.zip", generator=LinearGenerator())
    np.testing.assert_allclose(loaded.predict(GOALS, deterministic=True)[0], averaged, rtol=1e-6)
    safe = load_policy(tmp_path / "model.zip", FastReachEnv(), generator=LinearGenerator())
    np.testing.assert_allclose(safe.predict(GOALS, deterministic=True)[0], averaged, rtol=1e-6)
    # Without averaging nothing changes: predict is the policy's own.
    plain = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=16)
    assert plain.policy_average is None and "policy_average" not in plain._get_torch_save_params()[0]
    for bad in (0, 1, 1.5):
        with pytest.raises(ValueError, match=f"policy_averaging must be between 0 and 1 \\(exclusive\\) or None, got {bad}"):
            GenRL(FastReachEnv(), LinearGenerator(), policy_averaging=bad)


def _corners(dim: int) -> th.Tensor:
    """The 2^dim corners of [-1, 1]^dim."""
    return th.tensor(list(itertools.product((-1.0, 1.0), repeat=dim)))


def test_limit_log_std_change_is_the_largest_change_over_the_box_by_brute_force():
    from sb3_genrl.genrl.policies import ContextStdPolicy, limit_log_std_change, log_std_parameters

    space = gym.spaces.Box(-2.0, 3.0, (3,), np.float32)
    policy = ContextStdPolicy(space, gym.spaces.Box(-3, 3, (4,), np.float32), lambda _: 1e-3,
                              features_extractor_class=BoxScaler)
    before = log_std_parameters(policy)
    th.testing.assert_close(before["weight"], th.zeros(4, 3))  # it starts independent of the context
    generator = th.Generator().manual_seed(0)
    corners, inside = _corners(3), th.rand(1000, 3, generator=generator) * 2 - 1
    change = lambda features, params: features @ params["weight"].T + params["bias"] - before["bias"]  # noqa: E731
    for size, bound in ((0.05, 0.02), (0.001, 0.02)):  # a change beyond the bound, and one within it
        with th.no_grad():
            policy.log_std_net.weight.copy_(size * th.randn(4, 3, generator=generator))
            policy.log_std_net.bias.copy_(before["bias"] + size * th.randn(4, generator=generator))
        unbounded = log_std_parameters(policy)
        limit_log_std_change(policy, before, bound)
        after = log_std_parameters(policy)
        # A linear function's largest size over the box is at one of its corners: brute force over them.
        largest_before = change(corners, unbounded).abs().max().item()
        largest = change(corners, after).abs().max().item()
        assert change(inside, after).abs().max().item() <= largest + 1e-7
        if largest_before <= bound:  # kept as it was
            th.testing.assert_close(after, unbounded)
            continue
        assert largest == pytest.approx(bound, rel=1e-5)  # scaled back exactly to the bound ...
        for name in ("weight", "bias"):  # ... by one factor for the whole change: its direction is kept
            th.testing.assert_close(after[name] - before[name], bound / largest_before * (unbounded[name] - before[name]))


class _ContextStdRecorder(BaseCallback):
    """The policy's log std at the corners of the context box, at the start of every rollout and at the end."""

    def __init__(self, low: float, high: float) -> None:
        super().__init__()
        self.corners = low + (_corners(2) + 1) / 2 * (high - low)
        self.values: list[np.ndarray] = []

    def _record(self) -> None:
        with th.no_grad():
            corners = self.corners.to(self.model.device)
            self.values.append(self.model.policy.get_distribution(corners).distribution.stddev.log().cpu().numpy())

    def _on_rollout_start(self) -> None:
        self._record()

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        self._record()


@pytest.mark.parametrize("e_step", ["trpo", "kl_penalty"])
def test_context_std_policy_spread_depends_on_the_context_within_its_trust_region(e_step, tmp_path):
    from sb3_genrl.genrl.loading import load_policy
    from sb3_genrl.genrl.policies import ContextStdPolicy

    low, high = FastReachEnv.context_space.low[0], FastReachEnv.context_space.high[0]
    changes = {}
    for bound in (None, 0.01):
        recorder = _ContextStdRecorder(low, high)
        model = GenRL("ContextStdPolicy", FastReachEnv(), LinearGenerator(), e_step=e_step, seed=0, n_steps=32,
                      max_log_std_change=bound)
        model.learn(8 * 32, callback=recorder)
        values = np.array(recorder.values)
        np.testing.assert_allclose(values[0], 0.0, atol=1e-7)  # the prior's std at first, for every context
        changes[bound] = np.abs(np.diff(values, axis=0))
    assert isinstance(model.policy, ContextStdPolicy) and not hasattr(model.policy, "log_std")
    assert changes[None].max() > 0.02
    assert changes[0.01].max() <= 0.01 + 1e-6  # at every corner of the box, hence everywhere in it
    assert np.ptp(values[-1], axis=0).max() > 1e-4  # the spread differs between contexts
    # The policy's distributions agree however they are computed, and survive saving and loading.
    observations = th.as_tensor(GOALS, device=model.device)
    actions, _, log_prob = model.policy(observations)
    _, evaluated, entropy = model.policy.evaluate_actions(observations, actions)
    distribution = model.policy.get_distribution(observations)
    th.testing.assert_close(evaluated, log_prob)
    th.testing.assert_close(distribution.log_prob(actions), log_prob)
    th.testing.assert_close(distribution.entropy(), entropy)
    model.save(tmp_path / "model.zip")
    for loaded in (GenRL.load(tmp_path / "model.zip", generator=LinearGenerator()),
                   load_policy(tmp_path / "model.zip", FastReachEnv(), generator=LinearGenerator(), device=model.device)):
        assert isinstance(loaded.policy, ContextStdPolicy)
        th.testing.assert_close(loaded.policy.get_distribution(observations).distribution.stddev,
                                distribution.distribution.stddev)
        np.testing.assert_allclose(loaded.predict(GOALS, deterministic=True)[0], model.predict(GOALS, deterministic=True)[0])


def test_context_std_trust_region_needs_a_bounded_context():
    unbounded = DummyVecEnv([lambda: LatentActionWrapper(FastReachEnv(), LinearGenerator())])
    unbounded.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    with pytest.raises(ValueError, match="needs a bounded Box context scaled by BoxScaler"):
        GenRL("ContextStdPolicy", unbounded, max_log_std_change=0.01)
    GenRL("ContextStdPolicy", unbounded)  # without the trust region the spread may depend on any features


def test_check_genrl_kwargs_refuses_unknown_names_and_policies():
    from sb3_genrl.genrl.train import check_genrl_kwargs

    settings = {"policy": "ContextStdPolicy", "target_kl": 0.03, "policy_kwargs": {"net_arch": [8]}}
    assert check_genrl_kwargs(settings) is settings
    with pytest.raises(ValueError, match=r"--genrl-kwargs: 'target_kll' is not a GenRL setting"):
        check_genrl_kwargs({"target_kll": 0.03}, "--genrl-kwargs")
    with pytest.raises(ValueError, match=r"'a', 'seed' are not GenRL settings"):  # where it runs is not a setting
        check_genrl_kwargs({"seed": 1, "a": 2})
    with pytest.raises(ValueError, match="unknown policy 'CnnPolicy'"):
        check_genrl_kwargs({"policy": "CnnPolicy"})
    with pytest.raises(TypeError, match="expected a dict"):
        check_genrl_kwargs([("target_kl", 0.03)])
    # the values GenRL would refuse, before any work: alone, and against the others' defaults (e_step="trpo")
    with pytest.raises(ValueError, match="--genrl-kwargs: value_history must be a positive integer, got 0"):
        check_genrl_kwargs({"value_history": 0}, "--genrl-kwargs")
    with pytest.raises(ValueError, match="hindsight_history=2 keeps relabelled pulls, which needs hindsight=True"):
        check_genrl_kwargs({"hindsight_history": 2})
    with pytest.raises(ValueError, match="hindsight=True needs e_step='trpo'"):
        check_genrl_kwargs({"hindsight": True, "e_step": "kl_penalty"})
    assert check_genrl_kwargs({"hindsight": True, "hindsight_history": 2}) == {"hindsight": True, "hindsight_history": 2}


def test_genrl_settings_record_the_policy_arguments_as_json():
    from sb3_genrl.genrl.train import genrl_settings

    settings = genrl_settings({"policy_kwargs": {"net_arch": {"pi": [64, 64, 64], "vf": (64, 64)},
                                                 "activation_fn": th.nn.Tanh},
                               "learning_rate": lambda progress: 1e-3 * progress})
    assert settings["policy_kwargs"] == {"net_arch": {"pi": [64, 64, 64], "vf": [64, 64]},
                                         "activation_fn": "torch.nn.modules.activation.Tanh"}
    assert "learning_rate" not in settings  # a schedule is no JSON value
    assert genrl_settings({"policy_kwargs": {"net_arch": [8], "optimizer_kwargs": {"eps": object()}}}).get(
        "policy_kwargs", "left out") == "left out"


def test_genrl_kwargs_argument_parses_and_checks_json():
    import argparse

    from sb3_genrl.genrl.train import genrl_kwargs_argument, genrl_kwargs_override_argument

    # settings laid over a task's are checked by name only: their values may need the task's (hindsight=True)
    assert genrl_kwargs_override_argument('{"hindsight_regression": 8}') == {"hindsight_regression": 8}
    with pytest.raises(argparse.ArgumentTypeError, match="needs hindsight=True"):
        genrl_kwargs_argument('{"hindsight_regression": 8}')
    with pytest.raises(argparse.ArgumentTypeError, match="'x' is not a GenRL setting"):
        genrl_kwargs_override_argument('{"x": 1}')

    assert genrl_kwargs_argument('{"target_kl": 0.03}') == {"target_kl": 0.03}
    for text, message in (("{", "not JSON"), ("[1]", "expected a dict"), ('{"x": 1}', "'x' is not a GenRL setting")):
        with pytest.raises(argparse.ArgumentTypeError, match=message):
            genrl_kwargs_argument(text)


class HindsightReachEnv(FastReachEnv):
    """FastReachEnv whose pulls are relabelled with the point they reached (reward 0 there, the maximum)."""

    def hindsight(self, info):
        return np.asarray(info["reached"], dtype=np.float32), 0.0


class _EStepBatchRecorder(GenRL):
    """GenRL that keeps its first E-step batch, with V and the policy's log-probabilities then."""

    def _e_step(self, q, batch):
        if not hasattr(self, "recorded"):
            observations = batch[0]
            with th.no_grad():
                values = self.policy.predict_values(observations).flatten()
                log_prob = self.policy.get_distribution(observations).log_prob(batch[1])
            self.recorded = ([t.clone() for t in batch], values, log_prob, self.rollout_buffer.advantages.copy())
        return super()._e_step(q, batch)


def test_hindsight_relabels_each_pull_with_the_point_its_own_action_reached():
    # Two envs, so a pull paired with another pull's action would show. The linear generator's reached point is
    # computed here from each relabelled action on its own (decode, clip the steps, sum), independently of the infos.
    envs = DummyVecEnv([lambda: LatentActionWrapper(HindsightReachEnv(), LinearGenerator())] * 2)
    model = _EStepBatchRecorder("MlpPolicy", envs, seed=3, n_steps=16, hindsight=True)
    model.learn(32)
    (observations, actions, log_prob_pi, advantages), values, log_prob, buffer_advantages = model.recorded
    n_played = 32
    played_actions = np.clip(actions[:n_played].numpy(), -3, 3)
    reached = np.clip(LinearGenerator().decode(played_actions), -1, 1).sum(axis=1)
    inside = np.all(np.abs(reached) <= 0.8, axis=1)
    assert 0 < inside.sum() < n_played  # some pulls land outside the context box, and are left out
    assert len(observations) == n_played + inside.sum()
    relabelled = slice(n_played, None)
    relabelled_actions = np.clip(actions[relabelled].numpy(), -3, 3)
    expected_contexts = np.clip(LinearGenerator().decode(relabelled_actions), -1, 1).sum(axis=1)
    np.testing.assert_allclose(observations[relabelled].numpy(), expected_contexts, atol=1e-5)
    np.testing.assert_allclose(np.sort(actions[relabelled].numpy(), axis=0),
                               np.sort(actions[:n_played].numpy()[inside], axis=0))
    np.testing.assert_allclose(log_prob_pi[relabelled].numpy(), log_prob[relabelled].numpy(), rtol=1e-5)
    raw = th.as_tensor(buffer_advantages.flatten())
    expected = (0.0 - values[relabelled] - raw.mean()) / (raw.std() + 1e-8)
    np.testing.assert_allclose(advantages[relabelled].numpy(), expected.numpy(), rtol=1e-4, atol=1e-5)
    assert model.logger.name_to_value["train/hindsight_pulls"] == pytest.approx(inside.sum() / n_played)


class _EveryBatchRecorder(GenRL):
    """GenRL that keeps the first E-step batch of every iteration, with the policy's log-probabilities then and the
    actions as played."""

    def _e_step(self, q, batch):
        self.recorded = getattr(self, "recorded", [])
        if len(self.recorded) == self._n_updates:
            with th.no_grad():
                log_prob = self.policy.get_distribution(batch[0]).log_prob(batch[1])
            played = self.rollout_buffer.actions.reshape(-1, self.action_space.shape[0]).copy()
            self.recorded.append(([t.clone() for t in batch], log_prob, played))
        return super()._e_step(q, batch)


def test_hindsight_history_keeps_the_relabelled_pulls_of_the_last_batches():
    model = _EveryBatchRecorder(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=1, n_steps=16,
                                hindsight=True, hindsight_history=2)
    model.learn(64)  # four iterations
    inside_actions = []
    for iteration, ((observations, actions, log_prob_pi, _), log_prob, played) in enumerate(model.recorded):
        reached = np.clip(LinearGenerator().decode(np.clip(played, -3, 3)), -1, 1).sum(axis=1)
        inside_actions.append(played[np.all(np.abs(reached) <= 0.8, axis=1)])
        kept = np.concatenate(inside_actions[max(0, iteration - 1):])  # this batch's and the one before
        relabelled = slice(len(played), None)
        assert len(observations) == len(played) + len(kept)
        np.testing.assert_allclose(np.sort(actions[relabelled].numpy(), axis=0), np.sort(kept, axis=0))
        expected_contexts = np.clip(LinearGenerator().decode(np.clip(actions[relabelled].numpy(), -3, 3)), -1, 1)
        np.testing.assert_allclose(observations[relabelled].numpy(), expected_contexts.sum(axis=1), atol=1e-5)
        # the earlier batch's pulls are weighed with the current policy, not the one that played them
        np.testing.assert_allclose(log_prob_pi[relabelled].numpy(), log_prob[relabelled].numpy(), rtol=1e-5)
    assert len(model.recorded) == 4 and all(len(actions) > 0 for actions in inside_actions)


def test_hindsight_history_is_checked():
    for value in (0, 1.5):
        with pytest.raises(ValueError, match="hindsight_history must be a positive integer"):
            GenRL(FastReachEnv(), LinearGenerator(), hindsight=True, hindsight_history=value)
    with pytest.raises(ValueError, match="hindsight_history=4 keeps relabelled pulls, which needs hindsight=True"):
        GenRL(FastReachEnv(), LinearGenerator(), hindsight_history=4)


class _NothingReachedEnv(FastReachEnv):
    def hindsight(self, info):
        return None


def test_hindsight_with_no_pull_to_relabel_leaves_the_batch_as_played():
    model = _EStepBatchRecorder("MlpPolicy", LatentActionWrapper(_NothingReachedEnv(), LinearGenerator()), seed=0,
                                n_steps=16, hindsight=True)
    model.learn(16)
    observations = model.recorded[0][0]
    assert len(observations) == 16 and model.logger.name_to_value["train/hindsight_pulls"] == 0


def test_hindsight_reaches_new_goals_sooner_on_the_toy():
    distances = {}
    for hindsight in (False, True):
        model = GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=0, hindsight=hindsight)
        model.learn(640)
        after = np.array([model.predict(goal, deterministic=True)[0] for goal in GOALS])
        distances[hindsight] = np.abs(after - np.array([optimal_latent(goal) for goal in GOALS])).max()
    assert distances[True] < 0.6 * distances[False]  # 0.013 against 0.031 (seeds 1 and 2: 0.52 and 0.41 times)


@pytest.mark.parametrize("policy_name", ["MlpPolicy", "ContextStdPolicy"])
def test_mean_parameters_are_the_actors_without_its_spread(policy_name):
    from sb3_genrl.genrl.policies import actor_parameters
    from sb3_genrl.genrl.regression import mean_parameters

    policy = GenRL(policy_name, FastReachEnv(), LinearGenerator(), seed=0).policy
    names = {id(parameter): name for name, parameter in policy.named_parameters()}
    chosen = {names[id(parameter)] for parameter in mean_parameters(policy)}
    spread = {names[id(parameter)] for parameter in actor_parameters(policy)} - chosen
    assert chosen and all(name.startswith(("mlp_extractor.policy_net.", "action_net.")) for name in chosen)
    assert spread == ({"log_std"} if policy_name == "MlpPolicy" else {"log_std_net.weight", "log_std_net.bias"})
    # the mean's gradient reaches every chosen parameter and nothing else of the actor
    observations = th.rand(8, 2) * 1.6 - 0.8
    policy.get_distribution(observations).distribution.mean.sum().backward()
    assert {names[id(p)] for p in actor_parameters(policy) if p.grad is not None and p.grad.abs().sum() > 0} == chosen


@pytest.mark.parametrize("policy_name", ["MlpPolicy", "ContextStdPolicy"])
def test_policy_mean_is_the_distributions_mean(policy_name):
    from sb3_genrl.genrl.regression import policy_mean

    policy = GenRL(policy_name, FastReachEnv(), LinearGenerator(), seed=0,
                   policy_kwargs={"net_arch": {"pi": [16, 16, 16], "vf": [8]}}).policy
    with th.no_grad():  # move the mean off its near-zero start, so that a wrong path would show
        for parameter in policy.action_net.parameters():
            parameter.add_(th.randn(parameter.shape, generator=th.Generator().manual_seed(1)))
    observations = th.rand(32, 2, generator=th.Generator().manual_seed(0)) * 1.6 - 0.8
    expected = policy.get_distribution(observations).distribution.mean
    assert expected.abs().max() > 0.1
    th.testing.assert_close(policy_mean(policy, observations), expected, rtol=0, atol=0)


def test_regress_mean_fits_a_known_linear_map_and_leaves_the_rest():
    from sb3_genrl.genrl.regression import mean_parameters, regress_mean

    policy = GenRL(FastReachEnv(), LinearGenerator(), seed=0).policy
    generator = th.Generator().manual_seed(0)
    contexts = th.rand(512, 2, generator=generator) * 1.6 - 0.8
    weights, bias = th.tensor([[1.5, -0.5], [0.3, 2.0]]), th.tensor([0.2, -0.4])
    targets = contexts @ weights.T + bias  # the answer, computed here
    untouched = {name: value.clone() for name, value in policy.state_dict().items()
                 if name.startswith(("log_std", "value_net", "mlp_extractor.value_net"))}
    optimizer = th.optim.Adam(mean_parameters(policy), lr=1e-3)
    losses = regress_mean(policy, optimizer, contexts, targets, steps=1500, batch_size=64)
    assert len(losses) == 1500 and np.mean(losses[-50:]) < 0.01 * np.mean(losses[:50])
    test = th.rand(200, 2, generator=generator) * 1.6 - 0.8
    with th.no_grad():
        error = policy.get_distribution(test).distribution.mean - (test @ weights.T + bias)
    assert error.abs().max() < 0.1
    for name, value in untouched.items():
        th.testing.assert_close(policy.state_dict()[name], value)


def test_weighted_regress_mean_keeps_to_the_branch_the_policy_is_on():
    """Two latent actions solve every context, f(c) + b and f(c) - b: the plain fit lands on their average f(c), the
    weighted one, started on the first branch with a narrow spread, on that branch."""
    from sb3_genrl.genrl.regression import mean_parameters, policy_mean, regress_mean

    generator = th.Generator().manual_seed(0)
    contexts = th.rand(1024, 2, generator=generator) * 1.6 - 0.8
    weights, shift = th.tensor([[0.5, -0.2], [0.1, 0.4]]), th.tensor([1.0, -0.5])
    answer = contexts @ weights.T  # f(c), computed here
    branch = th.rand(1024, generator=generator) < 0.5
    targets = th.where(branch[:, None], answer + shift, answer - shift)
    test = th.rand(200, 2, generator=generator) * 1.6 - 0.8
    errors = {}
    for weighted in (False, True):
        policy = GenRL(FastReachEnv(), LinearGenerator(), seed=0, policy_kwargs={"log_std_init": np.log(0.2)}).policy
        with th.no_grad():
            policy.action_net.bias.copy_(shift)  # the policy starts near the first branch
        optimizer = th.optim.Adam(mean_parameters(policy), lr=1e-3)
        regress_mean(policy, optimizer, contexts, targets, steps=1500, batch_size=64, weighted=weighted)
        with th.no_grad():
            mean = policy_mean(policy, test)
        expected = test @ weights.T
        errors[weighted] = ((mean - expected).abs().max().item(), (mean - expected - shift).abs().max().item())
    assert errors[False][0] < 0.25 and errors[False][1] > 0.75  # the average of the branches, on neither
    assert errors[True][1] < 0.1 and errors[True][0] > 0.9  # the first branch


def test_hindsight_regression_reaches_new_goals_sooner_on_the_toy():
    distances = {}
    for steps in (0, 256):
        model = GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=0, n_steps=16, hindsight=True,
                      hindsight_history=8, hindsight_regression=steps)
        model.learn(320)
        after = np.array([model.predict(goal, deterministic=True)[0] for goal in GOALS])
        distances[steps] = np.abs(after - np.array([optimal_latent(goal) for goal in GOALS])).max()
    assert distances[256] < 0.5 * distances[0]  # 0.007 against 0.037 (seeds 1 and 2: 0.12 and 0.37 times)
    assert model.logger.name_to_value["train/hindsight_regression_loss"] > 0


def test_hindsight_regression_keeps_its_optimizer_across_save_and_load(tmp_path):
    model = GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=0, n_steps=16, hindsight=True,
                  hindsight_regression=4, hindsight_regression_lr=3e-4, hindsight_regression_batch_size=32)
    model.learn(32)
    state = model.hindsight_optimizer.state_dict()
    assert state["param_groups"][0]["lr"] == 3e-4 and all(v["step"] == 8 for v in state["state"].values())
    model.save(tmp_path / "model")
    loaded = GenRL.load(tmp_path / "model.zip", env=HindsightReachEnv(), generator=LinearGenerator())
    assert (loaded.hindsight_regression, loaded.hindsight_regression_batch_size) == (4, 32)
    for before, after in zip(state["state"].values(), loaded.hindsight_optimizer.state_dict()["state"].values(),
                             strict=True):
        th.testing.assert_close(after["exp_avg"], before["exp_avg"])
    assert GenRL(FastReachEnv(), LinearGenerator()).hindsight_optimizer is None  # none without the regression


def test_load_switches_the_optional_states_on_and_off(tmp_path):
    """policy_averaging and hindsight_regression changed at load: the saved state of a setting now off is dropped,
    one now on starts afresh from the loaded policy, and the regression's learning rate is the one given."""
    def trained(**kwargs):
        model = GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=0, n_steps=16, hindsight=True,
                      **kwargs)
        model.learn(32)
        model.save(tmp_path / "model")
        return model

    def load(**kwargs):
        loaded = GenRL.load(tmp_path / "model.zip", env=HindsightReachEnv(), generator=LinearGenerator(), **kwargs)
        loaded.learn(16)  # and it trains on
        return loaded

    contexts = np.array([[0.3, -0.2], [-0.5, 0.4]], dtype=np.float32)
    with_both = trained(policy_averaging=0.9, hindsight_regression=4)
    plain = GenRL.load(tmp_path / "model.zip", env=HindsightReachEnv(), generator=LinearGenerator(),
                       policy_averaging=None)  # the policy, not its saved average, acts
    np.testing.assert_allclose(plain.predict(contexts, deterministic=True)[0],
                               with_both.policy.predict(contexts, deterministic=True)[0], rtol=0, atol=0)
    switched_off = load(policy_averaging=None, hindsight_regression=0)
    assert switched_off.policy_average is None and switched_off.hindsight_optimizer is None
    faster = load(hindsight_regression_lr=1e-2)
    assert faster.hindsight_optimizer.param_groups[0]["lr"] == 1e-2
    assert all(value["step"] == 8 + 4 for value in faster.hindsight_optimizer.state_dict()["state"].values())

    without = trained()
    switched_on = GenRL.load(tmp_path / "model.zip", env=HindsightReachEnv(), generator=LinearGenerator(),
                             policy_averaging=0.9, hindsight_regression=4)
    # the new average starts as the loaded policy, not as the policy the model was built with
    np.testing.assert_allclose(switched_on.predict(contexts, deterministic=True)[0],
                               without.predict(contexts, deterministic=True)[0], rtol=0, atol=0)
    assert switched_on.hindsight_optimizer.state_dict()["state"] == {}
    switched_on.learn(16)
    assert all(value["step"] == 4 for value in switched_on.hindsight_optimizer.state_dict()["state"].values())


def test_hindsight_regression_is_checked():
    for kwargs, message in (({"hindsight_regression": -1}, "hindsight_regression must be a non-negative integer"),
                            ({"hindsight_regression": 1.5}, "hindsight_regression must be a non-negative integer"),
                            ({"hindsight_regression": True}, "hindsight_regression must be a non-negative integer"),
                            ({"hindsight_regression_lr": 0.0}, "hindsight_regression_lr must be positive"),
                            ({"hindsight_regression_batch_size": 0},
                             "hindsight_regression_batch_size must be a positive integer"),
                            ({"hindsight_regression_batch_size": True},
                             "hindsight_regression_batch_size must be a positive integer"),
                            ({"hindsight_regression": 4, "hindsight_regression_weighted": 1},
                             "hindsight_regression_weighted must be True or False"),
                            ({"hindsight_regression_weighted": True},
                             "hindsight_regression_weighted=True weights the hindsight regression's pulls, which needs "
                             "hindsight_regression > 0")):
        with pytest.raises(ValueError, match=message):
            GenRL(FastReachEnv(), LinearGenerator(), hindsight=True, **kwargs)
    from sb3_genrl.genrl.train import check_genrl_kwargs

    with pytest.raises(ValueError, match="hindsight_regression=8 fits the policy to relabelled pulls, which needs "
                                         "hindsight=True"):
        check_genrl_kwargs({"hindsight_regression": 8})


def test_hindsight_is_checked():
    with pytest.raises(ValueError, match="hindsight must be True or False"):
        GenRL(FastReachEnv(), LinearGenerator(), hindsight="yes")
    with pytest.raises(ValueError, match="hindsight=True needs e_step='trpo'"):
        GenRL(FastReachEnv(), LinearGenerator(), hindsight=True, e_step="kl_penalty")
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, hindsight=True)  # its task has no hindsight(info)
    with pytest.raises(ValueError, match=r"info\['hindsight'\]"):
        model.learn(64)
    assert model.num_timesteps == 1  # refused at the first pull, not after the rollout
    dict_env = LatentActionWrapper(ReachEnv(), LinearGenerator(), context=lambda obs: {"goal": obs[:2]},
                                   context_space=gym.spaces.Dict({"goal": gym.spaces.Box(-1, 1, (2,))}))
    with pytest.raises(ValueError, match="hindsight=True relabels Box contexts"):
        GenRL("MultiInputPolicy", dict_env, hindsight=True)
