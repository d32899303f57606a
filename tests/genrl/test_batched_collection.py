"""Tests of sb3_genrl.vec_env.BatchedLatentVecEnv: one fast-path call per step, the step path's results, SB3's tools."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from conftest import HANG_S, FastReachEnv, LinearGenerator, ReachEnv
from genrl_test_helpers import HindsightReachEnv
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.curves import read_monitor
from sb3_genrl.vec_env import BatchedLatentVecEnv, default_threads

WRAPPER_KEYS = ("fast_path", "steps_played", "hold_steps", "ended")  # how a step was played, not what it gave


class CountingReachEnv(HindsightReachEnv):
    """HindsightReachEnv that counts its fast-path calls and the trajectories each played."""

    calls: list[int] = []

    def play_trajectories(self, trajectories, goals, *, n_threads=1):
        CountingReachEnv.calls.append(len(trajectories))
        return super().play_trajectories(trajectories, goals, n_threads=n_threads)


def _same(first, second) -> bool:
    """Equal values, bit for bit, in nested tuples and arrays (an info's ``hindsight`` is ``(context, reward)``)."""
    if isinstance(first, tuple | list):
        return len(first) == len(second) and all(_same(a, b) for a, b in zip(first, second, strict=True))
    return np.array_equal(first, second)


def hockey_envs(generator, n, **kwargs):
    return [lambda: LatentActionWrapper(gym.make("GenRL/Hockey-v0"), generator, **kwargs) for _ in range(n)]


def test_a_batched_step_gives_the_step_paths_rewards_and_infos():
    """Hockey, three envs, two steps of the same latent actions from the same seed: the batched env, one fast-path
    call per episode (DummyVecEnv) and the step-by-step path give the same contexts, rewards and infos."""
    from sb3_genrl.generative import make_generator

    th.manual_seed(0)
    generator = make_generator("VAE1", horizon=69, action_dim=7, device="cpu")
    envs = {
        "batched": BatchedLatentVecEnv(hockey_envs(generator, 3), n_threads=2),
        "one by one": DummyVecEnv(hockey_envs(generator, 3)),
        "step by step": DummyVecEnv(hockey_envs(generator, 3, use_fast_path=False)),
    }
    actions = np.random.default_rng(1).normal(size=(2, 3, generator.latent_dim)).astype(np.float32)
    results = {}
    for name, venv in envs.items():
        venv.seed(5)
        observations = [venv.reset()]
        steps = []
        for step_actions in actions:
            observation, reward, done, infos = venv.step(step_actions)
            observations.append(observation)
            steps.append((reward, done, infos))
        results[name] = (observations, steps)
        venv.close()
    batched_observations, batched_steps = results["batched"]
    for name in ("one by one", "step by step"):
        observations, steps = results[name]
        np.testing.assert_array_equal(np.stack(observations), np.stack(batched_observations))
        for (reward, done, infos), (batched_reward, batched_done, batched_infos) in zip(steps, batched_steps, strict=True):
            np.testing.assert_array_equal(reward, batched_reward)
            np.testing.assert_array_equal(done, batched_done)
            for info, batched_info in zip(infos, batched_infos, strict=True):
                keys = set(info) - set(WRAPPER_KEYS) if name == "step by step" else set(info)
                assert keys <= set(batched_info)
                assert all(_same(info[key], batched_info[key]) for key in keys), (info, batched_info)
    assert all(info["fast_path"] for _, _, infos in batched_steps for info in infos)


def _toy_envs(n):
    return [lambda: LatentActionWrapper(CountingReachEnv(), LinearGenerator()) for _ in range(n)]


def test_genrl_on_the_batched_env_learns_as_on_dummy_vec_env_with_monitor_and_eval_callback(tmp_path):
    """GenRL (hindsight, value history) on a monitored batched env: the same parameters, bit for bit, as on SB3's
    DummyVecEnv; one fast-path call per step of all 4 envs; every episode in the Monitor file with the rollouts'
    rewards; EvalCallback evaluates on a batched env as on any VecEnv."""
    settings = dict(
        n_steps=4,
        batch_size=8,
        seed=2,
        value_history=2,
        n_critic_updates=2,
        hindsight_kwargs={"history": 2, "regression_steps": 4},
    )
    parameters = {}
    for name, venv_class in (("dummy", DummyVecEnv), ("batched", BatchedLatentVecEnv)):
        venv = VecMonitor(venv_class(_toy_envs(4)), str(tmp_path / name), info_keywords=("reward",))
        evaluation = EvalCallback(
            VecMonitor(venv_class(_toy_envs(2))),
            n_eval_episodes=4,
            eval_freq=4,
            log_path=str(tmp_path / f"{name}_eval"),
            verbose=0,
        )
        CountingReachEnv.calls = []
        model = GenRL(venv, **settings).learn(32, callback=evaluation)
        parameters[name] = th.cat([p.detach().flatten() for p in model.policy.parameters()])
        venv.close()
        episodes = read_monitor(tmp_path / f"{name}.monitor.csv")
        assert len(episodes["return"]) == 32 and np.all(episodes["length"] == 1)
        np.testing.assert_allclose(episodes["return"], episodes["reward"], atol=1e-6)
        assert len(evaluation.evaluations_results) == 2 and all(len(r) == 4 for r in evaluation.evaluations_results)
        if name == "batched":  # training's steps of 4 envs, the evaluations' of 2: never one call per episode
            assert sorted(set(CountingReachEnv.calls)) == [2, 4] and CountingReachEnv.calls.count(4) == 8
    assert th.equal(parameters["dummy"], parameters["batched"])


def test_a_batched_env_refuses_envs_without_the_fast_path_and_bad_thread_counts():
    with pytest.raises(ValueError, match="fast path"):
        BatchedLatentVecEnv([lambda: LatentActionWrapper(ReachEnv(), LinearGenerator())])
    with pytest.raises(ValueError, match="same task"):
        BatchedLatentVecEnv(
            [
                lambda: LatentActionWrapper(FastReachEnv(), LinearGenerator()),
                lambda: LatentActionWrapper(CountingReachEnv(), LinearGenerator()),
            ]
        )
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="n_threads must be a positive integer"):
            BatchedLatentVecEnv(_toy_envs(1), n_threads=bad)
    assert BatchedLatentVecEnv(_toy_envs(1)).n_threads == default_threads() >= 1


class _ShiftedTrajectories(LatentActionWrapper):
    """A wrapper whose latent actions become the generator's trajectories shifted by 0.1."""

    def trajectory(self, alpha):
        return super().trajectory(alpha) + 0.1


def test_the_batched_env_takes_each_trajectory_from_the_wrappers_public_trajectory():
    """The batched step asks each wrapper for its trajectory through the public ``trajectory`` (it used a private
    decode), so a wrapper that says how its latent actions become trajectories is played as its own step plays it."""
    actions = np.random.default_rng(0).normal(size=(2, 2)).astype(np.float32)
    for venv_class in (DummyVecEnv, BatchedLatentVecEnv):
        venv = venv_class([lambda: _ShiftedTrajectories(CountingReachEnv(), LinearGenerator()) for _ in range(2)])
        venv.seed(1)
        goals = venv.reset()
        rewards = venv.step(actions)[1]
        reached = np.clip(LinearGenerator().decode(np.clip(actions, -3, 3)) + 0.1, -1, 1).sum(axis=1)  # the toy's play
        np.testing.assert_allclose(rewards, -np.sum((reached - goals) ** 2, axis=1), rtol=1e-6)


def test_make_latent_vec_env_plays_a_fast_path_together_and_the_result_does_not_depend_on_the_cores():
    """The README's recipe: a task with a fast path gets one BatchedLatentVecEnv under VecMonitor (one env: a
    DummyVecEnv), and GenRL trained on it is the same, bit for bit, on 1 simulation thread and on 2, whatever torch's
    thread count (torch picks the machine's cores; GenRL learns on one and gives the caller's back)."""
    from sb3_genrl import make_latent_vec_env
    from sb3_genrl.generative import make_generator

    th.manual_seed(0)
    generator = make_generator("VAE1", horizon=69, action_dim=7, device="cpu")
    single = make_latent_vec_env("GenRL/Hockey-v0", generator, 1)
    assert isinstance(single, VecMonitor) and type(single.venv) is DummyVecEnv
    policies = []
    for threads in (1, 2):
        env = make_latent_vec_env("GenRL/Hockey-v0", generator, 8, n_threads=threads)
        assert isinstance(env.venv, BatchedLatentVecEnv) and env.num_envs == 8 and env.venv.n_threads == threads
        th.set_num_threads(threads)
        model = GenRL(env, n_steps=2, seed=4, hindsight_kwargs={"history": 2, "regression_steps": 8})
        model.learn(32)
        assert th.get_num_threads() == threads
        policies.append(model.policy.state_dict())
    for name, tensor in policies[0].items():
        assert th.equal(tensor, policies[1][name]), name
    with pytest.raises(ValueError, match="n_envs must be a positive integer, got 0"):
        make_latent_vec_env("GenRL/Hockey-v0", generator, 0)


def test_make_latent_vec_env_plays_a_task_without_a_fast_path_in_env_processes():
    from stable_baselines3.common.vec_env import SubprocVecEnv

    from sb3_genrl import make_latent_vec_env

    gym.register("GenRLTest/VecStepReach-v0", entry_point=ReachEnv)
    env = make_latent_vec_env("GenRLTest/VecStepReach-v0", LinearGenerator(), 2)
    try:
        assert isinstance(env.venv, SubprocVecEnv) and env.num_envs == 2
        env.seed(3)
        env.reset()
        _, rewards, dones, _ = env.step(np.zeros((2, LinearGenerator().latent_dim), dtype=np.float32))
        assert dones.all() and rewards.shape == (2,)
    finally:
        env.close()


def test_make_latent_vec_env_in_a_script_without_a_main_guard_is_told_to_add_one(tmp_path):
    script = tmp_path / "unguarded.py"
    script.write_text(
        f"import sys\nsys.path.insert(0, {str(Path(__file__).parents[1])!r})\n"
        "import gymnasium as gym\nfrom conftest import LinearGenerator, ReachEnv\nfrom sb3_genrl import make_latent_vec_env\n"
        "gym.register('GenRLTest/Unguarded-v0', entry_point=ReachEnv)\n"
        "make_latent_vec_env('GenRLTest/Unguarded-v0', LinearGenerator(), 2)\n"
    )
    done = subprocess.run([sys.executable, script], capture_output=True, text=True, timeout=HANG_S)
    assert done.returncode != 0
    assert "the 2 env processes did not start" in done.stderr and 'under `if __name__ == "__main__":`' in done.stderr
