"""One seed of the Fetch benchmark (``benchmarks/fetch.py``): GenRL trained with the held-out success curve, checkpointed
at every evaluation and resumed from its checkpoint.

The run's folder (``WORK/seed_S``) holds SB3's Monitor file and logger, the checkpoint (as ``genrl train-policy``
writes it, :mod:`sb3_genrl.run.checkpoint`) and, at the end, the model. The curve's points past the checkpoint a
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
import torch as th
from sb3_genrl.envs import get_task
from sb3_genrl.envs.demonstrations.fetch import evaluate_success
from sb3_genrl.envs.fetch import FETCH_HORIZON
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from sb3_genrl.curves import monitor_episodes, training_logger
from sb3_genrl.data.fingerprints import dataset_fingerprint
from sb3_genrl.generative import load
from sb3_genrl.genrl import GenRL
from sb3_genrl.genrl.demonstrations import DemonstrationCallback, build_callbacks, fit_mean_to_demonstrations
from sb3_genrl.genrl.generator_files import generator_digest
from sb3_genrl.genrl.policies import scale_contexts
from sb3_genrl.hyperparams import EVAL_GOAL_SEED
from sb3_genrl.run.checkpoint import GenRLCheckpoint, RandomStateRecorder, resume_genrl, resume_state
from sb3_genrl.run.folder import RunFolderError, keep_episodes
from sb3_genrl.run.train import effective_genrl_settings, make_genrl
from sb3_genrl.study.quickstart import task_settings
from sb3_genrl.wrappers import LatentActionWrapper

CURVE = ("curve_episodes", "curve_env_steps", "curve_success")


class SuccessCurve(BaseCallback):
    """Every ``every`` episodes, at the start of an iteration (after the update): the deterministic policy's success
    rate on ``states`` held-out initial states, appended to ``row`` and written; with ``demonstrations`` (the run's
    :class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback`, before this one), also at the start of a fresh run,
    after the policy's mean was fitted to them (the fit's losses as ``row["demo_init"]``)."""

    def __init__(
        self,
        task: str,
        every: int,
        states: int,
        row: dict,
        write: Callable[[], None],
        demonstrations: DemonstrationCallback | None = None,
    ) -> None:
        super().__init__()
        self.task, self.every, self.states, self.row, self.write = task, every, states, row, write
        self.demonstrations = demonstrations

    def _on_step(self) -> bool:
        return True

    def _on_training_start(self) -> None:
        if self.demonstrations is not None and self.demonstrations.fit:  # fitted at this fresh start
            self.row["demo_init"] = dict(self.demonstrations.fit)
            self.evaluate()  # the policy before its first episode

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


def recorded_genrl_settings(task: str) -> dict[str, Any]:
    """Every GenRL setting the task's entry runs with, its episodes per iteration as ``n_steps`` (the runs are made
    with ``n_steps=batch_episodes``): what the benchmark's JSON and each run's checkpoint record."""
    _, batch_episodes, genrl_kwargs = task_settings(task)
    return effective_genrl_settings(genrl_kwargs, batch_episodes, n_envs=1)


def fitted_policy(
    task: str, generator_path: str, dataset: str, fit_steps: int | None = None, net_arch: list[int] | None = None
) -> tuple[GenRL, DemonstrationCallback, tuple[th.Tensor, th.Tensor]]:
    """GenRL with the task's entry (policy seed 0) and its mean fitted to the demonstrations ``dataset`` as the entry's
    ``DemonstrationCallback`` fits them, its contexts scaled first where the entry's callback scales them
    (``fit_steps``: another number of Adam steps; 0: no fit), before any episode.
    ``net_arch``: other hidden layers of the policy's mean. Returns the model, the entry's callback and the
    demonstrations as pulls (contexts, latent actions)."""
    _, batch_episodes, genrl_kwargs = task_settings(task)
    callback = genrl_kwargs.pop("callback", None)
    if net_arch is not None:
        policy_kwargs = dict(genrl_kwargs.get("policy_kwargs") or {})
        policy_kwargs["net_arch"] = {**dict(policy_kwargs.get("net_arch") or {}), "pi": list(net_arch)}
        genrl_kwargs["policy_kwargs"] = policy_kwargs
    fit = next(
        (
            item
            for item in build_callbacks(callback, demonstrations=dataset, task=task)
            if isinstance(item, DemonstrationCallback)
        ),
        None,
    )
    if fit is None or not fit.fit_steps:
        raise ValueError(f"the entry of {task} in hyperparams/genrl.yml fits no demonstrations")
    generator = load(generator_path, device="cpu")
    model = make_genrl(
        LatentActionWrapper(gym.make(get_task(task).env_id), generator),
        generator,
        seed=0,
        device="cpu",
        n_steps=batch_episodes,
        **genrl_kwargs,
    )
    pulls = fit.pulls(generator, model.observation_space, model.latent_clip)
    if fit.scale_contexts:  # as the callback scales them on a fresh run, before its fit
        scale_contexts(model.policy, pulls[0])
    steps = fit.fit_steps if fit_steps is None else fit_steps
    if steps:
        fit_mean_to_demonstrations(
            model.policy, *pulls, steps=steps, learning_rate=fit.learning_rate, batch_size=fit.batch_size
        )
    return model, fit, pulls


def fitted_mean_success(task: str, generator_path: str, dataset: str, states: int, seed: int) -> float:
    """The success rate on ``states`` initial states (reset seeds from ``seed``) of GenRL's policy mean (policy seed 0,
    the task's entry) fitted to the demonstrations ``dataset`` as the entry's ``DemonstrationCallback`` fits it,
    before any episode: what a generator gives GenRL to start from."""
    model, _, _ = fitted_policy(task, generator_path, dataset)
    return float(evaluate_success(model, task, episodes=states, seed=seed)["success_rate"])


def train_seed(
    task: str, generator_path: str, seed: int, args: argparse.Namespace, row: dict, write: Callable[[], None]
) -> None:
    """Train (or resume) GenRL with one seed to ``args.episodes``, evaluating on the way and at the end (into ``row``)."""
    _, batch_episodes, genrl_kwargs = task_settings(task)
    callback = None if args.no_demonstrations else genrl_kwargs.get("callback")
    genrl_kwargs.pop("callback", None)
    demonstrations = build_callbacks(
        callback,
        demonstrations=args.dataset if callback else None,
        what=f"the entry of {task} in hyperparams/genrl.yml",
        task=task,
    )
    folder = pathlib.Path(args.work) / f"seed_{seed}"
    generator = load(generator_path, device="cpu")
    identity = {
        "algorithm": "genrl",
        "task": task,
        "episodes": int(args.episodes),
        "seed": seed,
        "batch_episodes": batch_episodes,
        "generator_sha256": generator_digest(generator),
        "genrl_settings": recorded_genrl_settings(task),
        "demonstration_callback": callback,
        "demonstrations": [dataset_fingerprint(item.dataset) for item in demonstrations],
    }
    try:
        state = resume_state(folder, identity)
    except RunFolderError:  # an earlier try's checkpoint, of other settings: started afresh below
        state = None
    if state is None:  # from the start: what an earlier unfinished try left is dropped
        shutil.rmtree(folder, ignore_errors=True)
        row.update({key: [] for key in CURVE}, seconds=0.0, evaluation_seconds=0.0)
    else:
        kept = sum(episodes <= state["episodes"] for episodes in row["curve_episodes"])
        row.update({key: row[key][:kept] for key in CURVE})
        row["resumed_at_episodes"] = [*row.get("resumed_at_episodes", []), int(state["episodes"])]
        keep_episodes(folder, int(state["episodes"]))  # the Monitor's rows after the checkpoint are played again
    os.makedirs(folder, exist_ok=True)
    env = monitor_episodes(
        RandomStateRecorder(LatentActionWrapper(gym.make(get_task(task).env_id), generator)), folder, append=state is not None
    )
    logger = training_logger(folder)
    curve = SuccessCurve(task, args.eval_every, args.eval_states, row, write, *demonstrations[:1])
    if state is None:
        model = make_genrl(env, generator, seed=seed, device="cpu", n_steps=batch_episodes, **genrl_kwargs)
        model.set_logger(logger)
    else:
        model = resume_genrl(state, env, generator, "cpu", logger)
    checkpoint = GenRLCheckpoint(folder, args.eval_every, identity, state)
    callbacks = [*demonstrations, curve, checkpoint]  # the fit before the curve's first point, the kept pulls saved
    begin = time.perf_counter()
    model.learn(int(args.episodes) - model.num_timesteps, callback=CallbackList(callbacks), reset_num_timesteps=state is None)
    row["seconds"] = row.get("seconds", 0.0) + time.perf_counter() - begin
    if not row["curve_episodes"] or row["curve_episodes"][-1] != model.num_timesteps:
        curve.evaluate()
    model.logger.close()
    model.save(folder / "genrl_policy.zip")
    env.close()
    row.update(
        final_success=row["curve_success"][-1],
        episodes=int(model.num_timesteps),
        env_steps=int(model.num_timesteps) * FETCH_HORIZON,
        finished=True,
    )
    write()
    shutil.rmtree(folder / "checkpoint", ignore_errors=True)
