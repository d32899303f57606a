"""The quickstart: demonstrations -> a beta-VAE -> its evaluation -> a GenRL policy -> a short report with plots.

Every task makes its demonstrations through the one entry of every task
(:func:`sb3_genrl.envs.demonstrations.task_demonstrations`): its own maker where it has one (the package's tasks,
through their :class:`~sb3_genrl.envs.spec.TaskSpec`), else its expert's recorded episodes (``metaworld/<name>``, a
Gymnasium id, ``module:Id``; see :mod:`sb3_genrl.envs.external`). A task with a TaskSpec takes its entry in
``hyperparams/genrl.yml`` and is scored on held-out goals (or its own ``evaluate``); any other is scored on the held-out
seeded resets of :func:`~sb3_genrl.envs.external.evaluate_success`. The stages, their records and the resume are the
same for all.
"""

from __future__ import annotations

import copy
import json
import math
import os
import pathlib
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import torch

import sb3_genrl
from sb3_genrl.checks import (
    MAX_EPISODES,
    check_device,
    check_episodes,
    check_int,
    check_not_in_a_dataset,
    check_output_dir,
    check_positive_int,
    check_seed,
    sub_seed,
)
from sb3_genrl.data import dataset_info
from sb3_genrl.data.fingerprints import dataset_fingerprint, file_fingerprint
from sb3_genrl.envs import get_task
from sb3_genrl.envs.demonstrations import (
    DEFAULT_NOISE,
    describe_horizon,
    expert_horizon,
    expert_name,
    own_maker,
    task_demonstrations,
)
from sb3_genrl.envs.external import HELD_OUT_RESETS, Task, evaluate_success, resolve_task, task_horizon
from sb3_genrl.generative import load, train_generator
from sb3_genrl.genrl import GenRL
from sb3_genrl.genrl.demonstrations import DEMONSTRATION_CALLBACK, uses_demonstrations
from sb3_genrl.hyperparams import EVAL_GOAL_SEED, known_env_ids, load_genrl_settings
from sb3_genrl.metrics import MEASURES, evaluate_generators
from sb3_genrl.provenance import provenance
from sb3_genrl.run import evaluate_on_goals, train_policy
from sb3_genrl.run.folder import RUN_RECORD
from sb3_genrl.run.stages import check_and_record, read_settings, refuse_conflicts, settings_conflicts
from sb3_genrl.run.train import effective_genrl_settings
from sb3_genrl.showcase import check_rendering
from sb3_genrl.utils import atomic_write_json, atomic_write_text, folder_lock
from sb3_genrl.video import record_video
from sb3_genrl.wrappers import default_context, task_has_fast_path

# Paper table 1's VAE1 (N_alpha = 2, beta = 0.01). Of the 2-D VAEs, its stronger prior term lays the hockey
# demonstrations out as one unfolded sheet (shot distance along one latent axis, direction along the other); with
# beta = 0.001 (VAE3) the sheet often folds over itself, and GenRL's Gaussian policy then stalls at the fold.
QUICKSTART_PRESET = "VAE1"
# A task without an entry in hyperparams/genrl.yml: the paper's 3000 episodes, GenRL's default 64 per iteration.
DEFAULT_POLICY_EPISODES, DEFAULT_BATCH_EPISODES = 3000, 64
# A task from outside the package starts from its demonstrations: the policy's mean fitted to their latent codes by
# DemonstrationCallback (4000 Adam steps), then GenRL's defaults but the spread, fixed at 0.37 prior standard deviations
# around that mean (GenRL's own 1.0 draws too far from the fit to find anything), and the mean refitted from its
# initial weights to the pulls that solved their own reset, at episode 512 and every 256 after (no relabelling: the
# env need only report its success), and each E-step's KL bound scaled by its batch's failed share, at least a tenth
# (success_kl_floor: a batch that mostly succeeds moves the mean less). On push-back-v3's tuning resets the refits take
# the policy from 0.51 to 0.63 (3 seeds); the floor takes pick-place-v3 from 0.970 to 0.980, reach-v3 from 0.907 to
# 0.923, peg-insert-side-v3 from 0.680 to 0.740, push-back-v3 from 0.670 to 0.710 (3 seeds each), shelf-place-v3 from
# 0.38 to 0.50 (one seed); docs/guide/your_task.md, "3. The policy", and docs/guide/search.md.
OUTSIDE_TASK_KWARGS: dict[str, Any] = {
    "callback": [{DEMONSTRATION_CALLBACK: {"fit_steps": 4000, "keep": False}}],
    "policy_kwargs": {"log_std_init": -1.0},
    "max_log_std_change": 0.0,
    "hindsight_kwargs": {"history": 0, "refit_every": 256, "refit_start": 512},
    "success_kl_floor": 0.1,
}
# The generator stage's defaults (also the generator of the rl-zoo3 runs, sb3_genrl.zoo.generators); a task's
# TaskSpec.quickstart_demo_episodes sets its quickstart's own demonstration count (hockey's: 2000)
DEMO_EPISODES, GENERATOR_EPOCHS, GENERATOR_EVAL_EVERY = 4000, 300, 10
# The quickstart plays at most this many GenRL episodes (basketball's budget is 20000, `genrl train-policy`'s and the
# benchmark's), so that basketball's takes 6 minutes on two idle cores. On 200 tuning goals, seeds 0 and 1, its policy
# comes within 4.5 and 4.7 cm after 10000 episodes, 4.0 and 4.2 after 12000, 4.2 and 4.7 after 20000 (docs/results.md,
# "The quickstart"); 12000 would take about 6 minutes.
QUICKSTART_MAX_EPISODES = 10000
# A task from outside the package records its demonstrations through its env's step path, closed loop and replayed
# open loop (a Meta-World push-v3 episode of 89 steps: about 0.1 s of CPU each), so it records fewer by default. On
# push-v3, 1000 against 500 lift the fitted start from 0.76 to 0.91 and the search from 0.94 to 0.96 (tuning resets),
# for about 110 s more of recording (docs/guide/your_task.md).
OUTSIDE_DEMO_EPISODES = 1000
# ... and at most this many demonstration steps, and GenRL at most this many episodes' steps of the horizon: 1000
# demonstrations up to a horizon of 300 steps and 3000 episodes up to 333, fewer above (Meta-World's push-back-v3, 500
# steps: 600 and 2048; shelf-place-v3, 258 steps and the costliest step of the long tasks: 1000 and 3008). On 100
# tuning resets (seed 0), with half these budgets push-back's quickstart solved 0.63 and shelf-place's 0.27, with twice
# the demonstrations 0.70 and 0.36, with these budgets 0.72 and 0.50, in 10 min 44 s and 9 min 34 s on two idle cores
# instead of 6.5 minutes. A task whose every GenRL episode fails plays the whole budget (docs/guide/your_task.md, "The
# quickstart").
OUTSIDE_DEMO_STEPS = 300_000
OUTSIDE_POLICY_STEPS = 1_000_000
# GenRL's envs played at a time by a task without the fast path (one process each; Fetch, Meta-World, a task of
# yours). A task with it (the arm tasks) plays an iteration's episodes in one threaded simulation call, as
# `genrl train-policy` does by default (sb3_genrl.vec_env). Fixed, not the machine's core count: the result depends on it.
QUICKSTART_ENVS = 2
# Precision and recall with k = 3 neighbours need more than 3 samples in each set: the demonstrations, at least 4
MIN_DEMO_EPISODES = 4
# The quickstart's video: a frame every other control step (25 Hz), shown at 10 frames a second (0.8 of real time)
VIDEO = {"goals": 4, "width": 320, "height": 240, "fps": 10, "every": 2}
# An outside task's generator trains for at least 4800 minibatch steps (about the Fetch tasks' 300 epochs of 4000
# demonstrations; 300 epochs of Meta-World push-back-v3's 300 demonstrations are 600), in minibatches of nearly equal
# sizes (not 256 and a remainder of 14), and keeps the checkpoint whose reconstructions of the held-out demonstrations
# are closest (GenRL's fit starts from the demonstrations' posterior means; the paper's selection kept epoch 10-20).
# On push-back-v3 the reconstructions of new demonstrations, replayed open loop, then succeed on 0.605 instead of 0.00
# (docs/guide/your_task.md, "2. A generator").
OUTSIDE_GENERATOR_TRAINING: dict[str, Any] = {"selection": "reconstruction", "min_steps": 4800, "even_batches": True}
# An outside task's horizon, as the expert's success settles (expert_horizon), kept for a rerun
HORIZON_FILE = "horizon.json"


def quickstart(
    out_dir: str | os.PathLike,
    *,
    task: str,
    demo_episodes: int | None = None,
    epochs: int | None = None,
    policy_episodes: int | None = None,
    pr_samples: int = 1000,
    dwpr_samples: int = 500,
    seed: int = 0,
    video: bool = True,
    device: str = "auto",
    progress_bar: bool = True,
    log: Callable[[str], None] | None = None,
    expert: Callable[[Any], Any] | None = None,
    horizon: int | None = None,
) -> pathlib.Path:
    """Run the whole GenRL workflow at a small size and write ``report.md`` in ``out_dir``.

    Each stage is skipped when its output exists, so a rerun resumes. Each stage also records the settings that
    made it (``vae.stage.json``, ``evaluation/stage.json``, ``policy/stage.json``, ``video.stage.json``; the
    dataset's own metadata) and the fingerprint of its input, and a rerun with other settings raises
    :class:`~sb3_genrl.run.stages.SettingsConflictError` before any work; one process at a time may work in
    ``out_dir`` (:class:`~sb3_genrl.utils.FolderInUseError`). The README gives the stages' times of the committed
    reports.

    A task from outside the package (``metaworld/<name>``, a Gymnasium id or ``module:Id`` with an ``expert``) records
    its demonstrations from the expert (:func:`~sb3_genrl.envs.demonstrations.record_demonstrations`, with ``horizon``), takes
    GenRL's defaults (or its entry in ``hyperparams/genrl.yml``), and its report and ``summary.json`` give the saved
    policy's success on :data:`~sb3_genrl.envs.external.HELD_OUT_RESETS` held-out seeded resets
    (:func:`~sb3_genrl.envs.external.evaluate_success`: reset seeds from ``2**31`` on, which nothing else uses).

    :param out_dir: output folder (a rerun resumes it)
    :param task: a task name from :data:`sb3_genrl.envs.TASKS`, or a task from outside the package
        (:func:`~sb3_genrl.envs.external.resolve_task`)
    :param demo_episodes: demonstrations to generate (None: :func:`quickstart_demo_episodes`; a task from outside the
        package: :func:`outside_demo_episodes` of its horizon, 1000 up to 300 steps)
    :param epochs: generator training epochs (None: :data:`GENERATOR_EPOCHS`, and for a task from outside the package
        at least the minibatch steps of :data:`OUTSIDE_GENERATOR_TRAINING`, its epochs raised on a small dataset;
        given: exactly these epochs)
    :param policy_episodes: GenRL episodes (None: the task's, at most :data:`QUICKSTART_MAX_EPISODES`); GenRL takes
        the task's settings and episodes per iteration too (its entry in ``hyperparams/genrl.yml``, see
        :func:`task_settings`)
    :param pr_samples: samples per set for precision and recall
    :param dwpr_samples: samples per intervention for DwPR
    :param seed: seed of the demonstrations, the generator, the evaluation and the policy (the video's:
        :func:`~sb3_genrl.checks.sub_seed` of it)
    :param video: also render the trained policy (a GIF and a strip of frames)
    :param device: torch device
    :param progress_bar: show the stages' progress bars
    :param log: called with a line after each stage
    :param expert: a task from outside the package: its expert, observation -> action (None: the task's own, such as
        Meta-World's scripted policies); a task of the package's takes none
    :param horizon: a task from outside the package: the control steps of a demonstration and of GenRL's episodes
        (None: the task's, :attr:`~sb3_genrl.envs.external.Task.horizon`, where it has one; else the shortest
        at which the expert's success settles, :func:`~sb3_genrl.envs.demonstrations.expert_horizon`, written to
        ``horizon.json``)
    :return: the report's path
    """
    outside = _outside_task(task, expert, horizon)
    if outside is None:
        episodes, batch_episodes, genrl_kwargs = task_settings(task)
        video = video and get_task(task).video  # a task without the arm tasks' renderer is not filmed
    else:
        _check_box_context(outside)
        if expert is None and outside.make_expert is not None and own_maker(outside) is None:
            expert = outside.make_expert()
        horizon, horizon_record = _outside_horizon(outside, horizon, expert, pathlib.Path(out_dir), seed, log)
        episodes, batch_episodes, genrl_kwargs = outside_task_settings(outside, horizon)
        video = False  # the video renders the package's arm tasks
    policy_episodes = min(episodes, QUICKSTART_MAX_EPISODES) if policy_episodes is None else policy_episodes
    if demo_episodes is None:
        demo_episodes = quickstart_demo_episodes(task) if outside is None else outside_demo_episodes(horizon)
    min_steps = OUTSIDE_GENERATOR_TRAINING["min_steps"] if epochs is None else 0  # epochs given: exactly those
    epochs = GENERATOR_EPOCHS if epochs is None else epochs
    _check_counts(
        demo_episodes=demo_episodes,
        epochs=epochs,
        policy_episodes=policy_episodes,
        pr_samples=pr_samples,
        dwpr_samples=dwpr_samples,
    )
    n_envs = quickstart_envs(task if outside is None else None, batch_episodes)
    if batch_episodes % n_envs:
        raise ValueError(
            f"task {task!r}: the quickstart plays its GenRL episodes in {n_envs} envs at a time, "
            f"so the task's batch_episodes ({batch_episodes}) must be a multiple of {n_envs}"
        )
    check_seed(seed)
    check_device(device)
    out = check_output_dir(out_dir)
    check_not_in_a_dataset(out)
    if (out / RUN_RECORD).is_file():  # its summary.json would be replaced by the quickstart's
        raise ValueError(
            f"out: {str(out_dir)!r} holds a training run ({RUN_RECORD}, written by genrl train-policy or genrl "
            "baseline); the quickstart writes into a folder of its own: choose another --out"
        )
    if video and not _done(out, "video"):  # a display missing fails at the first frame, after every other stage
        check_rendering("genrl quickstart --no-video, quickstart(video=False)")
    # The models are small: one torch thread is as fast as several and leaves the other cores to MuJoCo.
    torch.set_num_threads(1)
    settings = _stage_settings(
        task,
        demo_episodes,
        epochs,
        policy_episodes,
        batch_episodes,
        n_envs,
        genrl_kwargs,
        pr_samples,
        dwpr_samples,
        seed,
        video,
    )
    if outside is not None:
        _add_outside_settings(settings, outside, expert, horizon, min_steps)
    else:  # what the task's demonstrations depend on besides seed and number, as their dataset records it
        settings["demonstrations"] |= get_task(task).demonstration_recipe
    with folder_lock(out):
        refuse_conflicts(
            out,
            [
                line
                for name, wanted in settings.items()
                for line in settings_conflicts(*_recorded(out, name), wanted, output_exists=_done(out, name))
            ],
        )
        if outside is not None and horizon_record is not None:
            atomic_write_json(out / HORIZON_FILE, horizon_record)
        log = log or (lambda _line: None)
        timings = _run_stages(out, settings, device, progress_bar, log, expert)
        return _write_report(out, task, seed, video, timings, log, horizon if outside is not None else None)


def quickstart_envs(task: str | None, batch_episodes: int) -> int:
    """The envs the quickstart's GenRL stage plays at a time: an iteration's ``batch_episodes`` for a task of the
    package's with the fast path (one threaded call on all cores, as :func:`~sb3_genrl.run.train.default_n_envs`),
    else :data:`QUICKSTART_ENVS` env processes (``task`` None: a task from outside the package)."""
    return batch_episodes if task is not None and task_has_fast_path(get_task(task).env_class) else QUICKSTART_ENVS


def quickstart_demo_episodes(task: str) -> int:
    """The demonstrations ``genrl quickstart`` makes for ``task``, a task of the package's: its
    ``TaskSpec.quickstart_demo_episodes``, else :data:`DEMO_EPISODES`."""
    return get_task(task).quickstart_demo_episodes or DEMO_EPISODES


def outside_demo_episodes(horizon: int) -> int:
    """The demonstrations ``genrl quickstart`` records for a task from outside the package with episodes of
    ``horizon`` steps: :data:`OUTSIDE_DEMO_EPISODES`, or fewer where they would pass :data:`OUTSIDE_DEMO_STEPS` steps
    (at least :data:`MIN_DEMO_EPISODES`)."""
    return _within_steps(OUTSIDE_DEMO_EPISODES, OUTSIDE_DEMO_STEPS, horizon, MIN_DEMO_EPISODES)


def _within_steps(episodes: int, steps: int, horizon: int, fewest: int) -> int:
    """``episodes``, or as many episodes of ``horizon`` steps as ``steps`` hold where that is fewer (at least
    ``fewest``)."""
    return max(fewest, min(episodes, steps // int(horizon)))


def _outside_task(task: str, expert: Callable[[Any], Any] | None, horizon: int | None) -> Task | None:
    """The resolved task when it has no :class:`~sb3_genrl.envs.spec.TaskSpec` (None for one that has: the package's
    own, whose entry, goal region and score the quickstart uses), with its expert and horizon checked before any
    work."""
    resolved = resolve_task(task)
    if resolved.spec is not None:
        given = [name for name, value in dict(expert=expert, horizon=horizon).items() if value is not None]
        if given:
            raise ValueError(
                f"{' and '.join(given)} {'applies' if len(given) == 1 else 'apply'} to a task from outside the package; "
                f"{task!r} is one of the package's, which makes its own demonstrations"
            )
        return None
    if expert is None and resolved.make_expert is None:
        if own_maker(resolved) is None:
            raise ValueError(f"task {task!r} is not one of the package's: give its expert (expert=, --expert MODULE:FUNCTION)")
        if horizon is None and resolved.horizon is None:
            raise ValueError(f"task {task!r} makes its own demonstrations and has no expert to find a horizon: give horizon=")
    if expert is not None and not callable(expert):
        raise ValueError(f"expert must be a callable observation -> action, got {type(expert).__name__}")
    return resolved


def _check_box_context(task: Task) -> None:
    """Refuse, before any stage, a task whose GenRL context is not a Box: the quickstart starts GenRL from the
    demonstrations (``DemonstrationCallback``), whose contexts are flat first observations."""
    env = gym.make(task.env_id)
    try:
        _, space = default_context(env)
    finally:
        env.close()
    if not isinstance(space, gym.spaces.Box):
        raise ValueError(
            f"task {task.name!r}: the quickstart starts GenRL from demonstrations, which needs a Box context (a flat "
            f"observation, or a goal-conditioned env's goal), but its observation space is {space}; give the env a Box "
            "observation (e.g. gymnasium.wrappers.FlattenObservation), or train GenRL on it through the API"
        )


def _outside_horizon(
    task: Task,
    horizon: int | None,
    expert: Callable[[Any], Any],
    out: pathlib.Path,
    seed: int,
    log: Callable[[str], None] | None,
) -> tuple[int, dict[str, Any] | None]:
    """The control steps of an outside task's demonstrations: ``horizon``, else the task's, else the shortest at which
    the expert's success settles (:func:`~sb3_genrl.envs.demonstrations.expert_horizon` from the quickstart's seed,
    read from ``out/horizon.json`` on a rerun with the same expert and seed); a given horizon is checked against the
    env (:func:`~sb3_genrl.envs.external.task_horizon`).

    :return: the horizon, and the record to write to ``horizon.json`` once the folder is the run's (None: nothing new)
    """
    if horizon is not None or task.horizon is not None:
        env = gym.make(task.env_id)
        try:
            return task_horizon(env, horizon if horizon is not None else task.horizon, task.name), None
        finally:
            env.close()
    made_with = {"task": task.name, "expert": expert_name(expert), "seed": seed}
    path = out / HORIZON_FILE
    recorded = json.loads(path.read_text()) if path.is_file() else None
    if recorded is not None and {key: recorded.get(key) for key in made_with} == made_with:
        return int(recorded["horizon"]), None
    began = time.perf_counter()
    found = expert_horizon(task.name, expert, seed=seed)
    seconds = time.perf_counter() - began
    if log is not None:
        log(f"horizon: {found['horizon']} steps, {describe_horizon(found)} ({seconds:.0f} s)")
    record = made_with | {key: value for key, value in found.items() if key != "seed"} | {"seconds": seconds}
    return int(found["horizon"]), record


def outside_task_settings(task: Task, horizon: int | None = None) -> tuple[int, int, dict[str, Any]]:
    """The GenRL settings of a task from outside the package, as :func:`task_settings` gives a registered task's: its
    env id's entry in ``hyperparams/genrl.yml`` if it has one, else :data:`OUTSIDE_TASK_KWARGS` (started from the
    demonstrations, a fixed spread, refits to the solving pulls, else GenRL's defaults) with
    :data:`DEFAULT_POLICY_EPISODES` (fewer where episodes of ``horizon`` steps would pass :data:`OUTSIDE_POLICY_STEPS`)
    and :data:`DEFAULT_BATCH_EPISODES`.

    :param task: the resolved task (:func:`~sb3_genrl.envs.external.resolve_task`)
    :param horizon: the control steps of an episode (None: the episodes are not capped)
    :return: ``(episodes, batch_episodes, genrl_kwargs)``
    """
    if task.env_id not in known_env_ids("genrl"):
        episodes = DEFAULT_POLICY_EPISODES
        if horizon is not None:
            episodes = _within_steps(episodes, OUTSIDE_POLICY_STEPS, horizon, DEFAULT_BATCH_EPISODES)
        return episodes, DEFAULT_BATCH_EPISODES, copy.deepcopy(OUTSIDE_TASK_KWARGS)
    return load_genrl_settings(task.env_id)


def _add_outside_settings(
    settings: dict[str, dict[str, Any]], task: Task, expert: Callable[[Any], Any], horizon: int | None, min_steps: int
) -> None:
    """What the stages of a task from outside the package are made with besides a registered task's: the recorder's
    settings (compared with the dataset's metadata on a rerun; none for a task's own maker), the generator's training
    (:data:`OUTSIDE_GENERATOR_TRAINING`'s selection, ``min_steps`` its steps unless the epochs were given), the env id
    and horizon of the policy."""
    if expert is not None:
        settings["demonstrations"] |= {"horizon": horizon, "expert": expert_name(expert), "noise": DEFAULT_NOISE}
    settings["generator"] |= {**OUTSIDE_GENERATOR_TRAINING, "min_steps": min_steps}
    settings["policy"] |= {"env_id": task.env_id, "horizon": horizon}


def _check_counts(*, demo_episodes: int, epochs: int, policy_episodes: int, pr_samples: int, dwpr_samples: int) -> None:
    """Refuse counts the stages cannot run with, before the demonstrations are made."""
    for name, value in dict(epochs=epochs, dwpr_samples=dwpr_samples).items():
        check_positive_int(value, name)
    check_episodes(policy_episodes, "policy_episodes")
    for name, value in dict(demo_episodes=demo_episodes, pr_samples=pr_samples).items():
        check_int(value, name, minimum=MIN_DEMO_EPISODES, maximum=MAX_EPISODES)


def _stage_settings(
    task: str,
    demo_episodes: int,
    epochs: int,
    policy_episodes: int,
    batch_episodes: int,
    n_envs: int,
    genrl_kwargs: dict[str, Any],
    pr_samples: int,
    dwpr_samples: int,
    seed: int,
    video: bool,
) -> dict[str, dict[str, Any]]:
    """What each stage is made with: recorded beside its output, and compared with the record on a rerun."""
    return {
        "demonstrations": {"task": task, "episodes": demo_episodes, "seed": seed, "version": sb3_genrl.__version__},
        "generator": {"preset": quickstart_preset(task), "epochs": epochs, "eval_every": GENERATOR_EVAL_EVERY, "seed": seed},
        # precision/recall compares at most as many samples as there are demonstrations
        "evaluation": {"n": min(pr_samples, demo_episodes), "dwpr_n": dwpr_samples, "k": 3, "interventions": 5, "seed": seed},
        "policy": {
            "task": task,
            "episodes": policy_episodes,
            "batch_episodes": batch_episodes,
            "n_envs": n_envs,
            "seed": seed,
            "genrl_kwargs": genrl_kwargs,
            # every GenRL setting in effect, defaults included, as train_policy runs them
            "genrl": effective_genrl_settings(genrl_kwargs, batch_episodes, n_envs),
        },
        **({"video": {**VIDEO, "seed": sub_seed(seed, 1)}} if video else {}),
    }


# Where each stage writes (checked for "done") and where it records its settings.
_OUTPUTS = {
    "demonstrations": ("demonstrations",),
    "generator": ("vae.pt",),
    "evaluation": ("evaluation/results.json",),
    "policy": ("policy/summary.json",),
    "video": ("policy.gif", "policy_strip.png"),
}  # a stage is done when all exist
SUMMARY = "summary.json"  # the run's score on held-out goals or resets, as numbers
STAGE_TIMES = "stage_times.json"  # seconds each stage took when it was made, kept for the report of a resumed run
_RECORDS = {
    "generator": "vae.stage.json",
    "evaluation": "evaluation/stage.json",
    "policy": "policy/stage.json",
    "video": "video.stage.json",
}


def _read_stage_times(out: pathlib.Path) -> dict[str, float]:
    """The seconds each stage took when it was made (``stage_times.json``; empty for a new folder)."""
    path = out / STAGE_TIMES
    return {key: float(value) for key, value in json.loads(path.read_text()).items()} if path.is_file() else {}


def _done(out: pathlib.Path, stage: str) -> bool:
    """Whether every file the stage writes exists (a stage killed between two of them is not done)."""
    if stage == "demonstrations":
        path = out / _OUTPUTS[stage][0]
        return path.is_dir() and any(path.iterdir())
    return all((out / name).exists() for name in _OUTPUTS[stage])


def _recorded(out: pathlib.Path, stage: str) -> tuple[pathlib.Path, dict[str, Any] | None]:
    """Where a stage's settings are recorded, and what is recorded (None: nothing)."""
    if stage == "demonstrations":
        dataset = out / "demonstrations"
        return dataset, dataset_info(dataset) if _done(out, stage) else None
    return out / _RECORDS[stage], read_settings(out / _RECORDS[stage])


def _run_stages(
    out: pathlib.Path,
    settings: dict[str, dict[str, Any]],
    device: str,
    progress_bar: bool,
    log: Callable[[str], None],
    expert: Callable[[Any], Any] | None = None,
) -> dict[str, float]:
    dataset, model_path, policy = out / "demonstrations", out / "vae.pt", out / "policy"
    demos, generator, evaluation, policy_stage = (
        settings[name] for name in ("demonstrations", "generator", "evaluation", "policy")
    )
    timings: dict[str, float] = {}

    made_in = _read_stage_times(out)

    def stage(name: str, made_from: dict[str, str], work: Callable[[], Any]) -> None:
        start = time.perf_counter()
        done = _done(out, name)
        if name != "demonstrations":
            check_and_record(out / _RECORDS[name], {**settings[name], **made_from}, output_exists=done, folder=out)
        if not done:
            work()
            made_in[name] = time.perf_counter() - start
            atomic_write_json(out / STAGE_TIMES, made_in)
        timings[name] = made_in.get(name, math.nan)  # a stage already there: the time it took when it was made
        log(f"{name}: {'done' if not done else 'already there'} ({time.perf_counter() - start:.0f} s)")

    def train() -> None:  # the file is written atomically: it exists only once training is complete
        train_generator(
            dataset,
            preset=generator["preset"],
            epochs=generator["epochs"],
            eval_every=generator["eval_every"],
            selection=generator.get("selection", "prior"),  # the package's own tasks: the paper's
            min_steps=generator.get("min_steps", 0),
            even_batches=generator.get("even_batches", False),
            seed=generator["seed"],
            out=model_path,
            progress_bar=progress_bar,
            device=device,
            tensorboard_log=str(out / "tensorboard"),
        )

    def demonstrate() -> None:  # the one entry of every task: its own maker, or its expert's recorded episodes
        recorded = expert is not None
        task_demonstrations(
            demos["task"],
            demos["episodes"],
            dataset,
            expert=expert,
            seed=demos["seed"],
            noise=demos["noise"] if recorded else None,
            horizon=demos["horizon"] if recorded else None,
            progress_bar=progress_bar,
        )

    stage("demonstrations", {}, demonstrate)
    stage("generator", {"dataset": dataset_fingerprint(dataset)}, train)
    made_from = {"dataset": dataset_fingerprint(dataset), "generator": file_fingerprint(model_path)}
    stage(
        "evaluation",
        made_from,
        lambda: evaluate_generators(
            {generator["preset"]: model_path},
            dataset,
            n=evaluation["n"],
            k=evaluation["k"],
            dwpr_n=evaluation["dwpr_n"],
            interventions=evaluation["interventions"],
            seed=evaluation["seed"],
            out_dir=out / "evaluation",
            device=device,
        ),
    )
    policy_made_from, demonstrations = {"generator": made_from["generator"]}, None
    if uses_demonstrations(policy_stage["genrl_kwargs"].get("callback")):  # (the Fetch tasks') the generator's own
        policy_made_from["dataset"], demonstrations = made_from["dataset"], dataset
    stage(
        "policy",
        policy_made_from,
        lambda: train_policy(
            policy_stage.get("env_id", policy_stage["task"]),  # a task from outside the package: its Gymnasium id
            str(model_path),
            episodes=policy_stage["episodes"],
            batch_episodes=policy_stage["batch_episodes"],
            n_envs=policy_stage["n_envs"],
            seed=policy_stage["seed"],
            out_dir=policy,
            device=device,
            demonstrations=demonstrations,
            progress_bar=progress_bar,
            horizon=policy_stage.get("horizon"),
            **policy_stage["genrl_kwargs"],
        ),
    )
    if "video" in settings:
        shown = settings["video"]
        stage(
            "video",
            {"policy": file_fingerprint(policy / "genrl_policy.zip")},
            lambda: record_video(
                policy_stage["task"],
                out / "policy.gif",
                policy=policy,
                goals=shown["goals"],
                seed=shown["seed"],
                width=shown["width"],
                height=shown["height"],
                fps=shown["fps"],
                every=shown["every"],
            ),
        )
    return timings


def _training_line(generator: Any, settings: dict[str, Any]) -> str:
    """How the generator stage trained: its epochs and the checkpoint it kept, by which selection."""
    trained = generator.history[-1]["epoch"] if generator.history else settings["epochs"]
    if settings.get("selection", "prior") == "prior":
        return f"{trained} epochs, best checkpoint at epoch {generator.best_epoch}"
    parts = [f"at least {settings['min_steps']} minibatch steps"] if settings.get("min_steps") else []
    parts += ["minibatches of nearly equal sizes"] if settings.get("even_batches") else []
    how = f" ({', '.join(parts)})" if parts else ""
    return (
        f"{trained} epochs{how}, keeping the checkpoint whose reconstructions of the held-out demonstrations are "
        f"closest, epoch {generator.best_epoch}"
    )


def _write_report(
    out: pathlib.Path,
    task: str,
    seed: int,
    video: bool,
    timings: dict[str, float],
    log: Callable[[str], None],
    horizon: int | None = None,
) -> pathlib.Path:
    """``report.md`` and ``summary.json`` (the held-out score as a number), with every number read from what the
    stages recorded (``horizon``: a task from outside the package, played for that many steps)."""
    dataset = out / "demonstrations"
    found = json.loads((out / HORIZON_FILE).read_text()) if horizon is not None and (out / HORIZON_FILE).is_file() else None
    if found is not None:  # an outside task's horizon, found from its expert before the demonstrations
        timings = {"horizon": found["seconds"], **timings}
    summary = json.loads((out / "policy" / "summary.json").read_text())
    measures = json.loads((out / "evaluation" / "results.json").read_text())
    generator_settings = read_settings(out / _RECORDS["generator"])
    began = time.perf_counter()
    if horizon is None:
        score, score_line, held_out = _policy_score(out, task, seed)
    else:
        score, score_line, held_out = _outside_policy_score(out, task, horizon)
    timings = {**timings, "score": time.perf_counter() - began}  # the saved policy's score, played at each report
    generator = load(out / "vae.pt", device="cpu")
    lines = [
        f"# GenRL quickstart: {task}",
        "",
        _demonstrations_line(dataset)
        + ("" if found is None else f" The horizon, {found['horizon']} steps, is {describe_horizon(found)}."),
        f"2. **Generator**: beta-VAE (preset {generator_settings['preset']}: N_alpha = {generator.latent_dim}, "
        f"beta = {generator.beta}), {_training_line(generator, generator_settings)}.",
        f"3. **Evaluation**: {_measure_line(measures)}.",
        f"4. **GenRL**: {summary['episodes']} episodes; best iteration mean reward {summary['best_mean_reward']:.3f},"
        f" final {summary['final_mean_reward']:.3f}; {score}.",
        "",
        "![learning curve](policy/learning_curve.png)",
        "",
        "![precision and recall](evaluation/precision_recall.png)",
        "",
    ]
    if video:
        lines += ["![policy](policy.gif)", "", "![policy frames](policy_strip.png)", ""]
    lines += [
        "Stage times (s, as each stage took when it was made): "
        + ", ".join(f"{k} {v:.0f}" if math.isfinite(v) else f"{k} not recorded" for k, v in timings.items()),
        "",
    ]
    report = out / "report.md"
    atomic_write_text(report, "\n".join(lines))
    atomic_write_json(
        out / SUMMARY,
        {
            "task": task,
            **held_out,
            "policy": "policy/genrl_policy.zip",
            "policy_episodes": summary["episodes"],
            "stage_seconds": {k: v if math.isfinite(v) else None for k, v in timings.items()},
            "provenance": provenance(),  # the package version and git commit that wrote this summary
        },
    )
    log(f"GenRL on {task}: {score_line}")
    return report


def _demonstrations_line(dataset: pathlib.Path) -> str:
    """The report's line on the demonstrations: a registered task's (with its coverage of the goal region), or an
    outside task's recorder's (kept of tried, and why the others were dropped)."""
    info = dataset_info(dataset)
    if "failed_open_loop" in info:
        return (
            f"1. **Demonstrations**: {info['episodes']} perturbed episodes of the expert `{info['expert']}`, "
            f"{info['horizon']} steps each, kept of {info['tried']} tried ({info['kept_share']:.1%}: "
            f"{info['failed_closed_loop']} failed closed loop, {info['failed_open_loop']} failed when their actions were "
            "replayed open loop from their seeded reset)."
        )
    coverage_file = dataset / "coverage.json"
    coverage = json.loads(coverage_file.read_text()) if coverage_file.is_file() else {}
    return (
        f"1. **Demonstrations**: {info['episodes']} valid episodes from the scripted expert and its perturbations"
        + (f" (goal-region coverage {coverage['coverage']:.1%})" if "coverage" in coverage else "")
        + "."
    )


def _policy_score(out: pathlib.Path, task: str, seed: int) -> tuple[str, str, dict[str, Any]]:
    """The trained policy played deterministically from 100 held-out goals (or initial states): the report's words,
    the log's line and the summary's numbers (the success rate for a task scored by success, else the mean distance
    to the goal)."""
    model = GenRL.load(out / "policy" / "genrl_policy.zip", device="cpu")
    spec = get_task(task)
    if spec.evaluate is not None:
        success = spec.evaluate(model, task, episodes=100, seed=seed + EVAL_GOAL_SEED)["success_rate"]
        return (
            f"the trained policy's own success rate from 100 new initial states (deterministic): **{success:.0%}**",
            f"the deterministic policy's success rate from 100 new initial states is {success:.0%}",
            {
                "held_out_success": success,
                "held_out_resets": 100,
                "held_out_seeds": [seed + EVAL_GOAL_SEED, seed + EVAL_GOAL_SEED + 100],
            },
        )
    _, rewards, _ = evaluate_on_goals(model, task, goals=100, seed=seed + EVAL_GOAL_SEED)
    distance = float(-rewards.mean())
    return (
        f"the trained policy's own mean distance to 100 new goals (deterministic): **{distance:.3f} m** "
        f"({distance * 100:.1f} cm)",
        f"the deterministic policy's mean distance to 100 new goals is {distance:.3f} m",
        {"held_out_mean_distance": distance, "held_out_goals": 100, "held_out_goal_seed": seed + EVAL_GOAL_SEED},
    )


def _outside_policy_score(out: pathlib.Path, task: str, horizon: int) -> tuple[str, str, dict[str, Any]]:
    """An outside task's trained policy played deterministically from the held-out seeded resets of
    :func:`~sb3_genrl.envs.external.evaluate_success`: the report's words, the log's line and the summary's numbers."""
    model = GenRL.load(out / "policy" / "genrl_policy.zip", device="cpu")
    result = evaluate_success(model, task, resets=HELD_OUT_RESETS, horizon=horizon)
    success, (first, end) = result["success_rate"], result["seeds"]
    where = f"{result['resets']} held-out seeded resets (reset seeds {first} to {end - 1}, never used to record or train)"
    return (
        f"the saved policy's success on {where}, deterministic: **{success:.1%}**",
        f"the saved policy's success on {result['resets']} held-out seeded resets is {success:.1%}",
        {"held_out_success": success, "held_out_resets": result["resets"], "held_out_seeds": [first, end]},
    )


def quickstart_preset(task: str) -> str:
    """The generator preset the quickstart trains for ``task``: the task's own (its ``TaskSpec.generator_preset``, a
    latent space as large as its expert's family of motions; a task from outside the package: its
    ``Task.generator_preset``) or :data:`QUICKSTART_PRESET`."""
    return resolve_task(task).generator_preset or QUICKSTART_PRESET


def task_settings(task: str) -> tuple[int, int, dict[str, Any]]:
    """A registered task's GenRL settings: its entry in ``hyperparams/genrl.yml``
    (:func:`sb3_genrl.hyperparams.load_genrl_settings`), used by ``genrl quickstart``, ``genrl train-policy``, the
    study and the GenRL benchmark; a task without an entry (one of a user's own) takes GenRL's defaults.

    :param task: a task name from :data:`sb3_genrl.envs.TASKS` or its Gymnasium id
    :return: ``(episodes, batch_episodes, genrl_kwargs)``: the budget of episodes, the episodes per EM iteration and
        the further GenRL arguments (``policy`` among them, and the entry's ``callback`` where it has one, which
        :func:`~sb3_genrl.run.train_policy` takes: the Fetch tasks' learning from demonstrations)
    """
    env_id = get_task(task).env_id
    if env_id not in known_env_ids("genrl"):
        return DEFAULT_POLICY_EPISODES, DEFAULT_BATCH_EPISODES, {}
    return load_genrl_settings(env_id)


def _measure_line(measures: list[dict[str, Any]]) -> str:
    row = measures[0]
    return ", ".join(f"{key} {row[key]:.3f}" for key in MEASURES if key in row)
