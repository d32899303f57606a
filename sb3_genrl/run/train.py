"""Train a GenRL policy on a registered task, with logs, a learning curve (CSV + PNG) and the saved model.

Task-level workflow code: tasks are resolved through the registry (:func:`sb3_genrl.envs.get_task`); this layer imports
the tasks, the core library (:class:`~sb3_genrl.GenRL`) never does.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import pathlib
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.callbacks import CallbackList
from stable_baselines3.common.monitor import ResultsWriter
from stable_baselines3.common.vec_env import VecMonitor

from sb3_genrl.checks import (
    check_device,
    check_episodes,
    check_input_path,
    check_int,
    check_not_in_input,
    check_output_dir,
    check_positive_int,
    check_seed,
    json_argument,
)
from sb3_genrl.curves import (
    EPISODE_INFO,
    LOG_DIR,
    LOG_FILES,
    MONITOR_FILE,
    episode_info,
    monitor_episodes,
    training_logger,
    write_learning_curve,
)
from sb3_genrl.data import dataset_info
from sb3_genrl.data.fingerprints import dataset_fingerprint
from sb3_genrl.envs import TASKS, get_task
from sb3_genrl.envs.external import SuccessInfo, check_success_key, resolve_task
from sb3_genrl.generative import load
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl.demonstrations import DemonstrationCallback, build_callbacks, callback_entries
from sb3_genrl.genrl.generator_files import generator_digest
from sb3_genrl.genrl.genrl import EStep, GenRL
from sb3_genrl.genrl.hindsight_buffer import NO_SUCCESS_INFO
from sb3_genrl.genrl.policies import MlpPolicy
from sb3_genrl.genrl.settings import NOT_SETTINGS, SETTINGS, check_genrl_settings
from sb3_genrl.run.checkpoint import CHECKPOINT_EVERY, GenRLCheckpoint, RandomStateRecorder, resume_genrl, resume_state
from sb3_genrl.run.folder import SUMMARY, keep_episodes, open_run, remove_checkpoint
from sb3_genrl.utils import atomic_write_json, folder_lock
from sb3_genrl.vec_env import MAIN_GUARD, latent_envs
from sb3_genrl.wrappers import LatentActionWrapper


def evaluate_on_goals(
    model: GenRL,
    task: str,
    goals: int = 100,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Play the policy's deterministic latent actions for ``goals`` random goals through the task's fast path.

    :param model: a trained GenRL model with its generator
    :param task: a task name from :data:`sb3_genrl.envs.TASKS` or its Gymnasium id
    :param goals: number of goals, drawn with ``np.random.default_rng(seed)``
    :param seed: seed of the goals
    :return: the goals ``(goals, 2)``, the rewards (minus the final distance, m) and the episodes' infos
    """
    if model.generator is None:
        raise ValueError("this GenRL model has no generator: pass generator= to GenRL.load()")
    env = get_task(task).make_env()
    rng = np.random.default_rng(seed)
    goal_array = np.array([env.sample_goal(rng) for _ in range(goals)], dtype=np.float32)
    latents, _ = model.predict(goal_array, deterministic=True)
    rewards, infos = env.play_trajectories(model.generator.decode(latents), goal_array)
    env.close()
    return goal_array, rewards, infos


def _resolve_env_id(task: str) -> tuple[str, str]:
    """The Gymnasium id and name of a registered task, of any registered Gymnasium id (a user's own env), or of a task
    named otherwise (``metaworld/<name>``, ``module:Id``, a name given by :func:`sb3_genrl.envs.external.register`)."""
    if task not in TASKS and task in gym.registry:
        return task, task
    resolved = resolve_task(task)  # raises, naming what a task may be
    return resolved.env_id, resolved.spec.name if resolved.spec is not None else resolved.name


def train_policy(
    task: str,
    generator: TrajectoryGenerator | str,
    *,
    episodes: int,
    seed: int = 0,
    out_dir: str | os.PathLike,
    e_step: EStep = "trpo",
    batch_episodes: int = 64,
    n_envs: int | None = None,
    device: str = "auto",
    progress_bar: bool = False,
    verbose: int = 0,
    checkpoint_every: int | None = CHECKPOINT_EVERY,
    overwrite: bool = False,
    n_threads: int | None = None,
    demonstrations: str | os.PathLike | None = None,
    callback: Any = None,
    horizon: int | None = None,
    success_key: str | None = None,
    **genrl_kwargs: Any,
) -> dict[str, Any]:
    """Train a GenRL policy for ``episodes`` episodes on ``task`` and write everything to ``out_dir``.

    Writes ``genrl_policy.zip`` (the model; a generator given as a path is kept as its ``generator_path``),
    ``summary.json``, ``episodes.monitor.csv`` (SB3's Monitor: one row per episode, written as training goes),
    ``logs/`` (SB3's logger: ``progress.csv`` and TensorBoard, one row per EM iteration), ``learning_curve.csv`` and
    ``learning_curve.png`` (each iteration's mean reward, :func:`sb3_genrl.curves.write_learning_curve`).

    :param task: a task name from :data:`sb3_genrl.envs.TASKS`, or any registered Gymnasium id
    :param generator: the trajectory generator or the path of a saved one
    :param episodes: total episodes (trajectories played); rounded up to whole iterations
    :param seed: random seed
    :param out_dir: output folder (created), locked while the run works in it; a rerun of the same run into it
        returns the finished run's summary, or resumes the unfinished one; another run's folder is refused (see
        :mod:`sb3_genrl.run.folder`)
    :param e_step: ``"trpo"`` or ``"kl_penalty"`` (see :class:`~sb3_genrl.GenRL`)
    :param batch_episodes: the episodes of one EM iteration (GenRL's ``n_steps * n_envs``)
    :param n_envs: envs played at a time; a divisor of ``batch_episodes``. Above 1, a task with a fast path (the arm
        tasks) plays each step's trajectories in one threaded call in this process on ``n_threads`` cores
        (:class:`~sb3_genrl.vec_env.BatchedLatentVecEnv`), any other task each env in its own process (SB3's
        ``SubprocVecEnv``: a script must then run its work under ``if __name__ == "__main__":``; the Monitor's
        ``cpu_seconds`` is then the env process's). Default ``None``: ``batch_episodes`` for a task with a fast path
        (an iteration's episodes played together on all cores), else 1. The result depends on it (the envs draw their
        goals from seeds ``seed``, ``seed + 1``, ...), never on the machine nor ``n_threads``.
    :param device: torch device
    :param progress_bar: show a progress bar
    :param verbose: GenRL verbosity
    :param checkpoint_every: episodes between checkpoints (``None``: none), at the start of an iteration; the same
        run into the same ``out_dir`` resumes from the last one and ends as the run would have ended without the stop,
        bit for bit (:mod:`sb3_genrl.run.checkpoint`)
    :param overwrite: replace a run already in ``out_dir`` (its files only) instead of refusing or resuming it
    :param n_threads: simulation threads of the batched fast path (default: all cores)
    :param demonstrations: the dataset of the settings' :class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback`
        (settings that learn from demonstrations, such as the Fetch tasks' entries, need it; others refuse it); its
        fingerprint is part of the run's recorded settings
    :param callback: the run's callbacks in rl-zoo3's form (a task's entry's ``callback``, which
        :func:`~sb3_genrl.study.quickstart.task_settings` puts among the settings; see
        :func:`~sb3_genrl.genrl.demonstrations.build_callbacks`), built and checked before any work
    :param horizon: the env's episodes truncated to this many steps (``max_episode_steps`` of ``gymnasium.make``): an
        outside task's demonstrations recorded with a ``horizon`` shorter than its own (see
        :func:`sb3_genrl.envs.demonstrations.record_demonstrations`); None: for a task from outside the package given
        ``demonstrations`` (a dataset folder), the horizon they were recorded with, else the env's own episode length
    :param success_key: the info key of the env's success, copied to ``info["is_success"]`` for the Monitor's success
        and the refits (:class:`~sb3_genrl.envs.external.SuccessInfo`); default: a task from outside the package
        reads ``is_success``, falling back to ``success`` (the package's tasks report ``is_success`` themselves)
    :param genrl_kwargs: further :class:`~sb3_genrl.GenRL` arguments
    :return: paths of the outputs and a summary (``episodes``, ``iterations``, ``final_mean_reward``,
        ``best_mean_reward``, ``genrl_settings``: every GenRL hyperparameter in effect, see :func:`genrl_settings`)
    """
    env_id, task_name = _resolve_env_id(task)
    if horizon is None and task_name not in TASKS and demonstrations is not None and pathlib.Path(demonstrations).is_dir():
        horizon = dataset_info(demonstrations).get("horizon")  # the episodes end where the recorded ones did
    _check_arguments(
        episodes, batch_episodes, n_envs, seed, device, checkpoint_every, n_threads, {"e_step": e_step, **genrl_kwargs}
    )
    out = check_output_dir(out_dir)
    check_not_in_input(out, demonstrations, "out_dir", "the run's files would join the demonstrations' own")
    callbacks = build_callbacks(callback, demonstrations=demonstrations, what=f"the settings of {task_name}", task=task)
    # Built first: a generator that does not fit the task is refused before anything is written. The settings'
    # latent_clip is the wrapper's (GenRL refuses a wrapped env with another).
    latent_clip = genrl_kwargs.get("latent_clip", SETTINGS["latent_clip"].default)
    env = LatentActionWrapper(
        _make_env(env_id, horizon, success_key, outside=task_name not in TASKS),
        _as_generator(generator),
        latent_clip=latent_clip,
    )
    if n_envs is None:  # a fixed choice of the task, never of the machine: the result depends on n_envs
        n_envs = default_n_envs(env, batch_episodes)
    arguments = {
        "e_step": e_step,
        "seed": seed,
        "device": device,
        "verbose": verbose,
        **run_settings(genrl_kwargs, batch_episodes, n_envs),
    }
    settings = genrl_settings(arguments)
    if (settings.get("hindsight_kwargs") or {}).get("refit_every"):
        try:  # an env that reports no success is refused before its run folder is made
            _check_reports_success(env_id, horizon, success_key, task_name not in TASKS, env.generator, latent_clip, seed)
        except BaseException:
            env.close()
            raise
    identity = {
        "algorithm": "genrl",
        "task": task_name,
        "episodes": int(episodes),
        "seed": seed,
        "n_envs": n_envs,
        "batch_episodes": batch_episodes,
        "generator_sha256": generator_digest(env.generator),
        "genrl_settings": settings,
        **_callback_identity(callback, callbacks, env, arguments),
        **({} if horizon is None else {"horizon": int(horizon)}),
        **({} if success_key is None else {"success_key": success_key}),
    }
    return _open_and_run(
        env, generator, out, identity, arguments, checkpoint_every, progress_bar, env_id, n_threads, callbacks, overwrite
    )


def _make_env(env_id: str, horizon: int | None, success_key: str | None = None, *, outside: bool = False) -> gym.Env:
    """``gymnasium.make(env_id)``, its episodes truncated to ``horizon`` steps when given (at most its own length), its
    success copied to ``info["is_success"]`` from ``success_key`` (default for a task from ``outside`` the package:
    ``is_success``, falling back to ``success``)."""
    if success_key is not None:
        check_success_key(success_key)
    if horizon is None:
        env = gym.make(env_id)
    else:
        check_positive_int(horizon, "horizon")
        own = gym.spec(env_id).max_episode_steps
        if own is not None and horizon > own:
            raise ValueError(f"horizon {horizon} is longer than {env_id}'s episodes ({own} steps); expected at most {own}")
        env = gym.make(env_id, max_episode_steps=int(horizon))
    if success_key is None and not outside:
        return env
    return SuccessInfo(env, success_key or "is_success")


def _check_reports_success(
    env_id: str,
    horizon: int | None,
    success_key: str | None,
    outside: bool,
    generator: TrajectoryGenerator,
    latent_clip: float,
    seed: int,
) -> None:
    """Play one episode of a fresh env of the run's (the prior's centre, from reset ``seed``) and refuse the run when
    its step reports no ``info["is_success"]``: the refits of ``hindsight_kwargs`` need each pull's success, and would
    otherwise stop at the run's first pull, its folder already made."""
    probe = LatentActionWrapper(_make_env(env_id, horizon, success_key, outside=outside), generator, latent_clip=latent_clip)
    try:
        probe.reset(seed=seed)
        info = probe.step(np.zeros(probe.action_space.shape, dtype=probe.action_space.dtype))[-1]
    finally:
        probe.close()
    if "is_success" not in info:
        raise ValueError(NO_SUCCESS_INFO)


def _open_and_run(
    env: LatentActionWrapper,
    generator: TrajectoryGenerator | str,
    out: pathlib.Path,
    identity: dict[str, Any],
    arguments: dict[str, Any],
    checkpoint_every: int | None,
    progress_bar: bool,
    env_id: str,
    n_threads: int | None,
    callbacks: list[Any],
    overwrite: bool,
) -> dict[str, Any]:
    """:func:`_run` in ``out``, locked, unless ``out`` holds another run (refused) or this one finished (its summary)."""
    with folder_lock(out):  # one run at a time in out; another run's files are refused, never mixed in
        try:
            finished = open_run(out, identity, OUTPUTS, overwrite=overwrite)
        except BaseException:  # another run's folder: refused, nothing changed
            env.close()
            raise
        if finished is not None:  # this very run, finished: nothing to do
            env.close()
            return finished
        return _run(env, generator, out, identity, arguments, checkpoint_every, progress_bar, env_id, n_threads, callbacks)


def _callback_identity(
    callback: Any, callbacks: list[Any], env: LatentActionWrapper, arguments: dict[str, Any]
) -> dict[str, Any]:
    """What the run's callbacks add to its recorded settings (nothing without any): their settings and the
    fingerprints of their demonstrations, which are checked against the env and the settings first (``env`` is closed
    when they are refused)."""
    if callback is None:
        return {}

    settings = genrl_settings(arguments)
    datasets = []
    for demonstrations in (item for item in callbacks if isinstance(item, DemonstrationCallback)):
        try:
            hindsight = settings.get("hindsight_kwargs")
            demonstrations.check(
                env.generator,
                env.observation_space,
                settings["latent_clip"],
                hindsight is not None,
                bool((hindsight or {}).get("refit_every")),
            )
        except ValueError:
            env.close()
            raise
        datasets.append(dataset_fingerprint(demonstrations.dataset))
    return {
        "callback": _json_value(
            [
                {path: {key: value for key, value in kwargs.items() if key != "dataset"}}
                for path, kwargs in callback_entries(callback)
            ]
        ),
        "demonstrations": datasets,
    }


def _run(
    env: LatentActionWrapper,
    generator: TrajectoryGenerator | str,
    out: pathlib.Path,
    identity: dict[str, Any],
    arguments: dict[str, Any],
    checkpoint_every: int | None,
    progress_bar: bool,
    env_id: str,
    n_threads: int | None = None,
    callbacks: list[Any] | None = None,
) -> dict[str, Any]:
    """Train the run ``identity`` in ``out`` (from its checkpoint when it has one) with ``callbacks``; its summary,
    written last."""
    try:
        state = resume_state(out, identity)  # this unfinished run's checkpoint, if any
        if state is not None:
            keep_episodes(out, state["episodes"])
    except BaseException:  # another run's checkpoint, or a Monitor file shorter than it: refused
        env.close()
        raise
    checkpointing = None if checkpoint_every is None else (int(checkpoint_every), identity)
    model = _train(
        training_env(env, identity["n_envs"], out, append=state is not None, n_threads=n_threads),
        generator,
        identity["episodes"],
        out,
        progress_bar,
        arguments,
        state,
        checkpointing,
        callbacks or [],
    )
    curve = write_learning_curve(
        out / MONITOR_FILE, out, window=identity["batch_episodes"], title=f"GenRL on {env_id} (seed {identity['seed']})"
    )
    result = (
        {key: identity[key] for key in ("algorithm", "task", "seed", "n_envs")}
        | _output_paths(out)
        | {
            "episodes": int(model.num_timesteps),
            "iterations": len(curve["episodes"]),
            "final_mean_reward": float(curve["mean_reward"][-1]),
            "best_mean_reward": float(np.max(curve["mean_reward"])),
            "genrl_settings": identity["genrl_settings"],
        }
        | {key: identity[key] for key in ("horizon", "success_key") if key in identity}
    )
    if state is not None:
        result["resumed_at_episodes"] = [*state.get("resumed_at_episodes", []), state["episodes"]]
    atomic_write_json(out / SUMMARY, result)
    remove_checkpoint(out)  # after the summary: the run is finished once that exists
    return result


# What a run writes in its folder (besides summary.json, checkpoint/ and run_record.json; see sb3_genrl.run.folder)
OUTPUTS = (
    "genrl_policy.zip",
    "genrl_policy.generator.pt",
    "learning_curve.csv",
    "learning_curve.png",
    MONITOR_FILE,
    *LOG_FILES,
)


def _train(
    env: Any,
    generator: TrajectoryGenerator | str,
    episodes: int,
    out: pathlib.Path,
    progress_bar: bool,
    genrl_kwargs: dict[str, Any],
    state: dict[str, Any] | None,
    checkpointing: tuple[int, dict] | None,
    callbacks: list[Any],
) -> GenRL:
    """Train GenRL on ``env`` with SB3's logger in ``out`` and ``callbacks``, from the checkpoint ``state`` (``None``:
    from the start), checkpointing every ``checkpointing[0]`` episodes; save it there, and close ``env``."""
    try:
        logger = training_logger(out, genrl_kwargs["verbose"])
        if state is None:
            model = make_genrl(env, generator, **genrl_kwargs)
            model.set_logger(logger)
        else:
            model = resume_genrl(state, env, generator, genrl_kwargs["device"], logger)
        if checkpointing is not None:  # after the others: a checkpoint saves what they set at the same call
            callbacks = [*callbacks, GenRLCheckpoint(out, *checkpointing, state)]
        model.learn(
            total_timesteps=episodes - model.num_timesteps,
            progress_bar=progress_bar,
            tb_log_name="GenRL",
            reset_num_timesteps=state is None,
            callback=CallbackList(callbacks) if callbacks else None,
        )
        model.logger.dump(model.num_timesteps)  # SB3 dumps before each update: this writes the last one's logs
        model.logger.close()
        model.save(out / "genrl_policy.zip")
    finally:
        env.close()  # the env processes, and the Monitor file
    return model


def genrl_kwargs_argument(text: str) -> dict[str, Any]:
    """An argparse ``type`` for ``--genrl-kwargs``: a JSON object of GenRL settings, checked by
    :func:`~sb3_genrl.genrl.check_genrl_settings`."""

    try:
        return check_genrl_settings(json_argument(text))
    except (TypeError, ValueError) as error:
        raise argparse.ArgumentTypeError(str(error)) from None


# Settings laid over a task's are checked alone as any others (check the joined settings too).
genrl_kwargs_override_argument = genrl_kwargs_argument


def make_genrl(env: Any, generator: TrajectoryGenerator | str | None = None, **genrl_kwargs: Any) -> GenRL:
    """``GenRL`` with settings that may name the policy (``"policy"``, as a task's ``genrl_kwargs`` may)."""
    if "callback" in genrl_kwargs:  # a task's entry that names callbacks (task_settings puts them among its settings)
        raise ValueError(
            "callback is not a GenRL setting but learn()'s: build the callbacks with "
            "sb3_genrl.genrl.demonstrations.build_callbacks and give them to learn(callback=...)"
        )
    policy = genrl_kwargs.pop("policy", "MlpPolicy")
    return GenRL(policy, env, generator, **genrl_kwargs)


def _check_arguments(
    episodes: int,
    batch_episodes: int,
    n_envs: int | None,
    seed: int,
    device: str,
    checkpoint_every: int | None,
    n_threads: int | None,
    genrl_kwargs: dict[str, Any],
) -> None:
    check_episodes(episodes)
    if checkpoint_every is not None:
        check_positive_int(checkpoint_every, "checkpoint_every")
    if n_threads is not None:
        check_positive_int(n_threads, "n_threads")
    check_int(batch_episodes, "batch_episodes", minimum=2)
    if n_envs is not None:  # None: the task's default (default_n_envs), a divisor of batch_episodes in this process
        check_positive_int(n_envs, "n_envs")
        if n_envs > 1 and getattr(multiprocessing.current_process(), "_inheriting", False):  # Python's own test
            raise RuntimeError(MAIN_GUARD)  # in an env process that re-imports the script: its stderr shows why
        if batch_episodes % n_envs:
            raise ValueError(f"batch_episodes ({batch_episodes}) must be a multiple of n_envs ({n_envs})")
    check_seed(seed)
    check_device(device)
    if "n_steps" in genrl_kwargs:  # the learning curve's window and the summary's iterations follow batch_episodes
        raise ValueError(
            f"n_steps={genrl_kwargs['n_steps']!r}: give the episodes per iteration as batch_episodes "
            "(n_steps is batch_episodes / n_envs)"
        )
    check_genrl_settings(genrl_kwargs)


def default_n_envs(env: LatentActionWrapper, batch_episodes: int) -> int:
    """The envs a run plays at a time when none is asked for: an iteration's ``batch_episodes`` together where the task
    has a fast path (one threaded simulation call per iteration, on all cores), else 1 (another count plays env
    processes, which a script must start under ``if __name__ == "__main__":``)."""
    return batch_episodes if env.use_fast_path else 1


def training_env(
    env: LatentActionWrapper, n_envs: int, out: pathlib.Path, *, append: bool = False, n_threads: int | None = None
) -> Any:
    """The monitored training env of a run in ``out`` (GenRL's, or a latent-space baseline's): ``env`` itself, or
    ``n_envs`` copies of it played together
    (:class:`~sb3_genrl.vec_env.BatchedLatentVecEnv` on ``n_threads``, for a task with a fast path) or in their own
    processes, each under a :class:`~sb3_genrl.run.checkpoint.RandomStateRecorder` (``append``: a resumed run adds
    to the Monitor file)."""
    if n_envs == 1:
        return monitor_episodes(RandomStateRecorder(env), out, append=append)

    spec, generator = env.env.spec, env.generator  # the spec, not the id: the processes need not know the id
    batched, latent_clip = env.use_fast_path, env.latent_clip
    env.close()
    venv = latent_envs(partial(_episode_env, spec, generator, latent_clip), n_envs, batched=batched, n_threads=n_threads)
    keys = (*EPISODE_INFO, "cpu_seconds")
    monitor = VecMonitor(venv, None if append else str(out / MONITOR_FILE), info_keywords=keys)
    if append:  # SB3's VecMonitor always starts a new file
        monitor.results_writer = ResultsWriter(
            str(out / MONITOR_FILE), header={"t_start": monitor.t_start}, extra_keys=keys, override_existing=False
        )
    return monitor


def _episode_env(
    spec: gym.envs.registration.EnvSpec,
    generator: TrajectoryGenerator,
    latent_clip: float,
    own_process: bool = True,
) -> gym.Env:
    """One env of the training VecEnv (in its own process for a ``SubprocVecEnv``): the latent-action task, its action
    box ``latent_clip`` wide, with the Monitor's info keys."""
    if own_process:
        torch.set_num_threads(1)  # one core per env process
    return episode_info(RandomStateRecorder(LatentActionWrapper(gym.make(spec), generator, latent_clip=latent_clip)))


def _json_settings(genrl_kwargs: dict[str, Any]) -> dict[str, Any]:
    """The GenRL arguments as a JSON file holds them: numbers, strings, booleans, None, and lists and string-keyed
    dicts of them (``policy_kwargs``), a class by its qualified name; an argument that holds anything else is left
    out."""
    settings = {key: _json_value(value) for key, value in genrl_kwargs.items()}
    return {key: value for key, value in settings.items() if value is not _UNREPRESENTABLE}


_UNREPRESENTABLE = object()


def _json_value(value: Any) -> Any:
    if isinstance(value, bool | int | float | str | type(None)):
        return value
    if isinstance(value, type):
        return f"{value.__module__}.{value.__qualname__}"
    if isinstance(value, list | tuple):
        items = [_json_value(item) for item in value]
        return _UNREPRESENTABLE if any(item is _UNREPRESENTABLE for item in items) else items
    if isinstance(value, dict) and all(isinstance(key, str) for key in value):
        items = {key: _json_value(item) for key, item in value.items()}
        return _UNREPRESENTABLE if any(item is _UNREPRESENTABLE for item in items.values()) else items
    return _UNREPRESENTABLE


def run_settings(genrl_kwargs: dict[str, Any], batch_episodes: int, n_envs: int) -> dict[str, Any]:
    """The GenRL arguments :func:`train_policy` runs with for ``batch_episodes`` episodes per iteration on ``n_envs``
    envs: ``genrl_kwargs`` with ``n_steps = batch_episodes / n_envs`` and their ``batch_size`` (default 64) capped at
    ``batch_episodes``. What a stage that calls it records, through :func:`genrl_settings`."""
    settings = dict(genrl_kwargs)
    batch_size = min(batch_episodes, settings.pop("batch_size", 64))
    return {"n_steps": batch_episodes // n_envs, "batch_size": batch_size, **settings}


def genrl_settings(genrl_kwargs: dict[str, Any] | None = None) -> dict[str, Any]:
    """Every GenRL hyperparameter in effect with ``genrl_kwargs``: GenRL's defaults, updated with them (those a JSON
    file can hold). Recorded by the runs and the stages that train GenRL, so that a change of a default is seen when
    a stage is resumed, not silently mixed with results made under the old one. The policy is named only when it is
    not the default ``"MlpPolicy"`` (the records of runs with the default policy do not name it). A task entry's
    ``callback`` is not a GenRL setting and is left out."""
    defaults = {name: setting.default for name, setting in SETTINGS.items() if name != "policy"}
    settings = defaults | dict(genrl_kwargs or {})
    policy = settings.pop("policy", "MlpPolicy")
    if policy not in ("MlpPolicy", MlpPolicy):
        settings["policy"] = policy if isinstance(policy, str) else f"{policy.__module__}.{policy.__qualname__}"
    return _json_settings({name: value for name, value in settings.items() if name not in (*NOT_SETTINGS, "callback")})


def effective_genrl_settings(genrl_kwargs: dict[str, Any], batch_episodes: int, n_envs: int) -> dict[str, Any]:
    """Every GenRL setting in effect in :func:`train_policy`'s run with ``genrl_kwargs``, ``batch_episodes`` and
    ``n_envs`` (:func:`genrl_settings` of :func:`run_settings`): what a stage that trains GenRL records."""
    return genrl_settings(run_settings(genrl_kwargs, batch_episodes, n_envs))


def _output_paths(out: pathlib.Path) -> dict[str, str]:
    files = {
        "model_path": "genrl_policy.zip",
        "csv_path": "learning_curve.csv",
        "png_path": "learning_curve.png",
        "episodes_csv_path": MONITOR_FILE,
        "log_dir": LOG_DIR,
    }
    return {key: str(out / name) for key, name in files.items()}


def _as_generator(generator: TrajectoryGenerator | str | os.PathLike) -> TrajectoryGenerator:
    if isinstance(generator, TrajectoryGenerator):
        return generator
    check_input_path(generator, "generator")

    return load(generator)
