"""The baselines' hyperparameters: rl-baselines3-zoo's published settings, in ``hyperparams/<algo>.yml`` keyed by
env id (each file's comment names the zoo entry it copies and the changes).

``ppo`` (``ppo.yml``), ``sac`` and ``sac-no-prefill`` (``sac.yml``, the task's id), ``sac-her`` (``sac.yml``, the
task's goal-conditioned id), ``latent-ppo``, ``latent-sac``, ``latent-trpo`` (``latent_ppo.yml``, ...). The prefilled
SAC and SAC + HER learn from the first step (:data:`DEMONSTRATIONS_AS_WARM_UP`): the demonstrations in their buffer
replace the zoo's random warm-up.
"""

from __future__ import annotations

import argparse
import inspect
import json
from typing import Any

from sb3_contrib import TRPO
from sb3_genrl.baselines import BASELINES, FEEDBACK_BASELINES
from sb3_genrl.baselines.bc import behaviour_cloning, fit_actor
from sb3_genrl.baselines.normalization import CLIP, STD_FLOOR
from sb3_genrl.envs import get_task
from stable_baselines3 import PPO, SAC

from sb3_genrl.checks import json_object_argument
from sb3_genrl.hyperparams import ZOO_KEYS, load_hyperparams

# the settings file of each baseline
ZOO_FILES = {
    "ppo": "ppo",
    "sac": "sac",
    "sac-no-prefill": "sac",
    "sac-her": "sac",
    "latent-ppo": "latent_ppo",
    "latent-sac": "latent_sac",
    "latent-trpo": "latent_trpo",
}
DEMONSTRATIONS_AS_WARM_UP: dict[str, Any] = {"learning_starts": 0}  # SAC prefilled and SAC + HER learn at once
# what an entry holds besides the algorithm's plain arguments
_NOT_PLAIN = ZOO_KEYS | {"policy", "policy_kwargs", "replay_buffer_class", "replay_buffer_kwargs"}


def zoo_hyperparams(algorithm: str, task: str) -> dict[str, Any]:
    """A baseline's entry for a task (the goal-conditioned variant's for ``sac-her``), as
    :func:`sb3_genrl.hyperparams.load_hyperparams` reads it.

    :param algorithm: one of :data:`sb3_genrl.baselines.BASELINES`
    :param task: a task name from :data:`sb3_genrl.envs.TASKS` (or its Gymnasium id)
    """
    if algorithm not in ZOO_FILES:
        raise ValueError(f"unknown baseline {algorithm!r}; expected one of {tuple(ZOO_FILES)}")
    spec = get_task(task)
    return load_hyperparams(ZOO_FILES[algorithm], spec.goal_env_id if algorithm == "sac-her" else spec.env_id)


def baseline_settings(algorithm: str, task: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """A baseline's constructor arguments on a task, as it runs with them, and its ``policy_kwargs``.

    :return: the plain arguments (the entry without rl-zoo3's own keys, the policy and the buffer's settings; with
        :data:`DEMONSTRATIONS_AS_WARM_UP` for ``sac`` and ``sac-her``) and the policy's keyword arguments
    """
    entry = zoo_hyperparams(algorithm, task)
    settings = {key: value for key, value in entry.items() if key not in _NOT_PLAIN}
    if algorithm in ("sac", "sac-her"):
        settings |= DEMONSTRATIONS_AS_WARM_UP
    return settings, entry.get("policy_kwargs", {})


# Constructor arguments the baselines set themselves (the env and policy, the demonstrations' buffer and normalisation,
# seeding, device and logging): a user's ``algorithm_kwargs`` cannot change them.
RESERVED = frozenset(
    {
        "self",
        "policy",
        "env",
        "seed",
        "device",
        "verbose",
        "tensorboard_log",
        "buffer_size",
        "replay_buffer_class",
        "replay_buffer_kwargs",
        "policy_kwargs",
        "_init_setup_model",
        "rollout_buffer_class",
        "action_noise",
    }
)  # (the last two take Python objects)


def algorithm_class(algorithm: str) -> type:
    """The SB3 / sb3-contrib class of a baseline (PPO, SAC or TRPO)."""
    if algorithm not in BASELINES:
        raise ValueError(f"unknown baseline {algorithm!r}; expected one of {BASELINES}")
    if algorithm == "latent-trpo":
        return TRPO
    return PPO if algorithm in ("ppo", "latent-ppo") else SAC


def check_algorithm_kwargs(algorithm: str, kwargs: dict[str, Any] | None) -> dict[str, Any]:
    """Check a user's changes to a baseline's settings: names of the algorithm's constructor arguments (e.g.
    ``{"target_kl": 0.02}`` for PPO, ``{"gamma": 1.0}`` for SAC), none of :data:`RESERVED`, values as JSON holds
    them. Returns them as a plain dict (empty for ``None``)."""
    if kwargs is None:
        return {}
    if not isinstance(kwargs, dict):
        raise ValueError(f"{algorithm}'s settings must be a dict of argument names to values, got {kwargs!r}")
    cls = algorithm_class(algorithm)
    names = set(inspect.signature(cls.__init__).parameters) - RESERVED
    wrong = sorted(set(kwargs) - names)
    if wrong:
        raise ValueError(
            f"{algorithm} ({cls.__name__}) has no setting {', '.join(map(repr, wrong))} that a user may "
            f"change; the settable ones: {', '.join(sorted(names))}"
        )
    try:
        return json.loads(json.dumps(kwargs))
    except (TypeError, ValueError) as error:
        raise ValueError(f"{algorithm}'s settings must be JSON values: {error}") from None


def baseline_kwargs_argument(text: str) -> dict[str, dict[str, Any]]:
    """An argparse ``type``: a JSON object of changes per baseline, ``{"ppo": {"target_kl": 0.02}, ...}``, each
    checked by :func:`check_algorithm_kwargs`."""
    value = json_object_argument(text)
    try:
        return {name: check_algorithm_kwargs(name, kwargs) for name, kwargs in value.items()}
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def settings_record(task: str, algorithm_kwargs: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """The feedback baselines' settings on ``task`` as plain JSON values (recorded in each run's summary and checked
    when a benchmark resumes), with a user's changes (``{baseline: {argument: value}}``, see
    :func:`check_algorithm_kwargs`) applied."""

    def plain(values: dict[str, Any]) -> dict[str, Any]:
        return {key: value.__name__ if isinstance(value, type) else value for key, value in values.items()}

    cloning = {
        name: parameter.default
        for function in (behaviour_cloning, fit_actor)
        for name, parameter in inspect.signature(function).parameters.items()
        if parameter.default is not inspect.Parameter.empty and name != "seed"
    }
    observations = {"std_floor": STD_FLOOR, "clip": CLIP, "time_feature": True}
    changes = {name: check_algorithm_kwargs(name, kwargs) for name, kwargs in (algorithm_kwargs or {}).items()}
    record = {}
    for name in FEEDBACK_BASELINES:
        settings, policy_kwargs = baseline_settings(name, task)
        buffer = zoo_hyperparams(name, task).get("replay_buffer_kwargs", {})
        record[name] = plain(settings) | plain(buffer) | {"policy": plain(policy_kwargs), "observations": observations}
    record["ppo"]["behaviour_cloning"] = cloning
    return {name: values | changes.get(name, {}) for name, values in record.items()}
