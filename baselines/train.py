"""Train a baseline on a task with the same outputs as ``genrl train-policy`` (paper sections 6.1.5, 6.2, 6.3).

Feedback baselines (per-step actions on the task's observation plus the time feature, see
:mod:`sb3_genrl.baselines.feedback`; settings in ``hyperparams/ppo.yml`` and ``sac.yml``, read by
:mod:`sb3_genrl.baselines.hyperparameters`):

- ``ppo``: PPO whose actor is first cloned from the demonstrations (:mod:`sb3_genrl.baselines.bc`: held-out
  episodes, early stopping, exploration std = held-out residual std), then trained on the sparse terminal reward.
  The summary records the cloned policy's deterministic and sampled mean distance to :data:`EVAL_GOALS` held-out
  goals and what PPO's first batch (its first rollout, sampled from the cloned policy) scored.
- ``sac``: SAC with its replay buffer prefilled with the demonstration transitions and rewards.
- ``sac-no-prefill``: the same SAC without the demonstrations in its buffer (their statistics still normalise the
  observations), for reference.
- ``sac-her``: SAC with hindsight experience replay on the task's goal-conditioned variant
  (:mod:`sb3_genrl.envs.goal`), the demonstrations written into its ``HerReplayBuffer`` as episodes.

A task from outside the package (``metaworld/<name>``, a Gymnasium id, ``module:Id``) takes ``sac`` and
``sac-no-prefill`` on its recorded demonstrations, scored on held-out seeded resets (:mod:`sb3_genrl.baselines.outside`).

Latent-space baselines (the same generator as GenRL, on :class:`~sb3_genrl.LatentActionWrapper`, one-step
episodes): ``latent-ppo``, ``latent-sac``, ``latent-trpo`` - stock SB3 / sb3-contrib algorithms with their
defaults except 64 episodes per update (GenRL's batch; ``hyperparams/latent_*.yml``), so they show what the EM update
adds. On a task with a fast path they play an update's episodes together on all cores (:func:`default_latent_envs`).

Every run writes ``episodes.monitor.csv`` (SB3's Monitor: one row per episode with its return, length, table
contacts, distance and the process' CPU seconds so far, written as training goes), ``learning_curve.csv`` /
``learning_curve.png`` (mean over windows of 64 episodes), SB3's logs in ``logs/`` (``progress.csv`` and
TensorBoard), the model (with its normalisation statistics; ``ppo`` also the cloned policy before PPO,
``bc_policy.zip``), and ``summary.json``, whose ``final_eval`` is the trained policy's deterministic final distance
to :data:`EVAL_GOALS` held-out goals (:func:`evaluate_trained`, the same goals for every method and for GenRL), and
whose ``training_health`` says whether the training stayed stable (:func:`training_health`; a warning is issued
when it did not).
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import time
import warnings
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from sb3_genrl.baselines import BASELINES, LATENT_BASELINES, OFF_POLICY_BASELINES
from sb3_genrl.baselines.checkpoint import ReplayBufferCheckpoint, resume_off_policy
from sb3_genrl.baselines.evaluation import EVAL_GOALS, evaluate_trained, training_health
from sb3_genrl.baselines.feedback import (
    add_time_feature,
    evaluate_feedback_policy,
    make_feedback_env,
)
from sb3_genrl.baselines.her import goal_episodes
from sb3_genrl.baselines.hyperparameters import (
    algorithm_class,
    baseline_settings,
    check_algorithm_kwargs,
    settings_record,
    zoo_hyperparams,
)
from sb3_genrl.baselines.models import ppo_with_behaviour_cloning, sac_her_with_demonstrations, sac_with_demonstrations
from sb3_genrl.baselines.outside import (
    OUTSIDE_BASELINES,
    OUTSIDE_SETTINGS,
    evaluate_step_policy,
    outside_env,
    outside_horizon,
    outside_sac,
    outside_transitions,
)
from sb3_genrl.envs import get_task
from sb3_genrl.envs.external import HELD_OUT_RESETS, resolve_task
from stable_baselines3 import PPO, SAC

from sb3_genrl.checks import (
    check_device,
    check_episodes,
    check_input_path,
    check_output_dir,
    check_positive_int,
    check_seed,
    sub_seed,
)
from sb3_genrl.curves import LOG_FILES, MONITOR_FILE, monitor_episodes, read_monitor, training_logger, write_learning_curve
from sb3_genrl.data import load_transitions
from sb3_genrl.generative import load
from sb3_genrl.genrl.generator_files import generator_digest
from sb3_genrl.hyperparams import EVAL_GOAL_SEED
from sb3_genrl.run import training_env
from sb3_genrl.run.checkpoint import resume_state
from sb3_genrl.run.folder import keep_episodes, open_run, remove_checkpoint
from sb3_genrl.utils import atomic_path, atomic_write_json, folder_lock, one_torch_thread
from sb3_genrl.wrappers import LatentActionWrapper, env_id_has_fast_path

CHECKPOINT_EVERY = 250  # episodes between checkpoints of an off-policy baseline (about 5 minutes of one core)


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
    bc_kwargs: dict[str, Any] | None = None,
    algorithm_kwargs: dict[str, Any] | None = None,
    eval_goals: int = EVAL_GOALS,
    checkpoint_every: int | None = CHECKPOINT_EVERY,
    device: str = "auto",
    progress_bar: bool = False,
    verbose: int = 0,
    window: int = 64,
    overwrite: bool = False,
    n_envs: int | None = None,
    n_threads: int | None = None,
    eval_resets: int = HELD_OUT_RESETS,
) -> dict[str, Any]:
    """Train one baseline for ``episodes`` episodes and write its outputs to ``out_dir``.

    A task from outside the package (one without a TaskSpec: ``metaworld/<name>``, a Gymnasium id, ``module:Id``)
    takes ``sac`` and ``sac-no-prefill`` (:mod:`sb3_genrl.baselines.outside`): SB3's SAC learns from its recorded
    demonstrations (``demos``, a dataset folder of ``genrl demos``), for ``episodes`` episodes of their horizon, and is
    scored closed loop on ``eval_resets`` held-out seeded resets, the summary's ``final_eval``.

    :param algorithm: one of :data:`BASELINES`
    :param task: a task name from :data:`sb3_genrl.envs.TASKS` (or its Gymnasium id), or a task from outside the
        package (:func:`~sb3_genrl.envs.external.resolve_task`)
    :param episodes: budget of episodes (the horizon's worth of environment steps each for the feedback baselines)
    :param out_dir: output folder (created)
    :param seed: random seed
    :param demos: demonstrations for the feedback baselines: a dataset path or a transitions dict (see
        :func:`sb3_genrl.data.load_transitions`)
    :param demo_episodes: use only the first ``demo_episodes`` demonstration episodes (default: all)
    :param generator: a generator (or its file) for the latent-space baselines
    :param bc_kwargs: behaviour cloning options (``ppo``; see :func:`~sb3_genrl.baselines.bc.behaviour_cloning`)
    :param algorithm_kwargs: changes to the baseline's rl-zoo3 settings, as arguments of its SB3 class (e.g.
        ``{"target_kl": 0.02}`` for PPO; see :func:`~sb3_genrl.baselines.hyperparameters.check_algorithm_kwargs`),
        recorded in the summary's ``settings``
    :param eval_goals: held-out goals on which the trained policy (and ``ppo``'s cloned policy) is evaluated
        deterministically, the summary's ``final_eval`` (see :func:`evaluate_trained`)
    :param checkpoint_every: episodes between checkpoints of the off-policy baselines (``None``: none); the same run
        into the same ``out_dir`` resumes from the last one (:mod:`sb3_genrl.baselines.checkpoint`)
    :param window: episodes per point of the learning curve
    :param overwrite: replace a run already in ``out_dir`` (its files only) instead of refusing or resuming it; without
        it, a rerun of the same run returns the finished run's summary or resumes the unfinished one, and another
        run's folder is refused (see :mod:`sb3_genrl.run.folder`); ``out_dir`` is locked while the run works in it
    :param n_envs: latent-space baselines only: envs played at a time (default :func:`default_latent_envs`: an
        update's episodes together where the task has a fast path, else 1). The run's result depends on it, never on
        the number of cores; ``latent_vector_settings`` says how the settings follow it
    :param n_threads: simulation threads of a fast path's batched envs (default: all cores); the result does not
        depend on it
    :param eval_resets: a task from outside the package: the held-out seeded resets its policy is scored on
        (:func:`~sb3_genrl.baselines.outside.evaluate_step_policy`, those GenRL's policies are scored on)
    """
    _check_arguments(algorithm, episodes, seed, demos, demo_episodes, generator, eval_goals, checkpoint_every, device)
    _check_envs(algorithm, n_envs, n_threads)
    spec, out = resolve_task(task).spec, check_output_dir(out_dir)
    if spec is None:
        return _train_outside(
            algorithm,
            task,
            out,
            {"episodes": int(episodes), "seed": seed, "demos": demos, "demo_episodes": demo_episodes},
            {"algorithm_kwargs": algorithm_kwargs, "eval_resets": eval_resets, "checkpoint_every": checkpoint_every},
            {"device": device, "verbose": verbose, "progress_bar": progress_bar, "window": window, "overwrite": overwrite},
        )
    changes = check_algorithm_kwargs(algorithm, algorithm_kwargs)
    began = time.perf_counter(), time.process_time()
    transitions, generator = _inputs(algorithm, spec.name, demos, demo_episodes, generator)
    steps = int(episodes) if transitions is None else int(episodes) * spec.horizon
    summary = {"algorithm": algorithm, "task": spec.name, "episodes": int(episodes), "seed": seed} | (
        _latent_record(algorithm, spec.name, changes, n_envs)
        if transitions is None
        else _demonstration_record(algorithm, spec.name, transitions, bc_kwargs, changes)
    )
    checkpoint_every = checkpoint_every if algorithm in OFF_POLICY_BASELINES else None  # the others: short runs
    identity = _identity(summary) | {"eval_goals": eval_goals, "generator_sha256": generator_digest(generator)}
    outputs = (f"{algorithm}_policy.zip", "bc_policy.zip", *CURVE_FILES)
    return _run_in_folder(
        out,
        summary,
        identity,
        outputs,
        steps,
        began,
        {"checkpoint_every": checkpoint_every, "overwrite": overwrite, "device": device, "verbose": verbose}
        | {"progress_bar": progress_bar, "window": window},
        lambda: _model(
            algorithm,
            spec.name,
            out,
            transitions,
            generator,
            steps,
            summary,
            eval_goals,
            bc_kwargs,
            changes,
            {"seed": seed, "device": device, "verbose": verbose},
            n_threads,
        ),
        lambda model: evaluate_trained(algorithm, model, spec.name, generator=generator, goals=eval_goals),
    )


def _run_in_folder(
    out: pathlib.Path,
    summary: dict[str, Any],
    identity: dict[str, Any],
    outputs: tuple[str, ...],
    steps: int,
    began: tuple[float, float],
    options: dict[str, Any],
    new_model: Callable[[], Any],
    final_eval: Callable[[Any], dict[str, Any]],
) -> dict[str, Any]:
    """A baseline's run in ``out``, locked (another run's files are refused, never mixed in): a finished run's summary,
    or the model (``new_model()``, its setup's seconds since ``began`` recorded, or its checkpoint's) trained to
    ``steps`` environment steps and finished with ``final_eval(model)``. ``options``: ``checkpoint_every``,
    ``overwrite``, ``device``, ``verbose``, ``progress_bar`` and ``window``. Torch runs on one thread meanwhile
    (:func:`~sb3_genrl.utils.one_torch_thread`), as GenRL learns: the result does not depend on the machine."""
    algorithm, task = summary["algorithm"], summary["task"]
    with folder_lock(out), one_torch_thread():
        finished = open_run(out, identity, outputs, overwrite=options["overwrite"])
        if finished is not None:  # this very run, finished: nothing to do
            return finished
        state = None if options["checkpoint_every"] is None else resume_state(out, _identity(summary))
        if state is None:
            model = new_model()
            # demonstrations, behaviour cloning and its evaluation: wall-clock and this process' CPU seconds
            summary |= {
                "setup_seconds": time.perf_counter() - began[0],
                "setup_cpu_seconds": time.process_time() - began[1],
            }
        else:  # this run's checkpoint
            model, summary = _resumed_model(algorithm, task, out, state, options["device"])
        try:
            summary["learn_seconds"] = _learn(
                model, steps, out, state, options["checkpoint_every"], summary, options["progress_bar"], options["verbose"]
            )
        finally:  # the training env: its Monitor file (complete after this) and any env processes
            model.get_env().close()
        return _finish(algorithm, task, out, summary, options["window"], lambda: final_eval(model))


CURVE_FILES = ("learning_curve.csv", "learning_curve.png", MONITOR_FILE, *LOG_FILES)


def _inputs(algorithm: str, task: str, demos: Any, demo_episodes: int | None, generator: Any) -> tuple[Any, Any]:
    """The demonstration transitions of a feedback baseline (else ``None``) and the generator of a latent-space one
    (loaded from its file)."""
    if algorithm not in LATENT_BASELINES:
        return _demonstrations(demos, demo_episodes, task), generator
    if isinstance(generator, str | os.PathLike):
        generator = load(generator)
    return None, generator


def _model(
    algorithm: str,
    task: str,
    out: pathlib.Path,
    transitions: Any,
    generator: Any,
    steps: int,
    summary: dict[str, Any],
    eval_goals: int,
    bc_kwargs: dict[str, Any] | None,
    changes: dict[str, Any],
    common: dict[str, Any],
    n_threads: int | None = None,
) -> Any:
    """A new model to train: a latent-space baseline's, or a feedback baseline's with its demonstrations in place."""
    if transitions is None:
        return _latent_model(algorithm, task, generator, summary, common, out, n_threads)
    return _feedback_model(
        algorithm, task, transitions, steps, out, summary, eval_goals, bc_kwargs, common | {"settings": changes}
    )


def _finish(
    algorithm: str,
    task: str,
    out: pathlib.Path,
    summary: dict[str, Any],
    window: int,
    final_eval: Callable[[], dict[str, Any]],
) -> dict[str, Any]:
    """The trained run's results, final evaluation (``final_eval()``) and health in ``summary.json``; its checkpoint
    removed."""
    summary |= _episode_results(algorithm, task, out, window, summary["settings"])
    summary["final_eval"] = final_eval()
    summary["training_health"] = training_health(out)
    for warning in summary["training_health"]["warnings"]:
        warnings.warn(f"{algorithm} on {task}: {warning}", stacklevel=4)
    atomic_write_json(out / "summary.json", summary)
    remove_checkpoint(out)
    return summary


def _train_outside(
    algorithm: str,
    task: str,
    out: pathlib.Path,
    run: dict[str, Any],
    options: dict[str, Any],
    common: dict[str, Any],
) -> dict[str, Any]:
    """:func:`train_baseline` on a task from outside the package (:mod:`sb3_genrl.baselines.outside`): ``run`` holds
    the episodes, seed, demonstrations and their count; ``options`` the SAC changes, the held-out resets and the
    checkpoints; ``common`` the device, verbosity, progress bar, curve window and overwrite."""
    if algorithm not in OUTSIDE_BASELINES:
        raise ValueError(
            f"task {task!r} is from outside the package: genrl baseline takes {' and '.join(OUTSIDE_BASELINES)} there "
            f"(SAC learning from its recorded demonstrations), not {algorithm}"
        )
    check_positive_int(options["eval_resets"], "eval_resets")
    changes = check_algorithm_kwargs(algorithm, options["algorithm_kwargs"])
    began = time.perf_counter(), time.process_time()
    horizon = outside_horizon(run["demos"])
    transitions = _first_episodes(outside_transitions(task, run["demos"]), run["demo_episodes"])
    steps = run["episodes"] * horizon
    summary = {"algorithm": algorithm, "task": task, "episodes": run["episodes"], "seed": run["seed"]} | {
        "horizon": horizon,
        "demo_transitions": len(transitions["observations"]),
        "demo_sha256": _fingerprint(transitions),
        "settings": {"policy": "MlpPolicy", **OUTSIDE_SETTINGS, **changes},
    }
    identity = _identity(summary) | {"eval_resets": options["eval_resets"]}
    return _run_in_folder(
        out,
        summary,
        identity,
        (f"{algorithm}_policy.zip", *CURVE_FILES),
        steps,
        began,
        common | {"checkpoint_every": options["checkpoint_every"]},
        lambda: outside_sac(
            algorithm,
            monitor_episodes(outside_env(task, horizon), out),
            transitions,
            steps,
            run["seed"],
            device=common["device"],
            **changes,
        ),
        lambda model: evaluate_step_policy(
            lambda observation: model.predict(observation, deterministic=True)[0],
            task,
            horizon=horizon,
            resets=options["eval_resets"],
        ),
    )


def _learn(
    model: Any,
    steps: int,
    out: pathlib.Path,
    state: dict[str, Any] | None,
    checkpoint_every: int | None,
    summary: dict[str, Any],
    progress_bar: bool,
    verbose: int,
) -> float:
    """Train ``model`` from ``state`` (a checkpoint's, or ``None``: from the start) to ``steps`` environment steps with
    SB3's logger in ``out``, checkpointing every ``checkpoint_every`` episodes, and save it there; return the seconds
    it trained in all (those before a resume included)."""
    algorithm, start = summary["algorithm"], state or {"episodes": 0, "steps": 0, "learn_seconds": 0.0}
    callback = (
        None
        if checkpoint_every is None
        else ReplayBufferCheckpoint(out, checkpoint_every, _identity(summary), state, {"summary": summary})
    )
    model.set_logger(training_logger(out, verbose))
    began = time.perf_counter()
    model.learn(
        total_timesteps=steps - start["steps"],
        progress_bar=progress_bar,
        tb_log_name=algorithm,
        reset_num_timesteps=start["steps"] == 0,
        callback=callback,
    )
    seconds = time.perf_counter() - began
    model.logger.close()
    with atomic_path(out / f"{algorithm}_policy.zip") as tmp:
        model.save(tmp)
    return float(start["learn_seconds"]) + seconds


def _demonstration_record(
    algorithm: str, task: str, transitions: dict[str, np.ndarray], bc_kwargs: dict[str, Any] | None, changes: dict[str, Any]
) -> dict[str, Any]:
    """The summary's entries on the demonstrations and the settings of a feedback baseline (``changes``: the user's
    changes to them)."""
    settings = settings_record(task, {algorithm: changes})[algorithm]
    if algorithm == "ppo":
        settings["behaviour_cloning"] |= bc_kwargs or {}
    return {
        "demo_transitions": len(transitions["observations"]),
        "demo_sha256": _fingerprint(transitions),
        "settings": settings,
    }


def _identity(summary: dict[str, Any]) -> dict[str, Any]:
    """What a checkpoint must match to be resumed: the run's algorithm, task, budget, seed, data and settings."""
    keys = ("algorithm", "task", "episodes", "seed", "demo_transitions", "demo_sha256", "settings", "n_envs")
    return json.loads(json.dumps({key: summary[key] for key in keys if key in summary}))  # as state.json holds it


def _fingerprint(transitions: dict[str, np.ndarray]) -> str:
    """A digest of the demonstration transitions (what the run learns from)."""
    digest = hashlib.sha256()
    for key in ("observations", "actions", "rewards", "dones"):
        digest.update(np.ascontiguousarray(transitions[key], dtype=np.float32).tobytes())
    return digest.hexdigest()[:16]


def _resumed_model(
    algorithm: str, task: str, out: pathlib.Path, state: dict[str, Any], device: str
) -> tuple[SAC, dict[str, Any]]:
    """The off-policy baseline as its checkpoint left it, on a new monitored env that appends to the Monitor file, and
    the run's summary so far (the setup's record, and the episodes at which it was resumed)."""
    keep_episodes(out, int(state["episodes"]))
    env = _monitored_env(algorithm, task, out, append=True, horizon=state["summary"].get("horizon"))
    model = resume_off_policy(state, env, device=device)
    model.set_random_seed(sub_seed(state["identity"]["seed"], state["episodes"]))  # a resumed run is reproducible
    resumed = [*state["summary"].get("resumed_at_episodes", []), state["episodes"]]
    return model, state["summary"] | {"resumed_at_episodes": resumed}


def _episode_results(algorithm: str, task: str, out: pathlib.Path, window: int, settings: dict[str, Any]) -> dict[str, Any]:
    """Write the run's learning curve; return the summary's entries on the episodes played (from the Monitor file)."""
    curve = write_learning_curve(out / MONITOR_FILE, out, window=window, title=f"{algorithm} on {task}")
    episodes_record = read_monitor(out / MONITOR_FILE)
    returns = episodes_record["return"]
    results: dict[str, Any] = {
        "episodes_played": len(returns),
        "final_mean_reward": float(curve["mean_reward"][-1]),
        "best_mean_reward": float(np.max(curve["mean_reward"])),
        "max_reward": float(returns.max()),
    }
    if algorithm == "ppo":
        results["first_batch"] = _first_batch(episodes_record, settings["n_steps"])
    return results


def _check_arguments(
    algorithm: str,
    episodes: int,
    seed: int,
    demos: Any,
    demo_episodes: int | None,
    generator: Any,
    eval_goals: int,
    checkpoint_every: int | None,
    device: str,
) -> None:
    """Refuse bad arguments before anything is built or simulated."""
    if algorithm not in BASELINES:
        raise ValueError(f"unknown baseline {algorithm!r}; expected one of {BASELINES}")
    if algorithm in LATENT_BASELINES and generator is None:
        raise ValueError(f"{algorithm} needs a generator (generator=...)")
    if algorithm not in LATENT_BASELINES and demos is None:
        raise ValueError(f"{algorithm} needs demonstrations (demos=...)")
    if algorithm not in LATENT_BASELINES and generator is not None:  # it would be recorded, and used for nothing
        raise ValueError(f"{algorithm} acts in action space and takes no generator (generator=..., --generator)")
    check_episodes(episodes)
    check_seed(seed)
    check_positive_int(eval_goals, "eval_goals")
    if checkpoint_every is not None:
        check_positive_int(checkpoint_every, "checkpoint_every")
    check_device(device)
    if demo_episodes is not None:
        check_positive_int(demo_episodes, "demo_episodes")
    for name, path in (("demos", demos), ("generator", generator)):
        if isinstance(path, str | os.PathLike):
            check_input_path(path, name)


def _monitored_env(algorithm: str, task: str, out: pathlib.Path, *, append: bool = False, horizon: int | None = None) -> Any:
    """A feedback baseline's env under the run's Monitor: the goal-conditioned task for SAC + HER, else the task with
    the time feature, or, for a task from outside the package (its ``horizon`` given), the env its demonstrations were
    recorded in (``append``: a resumed run adds to the Monitor file)."""
    if horizon is not None:
        env = outside_env(task, horizon)
    else:
        env = gym.make(get_task(task).goal_env_id) if algorithm == "sac-her" else make_feedback_env(task)
    return monitor_episodes(env, out, append=append)


def _feedback_model(
    algorithm: str,
    task: str,
    transitions: dict[str, np.ndarray],
    steps: int,
    out: pathlib.Path,
    summary: dict[str, Any],
    eval_goals: int,
    bc_kwargs: dict[str, Any] | None,
    common: dict[str, Any],
) -> PPO | SAC:
    """The feedback baseline's model on a monitored env, its demonstrations in place; behaviour cloning's record
    goes to ``summary``."""
    env = _monitored_env(algorithm, task, out)
    if algorithm == "sac-her":
        return sac_her_with_demonstrations(env, goal_episodes(task, transitions), task=task, steps=steps, **common)
    transitions = add_time_feature(transitions, get_task(task).horizon)
    if algorithm != "ppo":
        return sac_with_demonstrations(env, transitions, task=task, steps=steps, prefill=algorithm == "sac", **common)
    model, record = ppo_with_behaviour_cloning(env, transitions, task=task, bc_kwargs=bc_kwargs, **common)
    with atomic_path(out / "bc_policy.zip") as tmp:  # before PPO changes it
        model.save(tmp)
    distances = {}
    for mode in ("deterministic", "sampled"):
        rewards = evaluate_feedback_policy(
            model, task, goals=eval_goals, seed=EVAL_GOAL_SEED, deterministic=mode == "deterministic"
        )["rewards"]
        distances[f"{mode}_distance"] = float(-rewards.mean())
    best = record["best_epoch"] - 1
    summary["bc"] = {
        "epochs": record["epochs"],
        "best_epoch": record["best_epoch"],
        "train_loss": record["train_loss"][best],
        "heldout_loss": record["heldout_loss"][best],
        "train_episodes": record["train_episodes"],
        "heldout_episodes": record["heldout_episodes"],
        "residual_std": record["residual_std"],
        "action_std": record["action_std"],
        "eval_goals": eval_goals,
        "eval_goal_seed": EVAL_GOAL_SEED,
        **distances,
    }
    return model


def _first_batch(episodes: dict[str, np.ndarray], n_steps: int) -> dict[str, Any]:
    """What PPO's first rollout (sampled from the cloned policy, before any PPO update) and first 64 episodes scored.

    :param episodes: the run's Monitor columns (one env: the timesteps at each episode's end are the lengths' sum)
    """
    returns = episodes["return"]
    first = returns[: int(np.sum(np.cumsum(episodes["length"]) <= n_steps))]
    return {
        "episodes": len(first),
        "mean_distance": float(-first.mean()) if len(first) else None,
        "first_64_mean_distance": float(-returns[:64].mean()),
    }


def _demonstrations(demos: Any, demo_episodes: int | None, task: str) -> dict[str, np.ndarray]:
    if isinstance(demos, dict):
        transitions = demos
    else:
        transitions = load_transitions(demos, task=task)  # refuses another task's demonstrations
    return _first_episodes(transitions, demo_episodes)


def _first_episodes(transitions: dict[str, np.ndarray], demo_episodes: int | None) -> dict[str, np.ndarray]:
    """The transitions of the first ``demo_episodes`` demonstrations (None: all)."""
    if demo_episodes is None:
        return transitions
    ends = np.flatnonzero(np.asarray(transitions["dones"]))
    if demo_episodes < 1 or demo_episodes > len(ends):
        raise ValueError(f"demo_episodes must be between 1 and {len(ends)}, got {demo_episodes}")
    n = ends[demo_episodes - 1] + 1
    return {key: np.asarray(value)[:n] for key, value in transitions.items()}


def _latent_model(
    algorithm: str,
    task: str,
    generator: Any,
    summary: dict[str, Any],
    common: dict,
    out: pathlib.Path,
    n_threads: int | None,
) -> Any:
    """A latent-space baseline on the task's :class:`~sb3_genrl.LatentActionWrapper` (``summary["n_envs"]`` of them
    played together, :func:`sb3_genrl.run.training_env`), under the run's Monitor."""
    env = LatentActionWrapper(gym.make(get_task(task).env_id), generator)
    venv = training_env(env, summary["n_envs"], out, n_threads=n_threads)
    policy = zoo_hyperparams(algorithm, task)["policy"]
    return algorithm_class(algorithm)(policy, venv, **summary["settings"], **common)


LATENT_SAC_ENVS = 16  # latent-sac's episodes played together on a fast path, each followed by one gradient step


def default_latent_envs(algorithm: str, settings: dict[str, Any], fast_path: bool) -> int:
    """The envs a latent-space baseline plays at a time when none is asked for, a fixed choice of the task and its
    settings, never of the machine: where the task has a fast path, an update's episodes together (PPO's and TRPO's
    ``n_steps``, the episodes between updates; :data:`LATENT_SAC_ENVS` for SAC), else 1."""
    if not fast_path:
        return 1
    return LATENT_SAC_ENVS if algorithm == "latent-sac" else int(settings.get("n_steps", 2048))


def latent_vector_settings(algorithm: str, settings: dict[str, Any], n_envs: int) -> dict[str, Any]:
    """A latent-space baseline's settings for ``n_envs`` envs played at a time, so that an update sees as many
    episodes as with one: PPO's and TRPO's ``n_steps`` per env (``n_steps / n_envs``, which must divide), SAC's
    ``gradient_steps=-1`` (one gradient step per episode played, unless the settings name theirs)."""
    if n_envs == 1:
        return settings
    if algorithm == "latent-sac":
        return {"gradient_steps": -1} | settings
    batch = int(settings.get("n_steps", 2048))
    if batch % n_envs:
        raise ValueError(f"n_envs ({n_envs}) must divide {algorithm}'s n_steps ({batch}), the episodes of one update")
    return settings | {"n_steps": batch // n_envs}


def _latent_record(algorithm: str, task: str, changes: dict[str, Any], n_envs: int | None) -> dict[str, Any]:
    """A latent-space baseline's ``settings`` (its constructor's, for ``n_envs`` envs) and ``n_envs`` (the default's
    where ``None``)."""
    settings = baseline_settings(algorithm, task)[0] | changes
    if n_envs is None:
        n_envs = default_latent_envs(algorithm, settings, env_id_has_fast_path(get_task(task).env_id))
    return {"settings": latent_vector_settings(algorithm, settings, n_envs), "n_envs": n_envs}


def _check_envs(algorithm: str, n_envs: int | None, n_threads: int | None) -> None:
    """Refuse ``n_envs`` or ``n_threads`` that are not positive integers, or given to a feedback baseline."""
    for name, value in (("n_envs", n_envs), ("n_threads", n_threads)):
        if value is None:
            continue
        check_positive_int(value, name)
        if algorithm not in LATENT_BASELINES:
            raise ValueError(f"{name} is for the latent-space baselines ({', '.join(LATENT_BASELINES)}), not {algorithm}")
