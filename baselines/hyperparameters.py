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
import math
from collections.abc import Callable
from typing import Any

from sb3_contrib import TRPO
from sb3_genrl.baselines import BASELINES, FEEDBACK_BASELINES
from sb3_genrl.baselines.bc import behaviour_cloning, fit_actor
from sb3_genrl.baselines.normalization import CLIP, STD_FLOOR
from sb3_genrl.envs import get_task
from stable_baselines3 import PPO, SAC

from sb3_genrl.checks import is_finite_number, is_whole_number, json_object_argument
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


def _whole(minimum: int, *, or_minus_one: str = "") -> tuple[str, Callable[[Any], bool]]:
    """An integer setting's description and check (``or_minus_one``: what -1 means, where SB3 takes it)."""
    allowed = f"an integer >= {minimum}" + (f", or -1 ({or_minus_one})" if or_minus_one else "")
    return (
        allowed,
        lambda value: is_whole_number(value) and (value >= minimum or (bool(or_minus_one) and value == -1)),
    )


def _between(low: float, high: float, *, low_open: bool = False, high_open: bool = False, none: bool = False):
    """A number setting's description and check: within ``[low, high]`` (an end open where asked; ``none``: or null)."""
    interval = f"{'(' if low_open else '['}{low}, {high}{')' if high_open else ']'}"
    allowed = f"a number in {interval}" + (", or null" if none else "")

    def valid(value: Any) -> bool:
        if value is None:
            return none
        if not is_finite_number(value):
            return False
        above = value > low if low_open else value >= low
        below = value < high if high_open else value <= high
        return above and below

    return allowed, valid


_FLAG = ("true or false", lambda value: isinstance(value, bool))
_TRAIN_FREQ = (
    "an integer >= 1, or [an integer >= 1, 'step' or 'episode']",
    lambda value: (
        _whole(1)[1](value)
        or (isinstance(value, list) and len(value) == 2 and _whole(1)[1](value[0]) and value[1] in ("step", "episode"))
    ),
)
# What each settable argument of PPO, SAC and TRPO accepts as a JSON value, as SB3 and sb3-contrib use it: values SB3
# would take silently into another run than asked (gamma 2, a negative clip range) or refuse with a traceback partway
_VALUES: dict[str, tuple[str, Callable[[Any], bool]]] = {
    "learning_rate": _between(0, math.inf, low_open=True, high_open=True),
    **{key: _whole(1) for key in ("n_steps", "batch_size", "n_epochs", "target_update_interval", "cg_max_steps")},
    **{key: _whole(1) for key in ("line_search_max_iter", "n_critic_updates", "stats_window_size", "sub_sampling_factor")},
    "learning_starts": _whole(0),
    "gradient_steps": _whole(1, or_minus_one="as many as the steps played"),
    "sde_sample_freq": _whole(1, or_minus_one="only at a rollout's start"),
    "train_freq": _TRAIN_FREQ,
    "gamma": _between(0, 1),
    "gae_lambda": _between(0, 1),
    "tau": _between(0, 1, low_open=True),
    "clip_range": _between(0, math.inf, low_open=True, high_open=True),
    "clip_range_vf": _between(0, math.inf, low_open=True, high_open=True, none=True),
    "target_kl": _between(0, math.inf, low_open=True, high_open=True, none=True),
    "vf_coef": _between(0, math.inf, high_open=True),
    "max_grad_norm": _between(0, math.inf, low_open=True, high_open=True),
    "cg_damping": _between(0, math.inf, high_open=True),
    "line_search_shrinking_factor": _between(0, 1, low_open=True, high_open=True),
    **{key: _FLAG for key in ("normalize_advantage", "use_sde", "use_sde_at_warmup", "optimize_memory_usage")},
}
_ENT_COEF = "a number >= 0 (SAC: also 'auto' or 'auto_<initial value>', the initial value > 0)"


def _valid_ent_coef(cls: type, value: Any) -> bool:
    """PPO's entropy coefficient is a number >= 0; SAC's may also be learnt: ``"auto"`` or ``"auto_0.1"``."""
    if is_finite_number(value):
        return value >= 0
    if cls is not SAC or not isinstance(value, str):
        return False
    if value == "auto":
        return True
    try:
        initial = float(value.removeprefix("auto_")) if value.startswith("auto_") else math.nan
    except ValueError:
        return False
    return is_finite_number(initial) and initial > 0


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
        plain = json.loads(json.dumps(kwargs))
    except (TypeError, ValueError) as error:
        raise ValueError(f"{algorithm}'s settings must be JSON values: {error}") from None
    for key, value in plain.items():
        if key == "ent_coef" and not _valid_ent_coef(cls, value):
            raise ValueError(f"{algorithm}'s ent_coef must be {_ENT_COEF}, got {value!r}")
        if key in _VALUES and not _VALUES[key][1](value):
            raise ValueError(f"{algorithm}'s {key} must be {_VALUES[key][0]}, got {value!r}")
    return plain


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
