"""Tasks from outside the package: any episodic Gymnasium env, as GenRL and the demonstration recorder play it.

The path a user's own task takes, with nothing added to the package for it (see the guide's "Your own task"):

1. :func:`sb3_genrl.envs.demonstrations.record_demonstrations` plays an expert closed loop from seeded resets of the
   task's env (:func:`make_task_env`) and keeps the episodes whose actions, replayed open loop, still succeed.
2. :func:`sb3_genrl.generative.train_generator` trains a generator on the dataset's actions.
3. ``GenRL(LatentActionWrapper(make_task_env(task), generator))`` trains the policy (or ``genrl train-policy``), and
   :func:`evaluate_success` scores it on held-out seeded resets.

A task is a Gymnasium id (``gymnasium.register``-ed, or ``"module:Id"`` whose module registers it on import), a
callable that makes the env, a task the package registers (:data:`sb3_genrl.envs.TASKS`), or ``metaworld/<name>`` for
one of Meta-World's 50 v3 tasks (:mod:`sb3_genrl.envs.metaworld`; its scripted expert comes with it). Success is read
from the last step's ``info["is_success"]`` (or ``info["success"]``; the key is configurable); the horizon is the env's
``max_episode_steps`` unless a ``horizon`` is given.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import TimeLimit
from sb3_genrl.envs import metaworld
from sb3_genrl.envs.registry import TASKS
from sb3_genrl.envs.spec import TaskSpec

from sb3_genrl import LatentActionWrapper
from sb3_genrl.checks import check_positive_int
from sb3_genrl.utils import same_observation

SUCCESS_KEYS = ("is_success", "success")  # read in this order when the default key is asked for
METAWORLD_PREFIX = "metaworld/"
# The held-out resets of an outside task: reset seeds 2**31, 2**31 + 1, ... The recorder draws every reset seed below
# 2**31 (sb3_genrl.envs.demonstrations.recorder) and GenRL's training resets follow the env's own random stream, so
# these resets are never used to record, train or choose anything.
HELD_OUT_SEED = 2**31
HELD_OUT_RESETS = 200


@dataclass(frozen=True)
class Task:
    """A task as every command and the API take it by name (:func:`resolve_task`): its Gymnasium id and what the
    package knows of it. The package's own tasks, Meta-World's and a user's (:func:`register`) are all of this kind.

    :param name: the name as given (``"metaworld/push-v3"``, ``"my_module:MyEnv-v0"``), or the short name of a task
        registered with a TaskSpec (``hockey`` for ``GenRL/Hockey-v0`` too)
    :param env_id: the registered Gymnasium id
    :param make_expert: makes the task's expert, observation -> action (Meta-World's scripted policies); None: none,
        an expert is given (``expert=``, ``--expert MODULE:FUNCTION``) where demonstrations are recorded
    :param horizon: the control steps of a demonstration that suit the task, which ``genrl quickstart`` records with
        (None: the shortest at which its expert's success settles, :func:`sb3_genrl.envs.demonstrations.expert_horizon`)
    :param generator_preset: the generator preset that ``genrl quickstart`` trains for the task (None: its default)
    :param recording_kwargs: arguments of the env that demonstrations are recorded and replayed in, where it is not
        the env GenRL plays (None: the same env). Meta-World's: its training env, which runs on after a success, so
        that a demonstration holds the expert's actions after its success up to the horizon (the env GenRL plays ends
        at the first success, with the same outcome for any action sequence)
    :param make_demonstrations: the task's own demonstration maker, ``(episodes, out_dir, *, seed, n_threads,
        progress_bar) -> dataset folder``, for a task whose demonstrations are not its expert's closed-loop episodes;
        None: recorded from the expert (:func:`sb3_genrl.envs.demonstrations.task_demonstrations` chooses)
    :param spec: the task's :class:`~sb3_genrl.envs.spec.TaskSpec` where it is registered with one (the package's
        hockey, basketball and Fetch tasks, or a user's :func:`sb3_genrl.envs.register_task`): its own demonstration
        maker (:func:`sb3_genrl.envs.demonstrations.make_demonstrations`: hockey's and basketball's open-loop motions,
        each labelled with the goal it reaches, which have no success to check; the Fetch tasks' expert aimed at
        relabelled goals), its goal region and, for the arm tasks, the fast path
    """

    name: str
    env_id: str
    make_expert: Callable[[], Callable[[Any], np.ndarray]] | None = None
    horizon: int | None = None
    generator_preset: str | None = None
    recording_kwargs: Mapping[str, Any] | None = None
    make_demonstrations: Callable[..., Any] | None = None
    spec: TaskSpec | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"a task's name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.env_id, str) or not self.env_id:
            raise ValueError(f"task {self.name!r}: env_id must be a non-empty string, got {self.env_id!r}")
        if self.horizon is not None:
            check_positive_int(self.horizon, f"task {self.name!r}: horizon")
        for hook in ("make_expert", "make_demonstrations"):
            if getattr(self, hook) is not None and not callable(getattr(self, hook)):
                raise ValueError(f"task {self.name!r}: {hook} must be callable, got {type(getattr(self, hook)).__name__}")


_NAMED: dict[str, Task] = {}  # the tasks named by register(), by name and by env id


def register(task: Task) -> Task:
    """Give ``task`` a name that every command and the API take (``genrl quickstart --task NAME``), with its expert,
    horizon, generator preset or own demonstration maker, as the package's own tasks are named.

    :param task: the task; its ``env_id`` must be registered with Gymnasium (``gymnasium.register``)
    :return: ``task``
    :raises ValueError: when the name is another task's, or ``metaworld/`` (Meta-World's), or the env id is unknown
    """
    if not isinstance(task, Task):
        raise ValueError(f"register() takes a sb3_genrl.envs.external.Task, got {type(task).__name__}")
    if task.name.startswith(METAWORLD_PREFIX):
        raise ValueError(f"task {task.name!r}: names under {METAWORLD_PREFIX!r} are Meta-World's tasks")
    if task.env_id not in gym.registry:
        raise ValueError(f"task {task.name!r}: {task.env_id!r} is not a registered Gymnasium id (gymnasium.register it)")
    for key in (task.name, task.env_id):
        known = _NAMED.get(key) or next((spec_task(spec) for spec in TASKS.values() if key in (spec.name, spec.env_id)), None)
        if known is not None and known != task:
            raise ValueError(f"{key!r} already names another task ({known.name!r}, {known.env_id!r})")
    _NAMED[task.name] = _NAMED[task.env_id] = task
    return task


def spec_task(spec: TaskSpec) -> Task:
    """The :class:`Task` of a task registered with a :class:`~sb3_genrl.envs.spec.TaskSpec` (the package's own)."""
    return Task(spec.name, spec.env_id, horizon=spec.horizon, generator_preset=spec.generator_preset, spec=spec)


def resolve_task(task: str) -> Task:
    """The task a name stands for, as every command and the API take it.

    :param task: a task's name or id: one given a name by :func:`register` or registered with a TaskSpec (the package's
        ``hockey``, ``basketball``, ``fetch-push``, ... or their Gymnasium ids), ``metaworld/<name>``, a registered
        Gymnasium id, or ``"module:Id"`` (the module is imported first, as ``gymnasium.make`` does, so that it
        registers ``Id``, a Gymnasium id or a name it gives with :func:`register`)
    :raises ValueError: naming ``task`` and what is accepted, when it is none of them
    """
    if not isinstance(task, str) or not task:
        raise ValueError(f"a task must be a non-empty string, got {task!r}")
    if task in _NAMED:
        return _NAMED[task]
    if task.startswith(METAWORLD_PREFIX):
        name = task.removeprefix(METAWORLD_PREFIX)
        metaworld.check_task_name(name)
        if not metaworld.installed():
            raise ValueError(f"task {task!r} needs Meta-World. {metaworld.INSTALL_HINT}")
        metaworld.register_metaworld_envs()
        return Task(
            task,
            metaworld.metaworld_env_id(name),
            functools.partial(metaworld.metaworld_expert, name),
            generator_preset=metaworld.GENERATOR_PRESET,
            recording_kwargs=metaworld.RECORDING_KWARGS,
        )
    spec = next((spec for spec in TASKS.values() if task in (spec.name, spec.env_id)), None)
    if spec is not None:
        return spec_task(spec)
    env_id = task
    if ":" in task:
        module, env_id = task.split(":", 1)
        try:
            importlib.import_module(module)
        except Exception as error:  # not found, or the module's own code failing as it runs
            raise ValueError(
                f"task {task!r}: cannot import the module {module!r} that should register {env_id!r} "
                f"({type(error).__name__}: {error}){_path_hint(error)}"
            ) from None
    if env_id in _NAMED:
        return _NAMED[env_id]
    if env_id in gym.registry:
        return Task(task, env_id)
    raise ValueError(
        f"unknown task {task!r}; expected a task of the package ({sorted(TASKS)}), metaworld/<name> (one of Meta-World's "
        "50 v3 tasks), a task named with sb3_genrl.envs.external.register, a registered Gymnasium id, or module:Id with "
        "a module that registers Id"
    )


def _path_hint(error: Exception) -> str:
    """For a module not found: how a module in the current folder is found (the ``genrl`` command does not look there)."""
    if not isinstance(error, ModuleNotFoundError):
        return ""
    return "; a module in the current folder is found with PYTHONPATH=. before the command"


def load_expert(spec: str) -> Callable[[Any], np.ndarray]:
    """The expert named ``"module:function"`` (``function`` may be dotted: ``module:Class.method``).

    :param spec: where the expert is; the named object must be callable, observation -> action
    :raises ValueError: naming ``spec`` and why, when it cannot be imported or is not callable
    """
    module_name, sep, attribute = str(spec).partition(":")
    if not sep or not module_name or not attribute:
        raise ValueError(f"an expert is given as module:function, got {spec!r}")
    try:
        found: Any = importlib.import_module(module_name)
    except Exception as error:  # not found, or the module's own code failing as it runs
        raise ValueError(
            f"expert {spec!r}: cannot import the module {module_name!r} ({type(error).__name__}: {error}){_path_hint(error)}"
        ) from None
    for part in attribute.split("."):
        if not hasattr(found, part):
            raise ValueError(f"expert {spec!r}: {module_name!r} has no attribute {attribute!r}")
        found = getattr(found, part)
    if not callable(found):
        raise ValueError(f"expert {spec!r} is a {type(found).__name__}, not a callable observation -> action")
    return found


class SuccessInfo(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """``info["is_success"]`` (a bool) copied from ``info[success_key]`` at every step, for SB3's success rate, GenRL's
    refits and the recorder; an env that reports neither key is left as it is.

    :param env: the env
    :param success_key: the info key of the env's success; ``"is_success"`` (default) also reads ``"success"``
    """

    def __init__(self, env: gym.Env, success_key: str = "is_success") -> None:
        gym.utils.RecordConstructorArgs.__init__(self, success_key=success_key)  # env processes rebuild it from the spec
        gym.Wrapper.__init__(self, env)
        self.success_key = success_key

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        key = success_key_of(info, self.success_key)
        if key is not None:
            info = {**info, "is_success": bool(info[key])}
        return observation, reward, terminated, truncated, info


def success_key_of(info: dict[str, Any], success_key: str = "is_success") -> str | None:
    """The key of ``info`` that holds the success: ``success_key`` (for the default, also ``"success"``), or None."""
    keys = SUCCESS_KEYS if success_key == SUCCESS_KEYS[0] else (success_key,)
    return next((key for key in keys if key in info), None)


def check_success_key(success_key: Any) -> None:
    """Refuse a ``success_key`` that is not a non-empty string."""
    if not isinstance(success_key, str) or not success_key:
        raise ValueError(f"success_key must be a non-empty string, got {success_key!r}")


def check_reports_success(info: dict[str, Any], success_key: str = "is_success", name: str = "the env") -> None:
    """Raise unless a step's ``info`` holds the env's success (:func:`success_key_of`), naming the keys it has."""
    if success_key_of(info, success_key) is None:
        wanted = " or ".join(repr(key) for key in (SUCCESS_KEYS if success_key == SUCCESS_KEYS[0] else (success_key,)))
        raise ValueError(
            f"{name} reports no success: its step's info has no {wanted} (it has {sorted(info)}); give the key that "
            "holds it as success_key (genrl demos and genrl train-policy: --success-key), or, for the quickstart, "
            "which reads is_success or success, have the env report one of those"
        )


def declared_horizon(env: gym.Env) -> int | None:
    """The env's own episode length: its ``spec.max_episode_steps``, else an integer ``horizon`` of ``env.unwrapped``."""
    steps = getattr(env.spec, "max_episode_steps", None) if env.spec is not None else None
    if steps is None:
        steps = getattr(env.unwrapped, "horizon", None)
    return int(steps) if isinstance(steps, int | np.integer) and steps > 0 else None


def task_horizon(env: gym.Env, horizon: int | None = None, name: str = "the env") -> int:
    """The control steps of a demonstration: ``horizon`` when given (at most the env's own), else the env's.

    :raises ValueError: when the env declares none and no ``horizon`` is given, or ``horizon`` exceeds the env's
    """
    declared = declared_horizon(env)
    if horizon is None:
        if declared is None:
            raise ValueError(
                f"{name} declares no episode length (no max_episode_steps in its spec, no horizon attribute): give "
                "horizon= (--horizon), the control steps of a demonstration, which every episode is truncated to"
            )
        return declared
    check_positive_int(horizon, "horizon")
    if declared is not None and horizon > declared:
        raise ValueError(f"horizon {horizon} is longer than {name}'s episodes ({declared} steps); expected at most {declared}")
    return int(horizon)


def make_task_env(
    task: str | Callable[[], gym.Env], *, horizon: int | None = None, success_key: str = "is_success"
) -> gym.Env:
    """The env of a task as the recorder plays it and GenRL should: ``info["is_success"]`` from ``success_key``
    (:class:`SuccessInfo`), and episodes truncated to ``horizon`` when it is shorter than the env's own.

    :param task: a task name (:func:`resolve_task`) or a callable that makes the env
    :param horizon: control steps of an episode (None: the env's ``max_episode_steps``)
    :param success_key: the info key of the env's success
    """
    return task_env_and_horizon(task, horizon, success_key)[0]


def task_env_and_horizon(
    task: str | Callable[[], gym.Env], horizon: int | None, success_key: str, *, recording: bool = False
) -> tuple[gym.Env, int]:
    """:func:`make_task_env`'s env and its horizon (the control steps of an episode, :func:`task_horizon`); with
    ``recording``, the env demonstrations are recorded in (:attr:`Task.recording_kwargs`)."""
    if callable(task):
        env = task()
    else:
        resolved = resolve_task(task)
        env = gym.make(resolved.env_id, **(dict(resolved.recording_kwargs or {}) if recording else {}))
    if not isinstance(env, gym.Env):
        raise ValueError(f"the env maker {task_name(task)!r} returned a {type(env).__name__}, not a gymnasium.Env")
    steps = task_horizon(env, horizon, task_name(task))
    if steps != declared_horizon(env):
        env = TimeLimit(env, max_episode_steps=steps)
    return SuccessInfo(env, success_key), steps


def evaluate_success(
    model: Any,
    task: str | Callable[[], gym.Env],
    *,
    resets: int = HELD_OUT_RESETS,
    horizon: int | None = None,
    success_key: str = "is_success",
) -> dict[str, Any]:
    """A GenRL policy's success on held-out seeded resets of a task: for each reset seed ``HELD_OUT_SEED + i``
    (:data:`HELD_OUT_SEED`, ``i < resets``), the policy's deterministic latent action for the reset's context, decoded
    by its generator and played open loop; a success is ``info["is_success"]`` (from ``success_key``) at the last step.

    :param model: a GenRL model with its generator (``GenRL.load`` of a saved policy)
    :param task: a task name (:func:`resolve_task`) or a callable that makes the env
    :param resets: held-out resets to play
    :param horizon: control steps of an episode (the demonstrations'; None: the env's own)
    :param success_key: the info key of the env's success
    :return: ``success_rate``, ``successes`` (one 0/1 per reset), ``resets`` and ``seeds`` (first and last + 1)
    """
    if getattr(model, "generator", None) is None:
        raise ValueError("this GenRL model has no generator: pass generator= to GenRL.load()")
    check_positive_int(resets, "resets")
    env = LatentActionWrapper(make_task_env(task, horizon=horizon, success_key=success_key), model.generator)
    successes = []
    for i in range(resets):
        context, _ = env.reset(seed=HELD_OUT_SEED + i)
        _, _, _, _, info = env.step(model.predict(context, deterministic=True)[0])
        successes.append(float(bool(info.get("is_success", False))))
    env.close()
    return held_out_result(successes)


def held_out_result(successes: list[float]) -> dict[str, Any]:
    """A policy's score on the held-out resets ``HELD_OUT_SEED + i``, one 0/1 success each: ``success_rate``,
    ``successes``, ``resets`` and ``seeds`` (first and last + 1)."""
    return {
        "success_rate": float(np.mean(successes)),
        "successes": successes,
        "resets": len(successes),
        "seeds": [HELD_OUT_SEED, HELD_OUT_SEED + len(successes)],
    }


def check_reproducible_reset(env: gym.Env, seed: int, name: str = "the env") -> Any:
    """Reset ``env`` twice with ``seed`` and raise unless both observations are the same; return the observation.

    GenRL's trajectories are open loop: a reset that does not reproduce its state from its seed can neither be
    replayed (the recorder's check) nor give a policy a context that says what the trajectory will meet.
    """
    first, _ = env.reset(seed=int(seed))
    second, _ = env.reset(seed=int(seed))
    if not same_observation(first, second):
        raise ValueError(
            f"{name}'s reset(seed={seed}) gave two different observations: its resets are not reproducible from the "
            "seed, so an open-loop trajectory cannot be replayed from its reset (fix the env's seeding: draw every "
            "random start from self.np_random, which reset(seed=...) reseeds)"
        )
    return second


def task_name(task: str | Callable[[], gym.Env]) -> str:
    """How messages and metadata name a task: the name as given, or the qualified name of the callable that makes it."""
    if not callable(task):
        return str(task)
    return getattr(task, "__qualname__", None) or type(task).__name__
