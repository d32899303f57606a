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
``learning_starts: 1000``, ``normalize: True``, ``n_sampled_goal: 4``, ``net_arch: [64, 64]``. Two changes, for
the tasks' terminal-only reward: ``goal_selection_strategy: 'final'`` instead of ``'future'`` (see
:mod:`sb3_genrl.envs.goal`) and ``gamma: 0.99`` (SAC's MuJoCo default) instead of 0.95, which would discount the
reward of a hit 40 steps ahead by 0.95 ** 40 = 0.13.

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
HER_BUFFER: dict[str, Any] = {"n_sampled_goal": 4, "goal_selection_strategy": "final", "copy_info_dict": True}
HER_POLICY: dict[str, Any] = {"net_arch": [64, 64]}


def settings_record() -> dict[str, Any]:
    """All settings as plain JSON values (recorded in each run's summary and checked when a benchmark resumes)."""
    def plain(values: dict[str, Any]) -> dict[str, Any]:
        return {key: value.__name__ if isinstance(value, type) else value for key, value in values.items()}

    return {"ppo": plain(PPO_SETTINGS) | {"policy": plain(PPO_POLICY)},
            "sac": plain(SAC_SETTINGS) | {"policy": plain(SAC_POLICY)},
            "sac-her": plain(HER_SETTINGS) | plain(HER_BUFFER) | {"policy": plain(HER_POLICY)}}
