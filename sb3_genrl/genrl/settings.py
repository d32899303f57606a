"""GenRL's settings: their table (name, default, what is allowed) and the one check of their values, for
:class:`~sb3_genrl.GenRL` itself (its constructor, and ``GenRL.load`` with settings) and for anything that takes them
before any work starts (``--genrl-kwargs``, the settings files, the benchmarks).

The table is the settings' own; :class:`~sb3_genrl.GenRL`'s signature gives each the same default (tested). A value
that would stop learning (a KL bound of 0, no line-search iteration, a NaN) or fail partway through a run (a string
for a number, ``net_arch: "big"``) is refused here, with a one-line message naming the setting and what it takes.
"""

from __future__ import annotations

import inspect
import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from sb3_genrl.genrl.hindsight import check_hindsight_kwargs
from sb3_genrl.genrl.latent_critic import check_latent_critic_kwargs
from sb3_genrl.genrl.policies import BoxScaler, ContextStdPolicy, MlpPolicy, MultiInputPolicy

# GenRL's policy aliases, as SB3 algorithms name theirs (GenRL.policy_aliases)
POLICY_ALIASES: dict[str, type[BasePolicy]] = {
    "MlpPolicy": MlpPolicy,
    "MultiInputPolicy": MultiInputPolicy,
    "ContextStdPolicy": ContextStdPolicy,
}
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


@dataclass(frozen=True)
class Setting:
    """One GenRL setting: its default and what it takes.

    :param default: GenRL's default
    :param allowed: what the setting takes, as the error messages say it (``"a positive integer"``)
    :param accepts: whether a value is allowed (its type and range)
    """

    default: Any
    allowed: str
    accepts: Callable[[Any], bool]


def _integer(minimum: int) -> Callable[[Any], bool]:
    return lambda value: isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= minimum


def _number(accepts: Callable[[float], bool]) -> Callable[[Any], bool]:
    """A finite real number (not a bool) that ``accepts`` takes."""
    return lambda value: (
        isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value) and accepts(value)
    )


def _or_none(accepts: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda value: value is None or accepts(value)


_POSITIVE = _number(lambda value: value > 0)
_FRACTION = _number(lambda value: 0 < value < 1)

SETTINGS: dict[str, Setting] = {
    "policy": Setting(
        "MlpPolicy",
        f"one of {', '.join(POLICY_ALIASES)} or an ActorCriticPolicy class",
        lambda value: value in POLICY_ALIASES if isinstance(value, str) else _is_class(value, ActorCriticPolicy),
    ),
    "e_step": Setting(
        "trpo", "'trpo' or 'kl_penalty'", lambda value: isinstance(value, str) and value in ("trpo", "kl_penalty")
    ),
    "learning_rate": Setting(
        3e-3,
        "a finite number > 0 or a schedule (a callable of the remaining progress)",
        lambda value: callable(value) or _POSITIVE(value),
    ),
    "n_steps": Setting(64, "a positive integer", _integer(1)),
    "batch_size": Setting(64, "a positive integer", _integer(1)),
    "n_critic_updates": Setting(50, "a positive integer", _integer(1)),
    "cg_max_steps": Setting(15, "a positive integer", _integer(1)),
    "cg_damping": Setting(0.1, "a finite number >= 0", _number(lambda value: value >= 0)),
    "line_search_shrinking_factor": Setting(0.8, "a number between 0 and 1 (exclusive)", _FRACTION),
    "line_search_max_iter": Setting(10, "a positive integer", _integer(1)),
    "target_kl": Setting(0.01, "a finite number > 0 (the E-step's KL bound)", _POSITIVE),
    "kl_coef": Setting(1.0, "a finite number > 0", _POSITIVE),
    "n_e_step_epochs": Setting(10, "a positive integer", _integer(1)),
    "n_em_iterations": Setting(3, "a positive integer", _integer(1)),
    "e_step_learning_rate": Setting(3e-3, "a finite number > 0", _POSITIVE),
    "normalize_advantage": Setting(True, "True or False", lambda value: isinstance(value, bool)),
    "max_log_std_change": Setting(  # inf: no bound, as None
        None,
        ">= 0 (0: the spread stays as it starts) or None",
        _or_none(lambda value: isinstance(value, numbers.Real) and not isinstance(value, bool) and value >= 0),
    ),
    "success_kl_floor": Setting(None, "between 0 (exclusive) and 1, or None", _or_none(_number(lambda value: 0 < value <= 1))),
    "value_history": Setting(1, "a positive integer", _integer(1)),
    "policy_averaging": Setting(None, "between 0 and 1 (exclusive) or None", _or_none(_FRACTION)),
    "hindsight_kwargs": Setting(None, "a dict or None", lambda value: value is None or isinstance(value, Mapping)),
    "latent_critic_kwargs": Setting(None, "a dict or None", lambda value: value is None or isinstance(value, Mapping)),
    "pulls_per_context": Setting(1, "a positive integer", _integer(1)),
    "latent_clip": Setting(3.0, "a finite number > 0", _POSITIVE),
    "policy_kwargs": Setting(None, "a dict or None", lambda value: value is None or isinstance(value, Mapping)),
}


def _is_class(value: Any, base: type) -> bool:
    return isinstance(value, type) and issubclass(value, base)


def check_genrl_settings(settings: Mapping[str, Any], name: str | None = None) -> dict[str, Any]:
    """Refuse what ``GenRL(**settings)`` would refuse or could not learn with, before any work, each missing setting
    at its default (:data:`SETTINGS`).

    :param settings: GenRL constructor arguments (``policy`` may be one of GenRL's aliases), without the env, the
        generator and the arguments that say where it runs (``seed``, ``device``, ``verbose``, ...)
    :param name: what the settings are, to start the error messages with (``"--genrl-kwargs"``); None: nothing
    :return: a plain dict copy of ``settings`` (``hindsight_kwargs`` copied too)
    :raises ValueError: naming the setting, the value and what was expected
    :raises TypeError: when ``settings`` is not a mapping
    """
    prefix = f"{name}: " if name else ""
    if not isinstance(settings, Mapping):
        raise TypeError(f"{prefix}expected a dict of GenRL arguments, got {type(settings).__name__}")
    unknown = sorted(set(settings) - set(SETTINGS))
    if unknown:
        raise ValueError(
            f"{prefix}{', '.join(map(repr, unknown))} "
            f"{'is not a GenRL setting' if len(unknown) == 1 else 'are not GenRL settings'} "
            f"(known: {', '.join(sorted(SETTINGS))})"
        )
    try:
        checked = _check_values({key: settings.get(key, setting.default) for key, setting in SETTINGS.items()})
    except ValueError as error:
        raise ValueError(f"{prefix}{error}") from None
    return {**settings, **({"hindsight_kwargs": checked} if "hindsight_kwargs" in settings else {})}


def _check_values(values: dict[str, Any]) -> dict[str, Any] | None:
    """Refuse a value outside its setting's range, or settings that do not go together; the hindsight settings as a
    dict (None: no hindsight)."""
    for key, value in values.items():
        if not SETTINGS[key].accepts(value):
            if key == "policy" and isinstance(value, str):
                raise ValueError(f"unknown policy {value!r} (known: {', '.join(POLICY_ALIASES)})")
            kind = "" if value is None or isinstance(value, numbers.Real) else f" ({type(value).__name__})"
            raise ValueError(f"{key} must be {SETTINGS[key].allowed}, got {value!r}{kind}")
    policy = values["policy"]
    _check_policy_kwargs(values["policy_kwargs"], POLICY_ALIASES.get(policy, policy))
    if values["latent_critic_kwargs"] is not None:
        check_latent_critic_kwargs(values["latent_critic_kwargs"])
        if values["pulls_per_context"] > 1:
            raise ValueError("latent_critic_kwargs and pulls_per_context > 1 both give the E-step its baseline: choose one")
    hindsight_kwargs = values["hindsight_kwargs"]
    if values["success_kl_floor"] is not None and not (hindsight_kwargs or {}).get("refit_every"):
        raise ValueError(
            "success_kl_floor scales the KL bound by the share of the batch's pulls that failed, whose success the "
            "buffer of the refits stores: it needs hindsight_kwargs with refit_every > 0"
        )
    if hindsight_kwargs is None:
        return None
    if values["e_step"] != "trpo":
        raise ValueError(
            "hindsight_kwargs needs e_step='trpo': a relabelled pull that pi makes unlikely at its new "
            "context has a ratio q/pi that grows exponentially as q moves towards it, faster than the KL "
            "penalty grows, so the KL-penalty E-step's objective has no maximum (TRPO's step keeps the KL "
            "bound)"
        )
    return check_hindsight_kwargs(hindsight_kwargs)


def _is_net_arch(value: Any) -> bool:
    def layers(sizes: Any) -> bool:
        return isinstance(sizes, list | tuple) and all(_integer(1)(size) for size in sizes)

    if isinstance(value, Mapping):
        return set(value) <= {"pi", "vf"} and all(layers(sizes) for sizes in value.values())
    return value is None or layers(value)


# The policy arguments GenRL sets itself (SB3 passes use_sde to the policy)
_SET_BY_GENRL = ("self", "observation_space", "action_space", "lr_schedule", "use_sde")
_POLICY_KWARG_KINDS: dict[str, tuple[str, Callable[[Any], bool]]] = {
    "net_arch": ("a list of positive layer sizes or a dict of them for 'pi' and 'vf'", _is_net_arch),
    "activation_fn": ("a torch.nn.Module class", lambda value: _is_class(value, th.nn.Module)),
    "log_std_init": ("a finite number", _number(lambda value: True)),
    "features_extractor_class": ("a BaseFeaturesExtractor class", lambda value: _is_class(value, BaseFeaturesExtractor)),
    "optimizer_class": ("a torch.optim.Optimizer class", lambda value: _is_class(value, th.optim.Optimizer)),
    "features_extractor_kwargs": ("a dict or None", lambda value: value is None or isinstance(value, Mapping)),
    "optimizer_kwargs": ("a dict or None", lambda value: value is None or isinstance(value, Mapping)),
    **{
        key: ("True or False", lambda value: isinstance(value, bool))
        for key in ("ortho_init", "full_std", "use_expln", "squash_output", "share_features_extractor", "normalize_images")
    },
}


def _check_policy_kwargs(policy_kwargs: Mapping[str, Any] | None, policy_class: Any) -> None:
    """Refuse a policy argument the policy class does not take, or a value of the wrong kind (``net_arch: "big"``)."""
    parameters = inspect.signature(policy_class.__init__).parameters
    takes_any = any(parameter.kind is inspect.Parameter.VAR_KEYWORD for parameter in parameters.values())
    known = [
        key for key in parameters if key not in _SET_BY_GENRL and parameters[key].kind is not inspect.Parameter.VAR_KEYWORD
    ]
    for key, value in (policy_kwargs or {}).items():
        if key in _SET_BY_GENRL or not (takes_any or key in known):
            raise ValueError(
                f"policy_kwargs: {key!r} is not an argument of {policy_class.__name__} that GenRL passes on "
                f"(known: {', '.join(known)})"
            )
        if key in _POLICY_KWARG_KINDS and not _POLICY_KWARG_KINDS[key][1](value):
            kind = "" if value is None or isinstance(value, numbers.Real) else f" ({type(value).__name__})"
            raise ValueError(f"policy_kwargs['{key}'] must be {_POLICY_KWARG_KINDS[key][0]}, got {value!r}{kind}")
    _check_optimizer_kwargs(policy_kwargs or {})
    _check_extractor_kwargs(policy_kwargs or {})


def _check_optimizer_kwargs(policy_kwargs: Mapping[str, Any]) -> None:
    """Refuse ``optimizer_kwargs`` that the policy's optimizer (``optimizer_class``, SB3's default Adam) does not take
    or refuses: it is built here on one parameter with them (SB3 gives it ``lr`` from the learning rate itself)."""
    optimizer_kwargs = dict(policy_kwargs.get("optimizer_kwargs") or {})
    optimizer_class = policy_kwargs.get("optimizer_class") or th.optim.Adam
    if not optimizer_kwargs:
        return
    for key in ("params", "lr"):
        if key in optimizer_kwargs:
            raise ValueError(f"policy_kwargs['optimizer_kwargs']: {key!r} is set by SB3 (the learning rate: learning_rate)")
    try:
        optimizer_class([th.zeros(1, requires_grad=True)], lr=1e-3, **optimizer_kwargs)
    except (TypeError, ValueError, RuntimeError) as error:
        raise ValueError(
            f"policy_kwargs['optimizer_kwargs'] {optimizer_kwargs!r}: {optimizer_class.__name__} refuses them ({error})"
        ) from None


def _check_extractor_kwargs(policy_kwargs: Mapping[str, Any]) -> None:
    """Refuse ``features_extractor_kwargs`` that are not arguments of the features extractor (``features_extractor_class``,
    GenRL's :class:`~sb3_genrl.genrl.policies.BoxScaler` for a Box context when not given)."""
    extractor_kwargs = policy_kwargs.get("features_extractor_kwargs") or {}
    if not extractor_kwargs:
        return
    extractor = policy_kwargs.get("features_extractor_class") or BoxScaler
    parameters = inspect.signature(extractor.__init__).parameters
    if any(parameter.kind is inspect.Parameter.VAR_KEYWORD for parameter in parameters.values()):
        return
    known = [key for key in parameters if key not in ("self", "observation_space")]
    unknown = [key for key in extractor_kwargs if key not in known]
    if unknown:
        raise ValueError(
            f"policy_kwargs['features_extractor_kwargs']: {', '.join(map(repr, unknown))} not an argument of "
            f"{extractor.__name__} (known: {', '.join(known) or 'none'})"
        )
