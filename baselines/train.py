"""Train a baseline on a task with the same outputs as ``genrl train-policy`` (paper sections 6.1.5, 6.2, 6.3).

Feedback baselines (per-step actions, observation = goal + joint positions + joint velocities):

- ``ppo``: SB3 PPO whose actor is first fitted to the demonstrations' state-action pairs by behaviour cloning
  (:func:`~sb3_genrl.baselines.bc.behaviour_cloning`, negative log-likelihood), then trained on the sparse
  terminal reward. Hyperparameters are SB3's PPO defaults (which follow the PPO paper's MuJoCo settings) except
  ``n_steps`` = 16 episodes per update, so that small episode budgets still give many updates.
- ``sac``: SB3 SAC with SB3's defaults (SAC paper values: lr 3e-4, batch 256, tau 0.005, automatic entropy), its
  replay buffer first filled with the same demonstration transitions and rewards
  (:func:`~sb3_genrl.baselines.prefill.prefill_replay_buffer`) and no random warm-up.

Latent-space baselines (the same generator as GenRL, on :class:`~sb3_genrl.LatentActionWrapper`, one-step
episodes): ``latent-ppo``, ``latent-sac``, ``latent-trpo`` - stock SB3 / sb3-contrib algorithms with their
defaults except 64 episodes per update (GenRL's batch), so they show what the EM update adds.

Every run writes ``episodes.csv`` (one row per episode: return, table contacts, distance, written as training
goes), ``learning_curve.csv`` / ``learning_curve.png`` (mean over windows of 64 episodes), TensorBoard logs in
``tensorboard/``, the model, and ``summary.json``.
"""

from __future__ import annotations

import json
import os
import pathlib
from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.baselines.bc import behaviour_cloning
from sb3_genrl.baselines.prefill import prefill_replay_buffer
from sb3_genrl.envs import get_task
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from sb3_genrl.callbacks import EpisodeRecorder
from sb3_genrl.curves import write_learning_curve

BASELINES = ("ppo", "sac", "latent-ppo", "latent-sac", "latent-trpo")
LATENT_BATCH = 64  # episodes per update of the latent-space baselines (GenRL's default N)


def train_baseline(
    algorithm: str,
    task: str,
    *,
    episodes: int,
    out_dir: str | os.PathLike,
    seed: int = 0,
    demos: str | os.PathLike | dict[str, np.ndarray] | None = None,
    demo_episodes: int | None = None,
    generator: Any = None,
    bc_epochs: int = 5,
    eval_episodes: int = 20,
    device: str = "auto",
    progress_bar: bool = False,
    verbose: int = 0,
    window: int = 64,
) -> dict[str, Any]:
    """Train one baseline for ``episodes`` episodes and write its outputs to ``out_dir``.

    :param algorithm: one of ``ppo``, ``sac``, ``latent-ppo``, ``latent-sac``, ``latent-trpo``
    :param task: a task name from :data:`sb3_genrl.envs.TASKS` (or its Gymnasium id)
    :param episodes: budget of episodes (the horizon's worth of steps each for ``ppo``/``sac``)
    :param out_dir: output folder (created)
    :param seed: random seed
    :param demos: demonstrations for ``ppo``/``sac``: a dataset path or a transitions dict (see
        :func:`sb3_genrl.data.load_transitions`)
    :param demo_episodes: use only the first ``demo_episodes`` demonstration episodes (default: all)
    :param generator: a generator (or its file) for the latent-space baselines
    :param bc_epochs: behaviour cloning epochs (``ppo``)
    :param eval_episodes: episodes to evaluate the behaviour-cloned policy before RL (``ppo``)
    :param window: episodes per point of the learning curve
    """
    if algorithm not in BASELINES:
        raise ValueError(f"unknown baseline {algorithm!r}; expected one of {BASELINES}")
    if int(episodes) != episodes or episodes < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    spec = get_task(task)
    task, env_id = spec.name, spec.env_id
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary: dict[str, Any] = {"algorithm": algorithm, "task": task, "episodes": int(episodes), "seed": seed}
    common = {"seed": seed, "device": device, "verbose": verbose, "tensorboard_log": str(out / "tensorboard")}
    if algorithm.startswith("latent-"):
        model, steps = _latent_model(algorithm, env_id, generator, episodes, common)
    else:
        if demos is None:
            raise ValueError(f"{algorithm} needs demonstrations (demos=...)")
        transitions = _demonstrations(demos, demo_episodes)
        summary["demo_transitions"] = len(transitions["observations"])
        env = gym.make(env_id)
        horizon = env.unwrapped.horizon
        steps = int(episodes) * horizon
        if algorithm == "ppo":
            model = PPO("MlpPolicy", env, n_steps=16 * horizon, batch_size=4 * horizon, **common)
            summary["bc_loss"] = behaviour_cloning(model.policy, transitions["observations"], transitions["actions"],
                                                   epochs=bc_epochs, seed=seed)
            eval_env = Monitor(gym.make(env_id))
            eval_env.reset(seed=seed + 10_000)
            summary["bc_mean_reward"], summary["bc_std_reward"] = (float(v) for v in evaluate_policy(
                model, eval_env, n_eval_episodes=eval_episodes, deterministic=True))
        else:
            model = SAC("MlpPolicy", env, buffer_size=max(len(transitions["observations"]) + steps, 1), learning_starts=0,
                        **common)
            prefill_replay_buffer(model, transitions)
    recorder = EpisodeRecorder(out / "episodes.csv")
    model.learn(total_timesteps=steps, callback=recorder, progress_bar=progress_bar, tb_log_name=algorithm)
    model.save(out / f"{algorithm}_policy.zip")
    curve = write_learning_curve(out / "episodes.csv", out, window=window, title=f"{algorithm} on {task}")
    returns = np.asarray(recorder.returns)
    summary |= {"episodes_played": len(returns), "final_mean_reward": float(curve["mean_reward"][-1]),
                "best_mean_reward": float(np.max(curve["mean_reward"])), "max_reward": float(returns.max())}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def _demonstrations(demos: Any, demo_episodes: int | None) -> dict[str, np.ndarray]:
    if isinstance(demos, dict):
        transitions = demos
    else:
        from sb3_genrl.data import load_transitions

        transitions = load_transitions(demos)
    if demo_episodes is None:
        return transitions
    ends = np.flatnonzero(np.asarray(transitions["dones"]))
    if demo_episodes < 1 or demo_episodes > len(ends):
        raise ValueError(f"demo_episodes must be between 1 and {len(ends)}, got {demo_episodes}")
    n = ends[demo_episodes - 1] + 1
    return {key: np.asarray(value)[:n] for key, value in transitions.items()}


def _latent_model(algorithm: str, env_id: str, generator: Any, episodes: int, common: dict) -> tuple[Any, int]:
    from sb3_genrl import LatentActionWrapper

    if generator is None:
        raise ValueError(f"{algorithm} needs a generator (generator=...)")
    if isinstance(generator, str | os.PathLike):
        from sb3_genrl.generative import load

        generator = load(generator)
    env = LatentActionWrapper(gym.make(env_id), generator)
    if algorithm == "latent-ppo":
        model = PPO("MlpPolicy", env, n_steps=LATENT_BATCH, batch_size=LATENT_BATCH, **common)
    elif algorithm == "latent-sac":
        model = SAC("MlpPolicy", env, learning_starts=LATENT_BATCH, **common)
    else:
        from sb3_contrib import TRPO

        model = TRPO("MlpPolicy", env, n_steps=LATENT_BATCH, batch_size=LATENT_BATCH, **common)
    return model, int(episodes)
