"""GenRL's optuna sampler for rl-zoo3's ``--optimize-hyperparameters`` (``HYPERPARAMS_SAMPLER["genrl"]``).

The settings searched are those the per-task settings were chosen over: the E-step's KL bound, the episodes per
iteration, the E/M repeats per batch, the value function's history, the spread's trust region and hindsight's history
and regression. The other settings of the task's entry (the policy and its network, ``policy_averaging``, ...) stay.
"""

from __future__ import annotations

import inspect
import math
from typing import Any

from sb3_genrl.genrl.genrl import GenRL

# name -> ("float", low, high) on a log scale, ("int", low, high), or ("categorical", choices)
SEARCH_SPACE: dict[str, tuple[Any, ...]] = {
    "target_kl": ("float", 0.003, 0.1),
    "n_steps_pow": ("int", 3, 6),  # 8 to 64 episodes per env and iteration
    "n_em_iterations": ("int", 1, 5),
    "value_history": ("categorical", (1, 5, 20, 60)),
    "max_log_std_change": ("categorical", (None, 0.005, 0.015, 0.05)),
    "hindsight_history": ("categorical", (1, 30, 60, 120, 240)),
    "hindsight_regression_steps": ("categorical", (0, 128, 512)),
}


def sample_genrl_params(trial: Any, n_actions: int, n_envs: int, additional_args: dict[str, Any]) -> dict[str, Any]:
    """rl-zoo3's sampler contract: a trial's GenRL arguments (laid over the task's entry by rl-zoo3)."""
    params = {}
    for name, (kind, *space) in SEARCH_SPACE.items():
        if kind == "float":
            params[name] = trial.suggest_float(name, *space, log=True)
        elif kind == "int":
            params[name] = trial.suggest_int(name, *space)
        else:
            params[name] = trial.suggest_categorical(name, list(space[0]))
    return convert_genrl_params(params, n_envs)


def convert_genrl_params(params: dict[str, Any], n_envs: int = 1) -> dict[str, Any]:
    """The GenRL arguments of a trial's parameters (rl-zoo3's ``HYPERPARAMS_CONVERTER["genrl"]``, used by
    ``--trial-id``): ``n_steps`` is ``2 ** n_steps_pow`` and the value function's minibatch a whole batch, as in the
    task entries; ``hindsight_kwargs`` gathers hindsight's two."""
    params = dict(params)
    n_steps = 2 ** int(params.pop("n_steps_pow"))
    hindsight = {"history": params.pop("hindsight_history"), "regression_steps": params.pop("hindsight_regression_steps")}
    return {**params, "n_steps": n_steps, "batch_size": n_steps * n_envs, "hindsight_kwargs": hindsight}


def entry_params(hyperparams: dict[str, Any]) -> dict[str, Any] | None:
    """The trial parameters that give a task entry's own settings (GenRL's defaults for those it leaves out), so that
    a study can try them first; ``None`` when one of them lies outside :data:`SEARCH_SPACE`."""
    defaults = {name: parameter.default for name, parameter in inspect.signature(GenRL.__init__).parameters.items()}
    settings = {
        name: hyperparams.get(name, defaults[name])
        for name in ("target_kl", "n_em_iterations", "value_history", "max_log_std_change")
    }
    hindsight = hyperparams.get("hindsight_kwargs")
    if hindsight is None:
        return None
    n_steps = int(hyperparams.get("n_steps", defaults["n_steps"]))
    params = {
        **settings,
        "n_steps_pow": round(math.log2(n_steps)),
        "hindsight_history": hindsight.get("history", 1),
        "hindsight_regression_steps": hindsight.get("regression_steps", 0),
    }
    if 2 ** params["n_steps_pow"] != n_steps or not all(_inside(name, value) for name, value in params.items()):
        return None
    return params


def _inside(name: str, value: Any) -> bool:
    kind, *space = SEARCH_SPACE[name]
    if kind == "categorical":
        return value in space[0]
    return space[0] <= value <= space[1]
