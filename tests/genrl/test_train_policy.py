"""train_policy and evaluate_on_goals (sb3_genrl/genrl/train.py): the files a run writes, env processes, the settings
recorded."""

from __future__ import annotations

import csv

import gymnasium as gym
import numpy as np
import pytest
import torch
import torch as th
from conftest import (
    HANG_S,
    FastReachEnv,
    LinearGenerator,
)
from genrl_test_helpers import GOALS, TOY_ID

from sb3_genrl import GenRL
from sb3_genrl.cli import main as cli_main
from sb3_genrl.run import train_policy

TOY_TASK_ID = "GenRLTest/FastReachTask-v0"


@pytest.fixture
def fast_reach_task():
    """FastReachEnv as a registered task (the registry is how train_policy resolves tasks)."""
    from sb3_genrl.envs import TASKS, TaskSpec, register_task

    spec = TaskSpec(
        name="fast-reach",
        env_id=TOY_TASK_ID,
        env_class=FastReachEnv,
        horizon=5,
        goal_low=np.full(2, -0.8),
        goal_high=np.full(2, 0.8),
        in_goal_region=lambda points: np.ones(len(points), dtype=bool),
        cell_size=0.1,
        sample_expert=lambda rng: np.zeros((5, 7)),
        perturbation_scales=np.zeros(7),
        is_valid=lambda info: True,
    )
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
    np.testing.assert_allclose(
        [float(row["train/mean_reward"]) for row in progress], [float(row["mean_reward"]) for row in rows], atol=1e-6
    )
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
    assert exit_info.value.code == 2 and "unknown task 'curling'" in capsys.readouterr().err
    argv = [
        "train-policy",
        "--task",
        "fast-reach",
        "--generator",
        str(tmp_path / "missing.pt"),
        "--episodes",
        "8",
        "--out",
        str(tmp_path),
    ]
    with pytest.raises(SystemExit):
        cli_main(argv)
    assert "missing.pt' does not exist" in capsys.readouterr().err


def test_train_policy_plays_several_envs_together(fast_reach_task, tmp_path):
    """n_envs > 1 on a task with a fast path: BatchedLatentVecEnv under VecMonitor; every episode recorded, the run
    reproducible from its seed."""
    from sb3_genrl.curves import read_monitor

    runs = [
        train_policy(
            "fast-reach", LinearGenerator(), episodes=64, seed=3, out_dir=tmp_path / name, batch_episodes=32, n_envs=2
        )
        for name in ("a", "b")
    ]
    assert runs[0]["episodes"] == 64 and runs[0]["iterations"] == 2 and runs[0]["n_envs"] == 2
    episodes = [read_monitor(run["episodes_csv_path"]) for run in runs]
    assert len(episodes[0]["return"]) == 64 and np.all(episodes[0]["length"] == 1)
    assert np.all(np.isfinite(episodes[0]["cpu_seconds"]))
    np.testing.assert_array_equal(episodes[0]["return"], episodes[1]["return"])
    assert GenRL.load(runs[0]["model_path"], generator=LinearGenerator()).n_steps == 16  # N = 16 steps x 2 envs
    with pytest.raises(ValueError, match=r"batch_episodes \(32\) must be a multiple of n_envs \(3\)"):
        train_policy("fast-reach", LinearGenerator(), episodes=64, out_dir=tmp_path / "c", batch_episodes=32, n_envs=3)
    assert not (tmp_path / "c").exists()


def test_by_default_an_iterations_episodes_play_together_and_the_result_does_not_depend_on_the_cores(
    fast_reach_task, tmp_path
):
    """With no n_envs, a task with a fast path plays each iteration's episodes in one threaded call; the saved policy
    is the same, bit for bit, on 1 simulation thread and on 2."""
    runs = [
        train_policy(
            "fast-reach",
            LinearGenerator(),
            episodes=64,
            seed=5,
            out_dir=tmp_path / str(threads),
            batch_episodes=16,
            n_threads=threads,
        )
        for threads in (1, 2)
    ]
    assert runs[0]["n_envs"] == runs[1]["n_envs"] == 16
    policies = [GenRL.load(run["model_path"], generator=LinearGenerator()).policy.state_dict() for run in runs]
    assert policies[0].keys() == policies[1].keys()
    for name, tensor in policies[0].items():
        assert torch.equal(tensor, policies[1][name]), name


def test_several_envs_without_a_main_guard_fail_with_a_clear_error(tmp_path):
    """A script that starts env processes at import time (a task without a fast path: one process per env): both the
    env process and the script say what to do."""
    import pathlib
    import subprocess
    import sys

    script = tmp_path / "no_guard.py"
    script.write_text(
        f"import sys\nsys.path.insert(0, {str(pathlib.Path(__file__).parents[1])!r})\n"
        "import gymnasium as gym\nfrom conftest import LinearGenerator, ReachEnv\n"
        "from sb3_genrl.run import train_policy\n"
        "gym.register('GenRLTest/StepReach-v0', entry_point=ReachEnv)\n"
        "train_policy('GenRLTest/StepReach-v0', LinearGenerator(), episodes=4, batch_episodes=2, n_envs=2, "
        f"out_dir={str(tmp_path / 'run')!r})\n"
    )
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=HANG_S, cwd=tmp_path)
    assert run.returncode != 0
    assert "RuntimeError: the 2 env processes did not start" in run.stderr
    assert 'under `if __name__ == "__main__":`' in run.stderr
    assert not (tmp_path / "run" / "model.zip").exists()


def test_evaluate_on_goals_plays_the_deterministic_policy(tmp_path):
    from sb3_genrl.generative import make_generator
    from sb3_genrl.run import evaluate_on_goals

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


def test_quickstart_records_the_settings_train_policy_runs_with(fast_reach_task, tmp_path):
    """The quickstart's policy stage records the GenRL settings of the run it makes (n_steps = batch_episodes / its
    envs, batch_size capped at batch_episodes), not GenRL's defaults for them; a task with the fast path plays an
    iteration's episodes together, as train_policy's default does."""
    from sb3_genrl.study.quickstart import _stage_settings, quickstart_envs

    settings = {"batch_size": 64, "target_kl": 0.02}
    n_envs = quickstart_envs("fast-reach", 16)
    run = train_policy("fast-reach", LinearGenerator(), episodes=16, seed=0, out_dir=tmp_path, batch_episodes=16, **settings)
    assert n_envs == run["n_envs"] == 16
    recorded = _stage_settings("fast-reach", 10, 2, 16, 16, n_envs, settings, 10, 10, 0, False)["policy"]["genrl"]
    assert recorded == run["genrl_settings"]
    assert (recorded["n_steps"], recorded["batch_size"], recorded["target_kl"]) == (1, 16, 0.02)


def test_genrl_settings_record_the_policy_arguments_as_json():
    from sb3_genrl.run.train import genrl_settings

    settings = genrl_settings(
        {
            "policy_kwargs": {"net_arch": {"pi": [64, 64, 64], "vf": (64, 64)}, "activation_fn": th.nn.Tanh},
            "learning_rate": lambda progress: 1e-3 * progress,
        }
    )
    assert settings["policy_kwargs"] == {
        "net_arch": {"pi": [64, 64, 64], "vf": [64, 64]},
        "activation_fn": "torch.nn.modules.activation.Tanh",
    }
    assert "learning_rate" not in settings  # a schedule is no JSON value
    assert (
        genrl_settings({"policy_kwargs": {"net_arch": [8], "optimizer_kwargs": {"eps": object()}}}).get(
            "policy_kwargs", "left out"
        )
        == "left out"
    )


def test_latent_clip_in_the_settings_is_the_action_box_of_the_run(fast_reach_task, tmp_path):
    """latent_clip among train_policy's settings (``genrl train-policy --genrl-kwargs``) is the action box of every
    env of the run, one or several (it used to be recorded in the summary and the model while the box stayed +-3)."""
    from sb3_genrl.curves import read_monitor

    for n_envs in (1, 2):
        result = train_policy(
            "fast-reach",
            LinearGenerator(),
            episodes=32,
            seed=0,
            out_dir=tmp_path / str(n_envs),
            batch_episodes=16,
            n_envs=n_envs,
            latent_clip=0.5,
        )
        model = GenRL.load(result["model_path"], generator=LinearGenerator())
        assert result["genrl_settings"]["latent_clip"] == model.latent_clip == 0.5
        assert model.action_space.high.tolist() == [0.5, 0.5]
        assert len(read_monitor(result["episodes_csv_path"])["return"]) == 32
