"""Per-env settings of GenRL and the baselines, read from ``hyperparams/<algo>.yml`` in rl-zoo3's format.

Each file maps env ids (``GenRL/Hockey-v0``) to an entry of algorithm arguments plus rl-zoo3's own keys
(``n_timesteps``, ``policy``, ``n_envs``, ``normalize``, ...). The files are installed with the package
(``sb3_genrl.hyperparams_files``, mapped to the repository's ``hyperparams/`` folder). Also the goal seeds that keep
tuning apart from evaluation: :data:`EVAL_GOAL_SEED`, :data:`TUNING_GOAL_SEED` and :data:`PRIOR_ROLLOUT_SEED`.
"""

from __future__ import annotations

import ast
import copy
import functools
import inspect
import pathlib
from importlib import resources
from typing import Any

import yaml
from torch import nn

from sb3_genrl.genrl import GenRL, check_genrl_settings
from sb3_genrl.genrl.demonstrations import callback_class, callback_entries
from sb3_genrl.genrl.hindsight import DEFAULTS as HINDSIGHT_DEFAULTS

__all__ = [
    "EVAL_GOAL_SEED",
    "PRIOR_ROLLOUT_SEED",
    "TUNING_GOAL_SEED",
    "changed_settings",
    "check_genrl_entry",
    "hyperparams_file",
    "known_algos",
    "known_env_ids",
    "lay_over",
    "load_genrl_settings",
    "load_hyperparams",
    "parse_kwargs",
]

EVAL_GOAL_SEED = 12345  # the held-out goals of every final evaluation (never used for tuning)
TUNING_GOAL_SEED = 777  # the goals settings are chosen on (never used for evaluation)
PRIOR_ROLLOUT_SEED = 4242  # the goals of the generator scorecard's prior rollout (neither of the above)

_PACKAGE = "sb3_genrl.hyperparams_files"
_KWARGS = ("policy_kwargs", "replay_buffer_kwargs")  # the entries' keys that may be rl-zoo3's "dict(...)" strings
# rl-zoo3's keys that its ExperimentManager takes out of an entry before the algorithm is built
ZOO_KEYS = frozenset(
    {"n_timesteps", "n_envs", "normalize", "env_wrapper", "vec_env_wrapper", "frame_stack", "callback", "normalize_kwargs"}
)


def known_algos() -> list[str]:
    """The algorithms with a settings file (``genrl``, ``ppo``, ``sac``, ...)."""
    return sorted(path.name.removesuffix(".yml") for path in resources.files(_PACKAGE).iterdir() if path.name.endswith(".yml"))


def known_env_ids(algo: str) -> list[str]:
    """The env ids with an entry in ``<algo>.yml``."""
    return sorted(_entries(algo))


def hyperparams_file(algo: str) -> pathlib.Path:
    """The installed ``<algo>.yml``; raises ``ValueError`` naming the known algorithms."""
    path = resources.files(_PACKAGE) / f"{algo}.yml"
    if not path.is_file():
        raise ValueError(f"no settings file {algo}.yml for {algo!r}; known: {', '.join(known_algos())}")
    return pathlib.Path(str(path))


@functools.cache
def _entries(algo: str) -> dict[str, Any]:
    path = hyperparams_file(algo)
    entries = yaml.safe_load(path.read_text())
    if not isinstance(entries, dict) or not all(isinstance(entry, dict) for entry in entries.values()):
        raise ValueError(f"{path}: expected a mapping of env ids to mappings of settings")
    return entries


def load_hyperparams(algo: str, env_id: str) -> dict[str, Any]:
    """The entry of ``env_id`` in ``<algo>.yml`` (a fresh copy), its ``policy_kwargs`` and ``replay_buffer_kwargs``
    as dicts (see :func:`parse_kwargs`).

    :param algo: ``genrl``, ``ppo``, ``sac``, ``latent_ppo``, ``latent_sac``, ``latent_trpo`` (:func:`known_algos`)
    :param env_id: a Gymnasium id, e.g. ``GenRL/Hockey-v0``
    :return: the entry's settings, rl-zoo3's own keys (``n_timesteps``, ``policy``, ...) included
    """
    entries = _entries(algo)
    if env_id not in entries:
        raise ValueError(
            f"{hyperparams_file(algo)} has no entry for {env_id!r}; known env ids: {', '.join(known_env_ids(algo))}"
        )
    entry = copy.deepcopy(entries[env_id])
    for key in _KWARGS:
        if key in entry:
            entry[key] = parse_kwargs(entry[key], f"{algo}.yml {env_id}: {key}")
    return entry


def load_genrl_settings(env_id: str) -> tuple[int, int, dict[str, Any]]:
    """A task's GenRL settings from ``genrl.yml``: the budget of episodes, the episodes per EM iteration and the
    further GenRL arguments, checked by :func:`sb3_genrl.genrl.check_genrl_settings`.

    One GenRL step is one episode: ``n_timesteps`` is the budget of episodes and ``n_steps`` x ``n_envs`` (default 1) is
    ``batch_episodes``, the episodes of an iteration; a run in another number of env processes keeps ``batch_episodes``.
    The entry's ``env_wrapper`` is rl-zoo3's (:mod:`sb3_genrl.zoo`), not a GenRL setting. Its ``callback`` (rl-zoo3's
    key, e.g. the Fetch tasks' :class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback`) is kept among the
    settings as ``callback``, a list of ``{class path: {arguments}}``, which :func:`sb3_genrl.run.train_policy` builds
    (and refuses without the demonstrations it needs).

    :param env_id: the task's Gymnasium id, e.g. ``GenRL/Hockey-v0``
    :return: ``(episodes, batch_episodes, genrl_kwargs)``; ``genrl_kwargs`` may name the ``policy`` and the
        ``callback``
    """
    return check_genrl_entry(load_hyperparams("genrl", env_id), f"{hyperparams_file('genrl')} {env_id}")


def check_genrl_entry(entry: dict[str, Any], name: str) -> tuple[int, int, dict[str, Any]]:
    """A task's entry of GenRL settings in rl-zoo3's format, checked before any work (:func:`load_genrl_settings`
    reads one from ``genrl.yml``; rl-zoo3's entry point checks the entry it runs with, ``-conf`` and ``-params``
    included).

    :param entry: the entry (not changed): ``n_timesteps``, ``n_steps``, optionally ``n_envs``, ``env_wrapper`` and
        ``callback``, and GenRL arguments (``policy_kwargs`` may be rl-zoo3's ``"dict(...)"`` string)
    :param name: where the entry comes from, to start the error messages with
    :return: ``(episodes, batch_episodes, genrl_kwargs)`` as :func:`load_genrl_settings`'s
    :raises ValueError: naming the setting and what was expected
    """
    entry = copy.deepcopy(entry)
    for key in _KWARGS:
        if key in entry:
            entry[key] = parse_kwargs(entry[key], f"{name}: {key}")
    for key in ("n_timesteps", "n_steps"):
        if key not in entry:
            raise ValueError(f"{name}: needs {key}")
    entry.pop("env_wrapper", None)  # rl-zoo3's latent-action wrapper (sb3_genrl.zoo): the package's runs build their own
    callback = [{path: kwargs} for path, kwargs in callback_entries(entry.pop("callback", None), f"{name}: callback")]
    episodes, n_envs, n_steps = entry.pop("n_timesteps"), entry.pop("n_envs", 1), entry.pop("n_steps")
    if isinstance(episodes, float) and episodes.is_integer():  # rl-zoo3's files write budgets as `!!float 3e3`
        episodes = int(episodes)
    for key, value, minimum in (("n_timesteps", episodes, 1), ("n_envs", n_envs, 1), ("n_steps", n_steps, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise ValueError(f"{name}: {key} must be an integer of at least {minimum}, got {value!r}")
    if n_envs * n_steps < 2:
        raise ValueError(
            f"{name}: batch_episodes = n_steps x n_envs, the episodes per iteration, must be at least 2, "
            f"got {n_steps} x {n_envs}"
        )
    return episodes, n_envs * n_steps, check_genrl_settings(entry, name) | ({"callback": callback} if callback else {})


# SB3's ActorCriticPolicy's own networks, and GenRL's spread for a normal prior (policies.default_log_std_init)
_POLICY_DEFAULTS = {"net_arch": {"pi": [64, 64], "vf": [64, 64]}, "log_std_init": 0.0}


def changed_settings(env_id: str) -> list[str]:
    """The GenRL settings of ``env_id``'s entry in ``genrl.yml`` that differ from GenRL's defaults, by name.

    Counted: the episodes per iteration (``batch_episodes``, as ``n_steps``), each :class:`~sb3_genrl.GenRL` argument,
    each key of ``policy_kwargs`` (against SB3's networks and GenRL's spread for a normal prior), ``hindsight_kwargs``
    (switched on) and each of its keys that differs from :class:`~sb3_genrl.genrl.hindsight.HindsightRelabelling`'s
    defaults, and each callback (``callback: DemonstrationCallback``) with each argument that differs from its defaults.
    Not counted: the budget (``n_timesteps``) and rl-zoo3's ``env_wrapper``.
    """

    _, batch_episodes, settings = load_genrl_settings(env_id)
    defaults = {name: parameter.default for name, parameter in inspect.signature(GenRL.__init__).parameters.items()}
    changed = ["n_steps"] if batch_episodes != defaults["n_steps"] else []
    for key, value in settings.items():
        if key == "policy_kwargs":
            changed += [f"policy_kwargs.{name}" for name, given in value.items() if _POLICY_DEFAULTS.get(name) != given]
        elif key == "hindsight_kwargs":
            changed += ["hindsight_kwargs"] * (value is not None)
            changed += [
                f"hindsight_kwargs.{name}" for name, given in (value or {}).items() if HINDSIGHT_DEFAULTS[name] != given
            ]
        elif key == "callback":
            for path, kwargs in callback_entries(value, f"{env_id}: callback"):
                cls = callback_class(path, f"{env_id}: callback")
                own = {name: parameter.default for name, parameter in inspect.signature(cls.__init__).parameters.items()}
                changed += [f"callback: {cls.__name__}"]
                changed += [f"{cls.__name__}.{name}" for name, given in kwargs.items() if own.get(name) != given]
        elif key == "policy":
            changed += ["policy"] * (value != "MlpPolicy")
        elif defaults.get(key, inspect.Parameter.empty) != value:
            changed.append(key)
    return changed


def parse_kwargs(value: Any, name: str = "kwargs") -> dict[str, Any]:
    """A mapping of keyword arguments, as a YAML mapping or as rl-zoo3's string ``"dict(net_arch=[64, 64],
    activation_fn=nn.ReLU)"``.

    rl-zoo3 runs ``eval`` on such strings; a settings file is data, and ``eval`` would run whatever code a file
    holds, so the string is read by a parser that accepts only literals (numbers, strings, booleans, ``None``), lists,
    tuples, ``{...}`` and ``dict(...)`` of them, and ``nn.Name`` (``th.nn.Name``, ``torch.nn.Name``) for a class of
    ``torch.nn``.

    :param value: the mapping or the string
    :param name: where it comes from, for the error message
    """
    if isinstance(value, dict):
        return copy.deepcopy(value)
    if not isinstance(value, str):
        raise ValueError(f"{name}: expected a mapping or a 'dict(...)' string, got {value!r}")
    try:
        parsed = _literal(ast.parse(value.strip(), mode="eval").body)
    except (SyntaxError, ValueError) as error:
        raise ValueError(f"{name}: cannot read {value!r}: {error}") from None
    if not isinstance(parsed, dict):
        raise ValueError(f"{name}: expected 'dict(...)', got {value!r}")
    return parsed


def _literal(node: ast.AST) -> Any:
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd) and isinstance(node.operand, ast.Constant):
        number = node.operand.value
        if isinstance(number, bool) or not isinstance(number, int | float):
            raise ValueError(f"a sign before {number!r}")
        return -number if isinstance(node.op, ast.USub) else number
    if isinstance(node, ast.List | ast.Tuple):
        items = [_literal(item) for item in node.elts]
        return items if isinstance(node, ast.List) else tuple(items)
    if isinstance(node, ast.Dict):
        if None in node.keys:
            raise ValueError("{**...} is not accepted")
        return {_literal(key): _literal(item) for key, item in zip(node.keys, node.values, strict=True)}
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict" and not node.args:
        if any(keyword.arg is None for keyword in node.keywords):
            raise ValueError("dict(**...) is not accepted")
        return {keyword.arg: _literal(keyword.value) for keyword in node.keywords}
    if isinstance(node, ast.Attribute):
        return _torch_nn_class(node)
    raise ValueError(f"{ast.unparse(node)!r} is not a literal, a dict(...) or a torch.nn class")


def _torch_nn_class(node: ast.Attribute) -> type:
    """``nn.ReLU``, ``th.nn.ReLU`` or ``torch.nn.ReLU``: the class of ``torch.nn``."""
    path = ast.unparse(node)
    module, _, name = path.rpartition(".")
    cls = getattr(nn, name, None) if module in ("nn", "th.nn", "torch.nn") else None
    if not (isinstance(cls, type) and issubclass(cls, nn.Module)):
        raise ValueError(f"{path!r} is not a class of torch.nn")
    return cls


def lay_over(settings: dict[str, Any], changes: dict[str, Any]) -> dict[str, Any]:
    """``settings`` with ``changes`` laid over them (a new dict): a mapping laid over a mapping is merged into it,
    key by key; any other value replaces what was there (``None`` too: ``{"hindsight_kwargs": None}`` switches
    GenRL's hindsight off).

    :param settings: e.g. a task's entry (:func:`load_hyperparams`)
    :param changes: e.g. ``{"hindsight_kwargs": {"history": 30}}``
    """
    laid = copy.deepcopy(settings)
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(laid.get(key), dict):
            laid[key] = lay_over(laid[key], value)
        else:
            laid[key] = copy.deepcopy(value)
    return laid
