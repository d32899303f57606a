"""The baselines' hyperparameters: rl-baselines3-zoo's published settings (``hyperparams/*.yml``), named by entry.

**PPO** (``ppo``): rl-zoo3 ``ppo.yml``, entry ``HalfCheetah-v4`` (tuned, one env): ``normalize: true``,
``n_steps: 512``, ``batch_size: 64``, ``gamma: 0.98``, ``learning_rate: 2.0633e-05``, ``ent_coef: 0.000401762``,
``clip_range: 0.1``, ``n_epochs: 20``, ``gae_lambda: 0.92``, ``max_grad_norm: 0.8``, ``vf_coef: 0.58096``,
``policy_kwargs: dict(log_std_init=-2, ortho_init=False, activation_fn=nn.ReLU, net_arch=dict(pi=[256, 256],
vf=[256, 256]))``. ``log_std_init`` is then replaced by behaviour cloning's held-out residual std.

**SAC** (``sac``, ``sac-no-prefill``): rl-zoo3 ``sac.yml``, entry ``HalfCheetah-v3`` (``&mujoco-defaults``, shared
by Ant, Hopper, Walker2d, Humanoid): ``learning_starts: 10000`` and otherwise SB3's defaults, ``learning_rate:
3e-4``, ``buffer_size: 1e6``, ``batch_size: 256``, ``tau: 0.005``, ``gamma: 0.99``, ``train_freq: 1``,
``gradient_steps: 1``, ``ent_coef: 'auto'``, ``net_arch: [256, 256]``. The prefilled run starts learning at once
(``learning_starts: 0``): its warm-up data are the demonstrations, where the zoo's would be 10000 uniformly random
actions.

**SAC + HER** (``sac-her``): rl-zoo3 ``sac.yml``, entry ``FetchReach-v1`` (the zoo's SAC + ``HerReplayBuffer``
entry): ``learning_rate: 0.001``, ``batch_size: 256``, ``buffer_size: 1e6``, ``ent_coef: 'auto'``,
``normalize: True``, ``n_sampled_goal: 4``, ``net_arch: [64, 64]``. Two changes, for the tasks' terminal-only
reward: ``goal_selection_strategy: 'final'`` instead of ``'future'`` (see :mod:`sb3_genrl.envs.goal`) and
``gamma: 0.99`` (SAC's MuJoCo default) instead of 0.95, which would discount the reward of a hit 40 steps ahead by
0.95 ** 40 = 0.13. As with the prefilled SAC, the demonstrations in the buffer replace the zoo's random warm-up
(``learning_starts: 1000``): learning starts at once.

Everywhere: observations normalised with the demonstrations' statistics
(:mod:`sb3_genrl.baselines.normalization`, the zoo's ``normalize`` on observations), rewards not normalised (the
only nonzero reward is the terminal distance in metres), buffers large enough to keep every transition, and one
episode = the task's horizon in environment steps.
"""

from __future__ import annotations

from typing import Any

from torch import nn

PPO_SETTINGS: dict[str, Any] = {
    "n_steps": 512, "batch_size": 64, "gamma": 0.98, "learning_rate": 2.0633e-05, "ent_coef": 0.000401762,
    "clip_range": 0.1, "n_epochs": 20, "gae_lambda": 0.92, "max_grad_norm": 0.8, "vf_coef": 0.58096,
}
PPO_POLICY: dict[str, Any] = {"log_std_init": -2, "ortho_init": False, "activation_fn": nn.ReLU,
                              "net_arch": {"pi": [256, 256], "vf": [256, 256]}}
SAC_SETTINGS: dict[str, Any] = {"learning_rate": 3e-4, "batch_size": 256, "tau": 0.005, "gamma": 0.99, "train_freq": 1,
                                "gradient_steps": 1, "ent_coef": "auto", "learning_starts": 10_000}
SAC_POLICY: dict[str, Any] = {"net_arch": [256, 256]}
HER_SETTINGS: dict[str, Any] = {"learning_rate": 1e-3, "batch_size": 256, "gamma": 0.99, "ent_coef": "auto",
                                "learning_starts": 1000}
DEMONSTRATIONS_AS_WARM_UP: dict[str, Any] = {"learning_starts": 0}  # SAC prefilled and SAC + HER learn at once
HER_BUFFER: dict[str, Any] = {"n_sampled_goal": 4, "goal_selection_strategy": "final", "copy_info_dict": True}
HER_POLICY: dict[str, Any] = {"net_arch": [64, 64]}


# Constructor arguments the baselines set themselves (the env and policy, the demonstrations' buffer and normalisation,
# seeding, device and logging): a user's ``algorithm_kwargs`` cannot change them.
RESERVED = frozenset({"self", "policy", "env", "seed", "device", "verbose", "tensorboard_log", "buffer_size",
                      "replay_buffer_class", "replay_buffer_kwargs", "policy_kwargs", "_init_setup_model",
                      "rollout_buffer_class", "action_noise"})  # (the last two take Python objects)


def algorithm_class(algorithm: str) -> type:
    """The SB3 / sb3-contrib class of a baseline (PPO, SAC or TRPO)."""
    from sb3_genrl.baselines import BASELINES
    from stable_baselines3 import PPO, SAC

    if algorithm not in BASELINES:
        raise ValueError(f"unknown baseline {algorithm!r}; expected one of {BASELINES}")
    if algorithm == "latent-trpo":
        from sb3_contrib import TRPO

        return TRPO
    return PPO if algorithm in ("ppo", "latent-ppo") else SAC


def check_algorithm_kwargs(algorithm: str, kwargs: dict[str, Any] | None) -> dict[str, Any]:
    """Check a user's changes to a baseline's settings: names of the algorithm's constructor arguments (e.g.
    ``{"target_kl": 0.02}`` for PPO, ``{"gamma": 1.0}`` for SAC), none of :data:`RESERVED`, values as JSON holds
    them. Returns them as a plain dict (empty for ``None``)."""
    import inspect
    import json

    if kwargs is None:
        return {}
    if not isinstance(kwargs, dict):
        raise ValueError(f"{algorithm}'s settings must be a dict of argument names to values, got {kwargs!r}")
    cls = algorithm_class(algorithm)
    names = set(inspect.signature(cls.__init__).parameters) - RESERVED
    wrong = sorted(set(kwargs) - names)
    if wrong:
        raise ValueError(f"{algorithm} ({cls.__name__}) has no setting {', '.join(map(repr, wrong))} that a user may "
                         f"change; the settable ones: {', '.join(sorted(names))}")
    try:
        return json.loads(json.dumps(kwargs))
    except (TypeError, ValueError) as error:
        raise ValueError(f"{algorithm}'s settings must be JSON values: {error}") from None


def json_object_argument(text: str) -> dict[str, Any]:
    """An argparse ``type``: a JSON object (``genrl baseline --algorithm-kwargs``, checked by name once the
    baseline is known)."""
    import argparse

    from sb3_genrl.checks import json_argument

    value = json_argument(text)
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r}")
    return value


def baseline_kwargs_argument(text: str) -> dict[str, dict[str, Any]]:
    """An argparse ``type``: a JSON object of changes per baseline, ``{"ppo": {"target_kl": 0.02}, ...}``, each
    checked by :func:`check_algorithm_kwargs`."""
    import argparse

    value = json_object_argument(text)
    try:
        return {name: check_algorithm_kwargs(name, kwargs) for name, kwargs in value.items()}
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def settings_record(algorithm_kwargs: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """All settings as plain JSON values (recorded in each run's summary and checked when a benchmark resumes),
    with a user's changes (``{baseline: {argument: value}}``, see :func:`check_algorithm_kwargs`) applied."""
    def plain(values: dict[str, Any]) -> dict[str, Any]:
        return {key: value.__name__ if isinstance(value, type) else value for key, value in values.items()}

    import inspect

    from sb3_genrl.baselines.bc import behaviour_cloning, fit_actor
    from sb3_genrl.baselines.normalization import CLIP, STD_FLOOR

    cloning = {name: parameter.default for function in (behaviour_cloning, fit_actor)
               for name, parameter in inspect.signature(function).parameters.items()
               if parameter.default is not inspect.Parameter.empty and name != "seed"}
    observations = {"std_floor": STD_FLOOR, "clip": CLIP, "time_feature": True}
    changes = {name: check_algorithm_kwargs(name, kwargs) for name, kwargs in (algorithm_kwargs or {}).items()}
    record = {"ppo": plain(PPO_SETTINGS) | {"policy": plain(PPO_POLICY), "behaviour_cloning": cloning,
                                          "observations": observations},
            "sac": plain(SAC_SETTINGS | DEMONSTRATIONS_AS_WARM_UP) | {"policy": plain(SAC_POLICY),
                                                                       "observations": observations},
            "sac-no-prefill": plain(SAC_SETTINGS) | {"policy": plain(SAC_POLICY), "observations": observations},
            "sac-her": plain(HER_SETTINGS | DEMONSTRATIONS_AS_WARM_UP) | plain(HER_BUFFER)
            | {"policy": plain(HER_POLICY), "observations": observations}}
    return {name: values | changes.get(name, {}) for name, values in record.items()}
