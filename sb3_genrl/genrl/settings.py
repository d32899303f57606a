"""The one check of GenRL's settings, for :class:`~sb3_genrl.GenRL` itself and for anything that takes them before any
work starts (the command line, settings files, benchmarks)."""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

from sb3_genrl.genrl.hindsight import check_hindsight_kwargs

# GenRL arguments that say what to train on, where or how verbosely it runs, not what it computes
NOT_SETTINGS = (
    "self",
    "env",
    "generator",
    "seed",
    "device",
    "verbose",
    "tensorboard_log",
    "stats_window_size",
    "_init_setup_model",
)


def check_genrl_settings(settings: Mapping[str, Any], name: str | None = None) -> dict[str, Any]:
    """Refuse what ``GenRL(**settings)`` would refuse, before any work, each missing setting at GenRL's default.

    :param settings: GenRL constructor arguments (``policy`` may be one of GenRL's aliases), without the env, the
        generator and the arguments that say where it runs (``seed``, ``device``, ``verbose``, ...)
    :param name: what the settings are, to start the error messages with (``"--genrl-kwargs"``); None: nothing
    :return: a plain dict copy of ``settings``
    :raises ValueError: naming the setting and what was expected
    :raises TypeError: when ``settings`` is not a mapping
    """
    from sb3_genrl.genrl.genrl import GenRL

    prefix = f"{name}: " if name else ""
    if not isinstance(settings, Mapping):
        raise TypeError(f"{prefix}expected a dict of GenRL arguments, got {type(settings).__name__}")
    known = set(inspect.signature(GenRL.__init__).parameters) - set(NOT_SETTINGS)
    unknown = sorted(set(settings) - known)
    if unknown:
        raise ValueError(
            f"{prefix}{', '.join(map(repr, unknown))} "
            f"{'is not a GenRL setting' if len(unknown) == 1 else 'are not GenRL settings'} "
            f"(known: {', '.join(sorted(known))})"
        )
    policy = settings.get("policy", "MlpPolicy")
    if isinstance(policy, str) and policy not in GenRL.policy_aliases:
        raise ValueError(f"{prefix}unknown policy {policy!r} (known: {', '.join(GenRL.policy_aliases)})")
    defaults = inspect.signature(GenRL.__init__).parameters
    try:
        checked = _check_values(
            **{key: settings.get(key, defaults[key].default) for key in inspect.signature(_check_values).parameters}
        )
    except ValueError as error:
        raise ValueError(f"{prefix}{error}") from None
    return {**settings, **checked}


def _check_values(
    *,
    e_step: str,
    n_em_iterations: int,
    value_history: int,
    batch_size: int,
    max_log_std_change: float | None,
    policy_averaging: float | None,
    hindsight_kwargs: Mapping[str, Any] | None,
) -> dict[str, Any]:
    """Refuse the values of the GenRL settings that SB3 does not check itself; the hindsight settings as a dict."""
    if e_step not in ("trpo", "kl_penalty"):
        raise ValueError(f"e_step must be 'trpo' or 'kl_penalty', got {e_step!r}")
    for key, value in (("n_em_iterations", n_em_iterations), ("value_history", value_history), ("batch_size", batch_size)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise ValueError(f"{key} must be a positive integer, got {value!r}")
    if max_log_std_change is not None and not max_log_std_change >= 0:
        raise ValueError(
            f"max_log_std_change must be >= 0 (0: the spread stays as it starts) or None, got {max_log_std_change!r}"
        )
    if policy_averaging is not None and not 0 < policy_averaging < 1:
        raise ValueError(f"policy_averaging must be between 0 and 1 (exclusive) or None, got {policy_averaging!r}")
    if hindsight_kwargs is None:
        return {}
    if e_step != "trpo":
        raise ValueError(
            "hindsight_kwargs needs e_step='trpo': a relabelled pull that pi makes unlikely at its new "
            "context has a ratio q/pi that grows exponentially as q moves towards it, faster than the KL "
            "penalty grows, so the KL-penalty E-step's objective has no maximum (TRPO's step keeps the KL "
            "bound)"
        )
    return {"hindsight_kwargs": check_hindsight_kwargs(hindsight_kwargs)}
