"""One seed of the Fetch benchmark (``benchmarks/fetch.py``): GenRL trained with the held-out success curve, checkpointed
at every evaluation and resumed from its checkpoint.

The run's folder (``WORK/seed_S``) holds SB3's Monitor file and logger, the checkpoint (as ``genrl train-policy``
writes it, :mod:`sb3_genrl.genrl.checkpoint`) and, at the end, the model. The curve's points past the checkpoint a
resumed run starts from are dropped from the row and measured again.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import shutil
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
from sb3_genrl.envs import get_task
from sb3_genrl.envs.fetch import FETCH_HORIZON
from sb3_genrl.envs.fetch_demonstrations import evaluate_success
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from sb3_genrl.curves import monitor_episodes, training_logger
from sb3_genrl.generative import load
from sb3_genrl.genrl.checkpoint import GenRLCheckpoint, RandomStateRecorder, resume_genrl, resume_state
from sb3_genrl.genrl.generator_files import generator_digest
from sb3_genrl.genrl.train import genrl_settings, make_genrl
from sb3_genrl.hyperparams import EVAL_GOAL_SEED
from sb3_genrl.study.quickstart import task_settings
from sb3_genrl.wrappers import LatentActionWrapper

CURVE = ("curve_episodes", "curve_env_steps", "curve_success")


class SuccessCurve(BaseCallback):
    """Every ``every`` episodes, at the start of an iteration (after the update): the deterministic policy's success
    rate on ``states`` held-out initial states, appended to ``row`` and written."""

    def __init__(self, task: str, every: int, states: int, row: dict, write: Callable[[], None]) -> None:
        super().__init__()
        self.task, self.every, self.states, self.row, self.write = task, every, states, row, write

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:
        episodes = int(self.num_timesteps)
        if episodes and episodes % self.every == 0 and episodes not in self.row["curve_episodes"]:
            self.evaluate()

    def evaluate(self, model: Any = None) -> None:
        """Evaluate ``model`` (default: the trained one, at its episodes; a model before training: at 0)."""
        start = time.perf_counter()
        model = self.model if model is None else model
        result = evaluate_success(model, self.task, episodes=self.states, seed=EVAL_GOAL_SEED)
        episodes = int(model.num_timesteps)
        self.row["curve_episodes"].append(episodes)
        self.row["curve_env_steps"].append(episodes * FETCH_HORIZON)
        self.row["curve_success"].append(result["success_rate"])
        self.row["evaluation_seconds"] = self.row.get("evaluation_seconds", 0.0) + time.perf_counter() - start
        self.row["episodes_done"] = episodes
        self.write()
        print(f"  seed {self.row['seed']}, {episodes} episodes: success {result['success_rate']:.3f}", flush=True)


def fit_mean_to_demonstrations(model: Any, generator: Any, dataset: str, steps: int) -> dict[str, float]:
    """Start GenRL's policy from the demonstrations: fit its mean, by ``steps`` Adam steps (learning rate 1e-3,
    minibatches of 256) of the regression that GenRL's hindsight component uses, to each demonstration's posterior
    mean at its context (its reset observation with the goal it reached, as the dataset stores it at step 0: the
    context its hindsight relabelling would give), the latent codes clipped to GenRL's ``latent_clip``."""
    import numpy as np
    import torch as th

    from sb3_genrl.data import load_arrays
    from sb3_genrl.genrl.regression import mean_parameters, regress_mean

    arrays = load_arrays(dataset)
    contexts = th.as_tensor(arrays["observations"][:, 0], dtype=th.float32)
    latents = np.clip(generator.encode(arrays["actions"])[0], -model.latent_clip, model.latent_clip)
    optimizer = th.optim.Adam(mean_parameters(model.policy), lr=1e-3)
    losses = regress_mean(model.policy, optimizer, contexts, th.as_tensor(latents), steps=steps, batch_size=256)
    return {"demonstrations": len(latents), "steps": steps, "first_loss": float(losses[0]),
            "last_loss": float(np.mean(losses[-100:]))}


class DemonstrationMemory(BaseCallback):
    """Keep the demonstrations in GenRL's hindsight memory for the whole run, as one batch of relabelled pulls
    (context, posterior mean, reward 0: each reached the goal of its context) that the E-step and the regression of
    the mean use as they use the kept pulls: at the start of every iteration the batch is put back as the newest, so
    it never ages out of the last ``history`` batches (as the demonstrations stay in SAC+HER's buffer)."""

    def __init__(self, generator: Any, dataset: str, latent_clip: float) -> None:
        super().__init__()
        import numpy as np
        import torch as th

        from sb3_genrl.data import load_arrays

        arrays = load_arrays(dataset)
        latents = np.clip(generator.encode(arrays["actions"])[0], -latent_clip, latent_clip)
        self.batch = (th.as_tensor(arrays["observations"][:, 0], dtype=th.float32), th.as_tensor(latents),
                      th.zeros(len(latents)))

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:
        import torch as th

        memory, contexts = self.model.hindsight.memory, self.batch[0]
        kept = [entry for entry in memory  # (a resumed run's memory holds the checkpoint's copy of the batch)
                if not (entry[0].shape == contexts.shape and th.equal(entry[0], contexts))]
        memory.clear()
        memory.extend(kept[-(memory.maxlen - 1):] if memory.maxlen > 1 else [])
        memory.append(self.batch)


def train_seed(task: str, generator_path: str, seed: int, args: argparse.Namespace, row: dict,
               write: Callable[[], None]) -> None:
    """Train (or resume) GenRL with one seed to ``args.episodes``, evaluating on the way and at the end (into ``row``)."""
    _, batch_episodes, genrl_kwargs = task_settings(task)
    folder = pathlib.Path(args.work) / f"seed_{seed}"
    generator = load(generator_path, device="cpu")
    identity = {"algorithm": "genrl", "task": task, "episodes": int(args.episodes), "seed": seed,
                "batch_episodes": batch_episodes, "generator_sha256": generator_digest(generator),
                "genrl_settings": genrl_settings(genrl_kwargs), "demo_init_steps": args.demo_init_steps,
                "demo_memory": args.demo_memory}
    state = resume_state(folder / "checkpoint", identity)
    if state is None:  # from the start: what an earlier unfinished try left is dropped
        shutil.rmtree(folder, ignore_errors=True)
        row.update({key: [] for key in CURVE}, seconds=0.0, evaluation_seconds=0.0)
    else:
        kept = sum(episodes <= state["episodes"] for episodes in row["curve_episodes"])
        row.update({key: row[key][:kept] for key in CURVE})
        row["resumed_at_episodes"] = [*row.get("resumed_at_episodes", []), int(state["episodes"])]
    os.makedirs(folder, exist_ok=True)
    env = monitor_episodes(RandomStateRecorder(LatentActionWrapper(gym.make(get_task(task).env_id), generator)),
                           folder, append=state is not None)
    logger = training_logger(folder)
    curve = SuccessCurve(task, args.eval_every, args.eval_states, row, write)
    if state is None:
        model = make_genrl(env, generator, seed=seed, device="cpu", n_steps=batch_episodes, **genrl_kwargs)
        model.set_logger(logger)
        if args.demo_init_steps:
            row["demo_init"] = fit_mean_to_demonstrations(model, generator, args.dataset, args.demo_init_steps)
            curve.evaluate(model)  # the policy before its first episode
    else:
        model = resume_genrl(state, env, generator, "cpu", logger)
    checkpoint = GenRLCheckpoint(folder / "checkpoint", args.eval_every, identity, state)
    callbacks = [curve, checkpoint]
    if args.demo_memory:  # before the checkpoint's save in the same call: saved with the batch in place
        callbacks.insert(1, DemonstrationMemory(generator, args.dataset, model.latent_clip))
    begin = time.perf_counter()
    model.learn(int(args.episodes) - model.num_timesteps, callback=CallbackList(callbacks),
                reset_num_timesteps=state is None)
    row["seconds"] = row.get("seconds", 0.0) + time.perf_counter() - begin
    if not row["curve_episodes"] or row["curve_episodes"][-1] != model.num_timesteps:
        curve.evaluate()
    model.logger.close()
    model.save(folder / "genrl_policy.zip")
    env.close()
    row.update(final_success=row["curve_success"][-1], episodes=int(model.num_timesteps),
               env_steps=int(model.num_timesteps) * FETCH_HORIZON, finished=True)
    write()
    shutil.rmtree(folder / "checkpoint", ignore_errors=True)
