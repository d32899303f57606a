"""Hindsight relabelling for GenRL: each pull joins the E-step a second time, relabelled with the context it solved.

The latent-space counterpart of hindsight experience replay (Andrychowicz et al., 2017), switched on by GenRL's
``hindsight_kwargs`` as SB3 switches on its ``HerReplayBuffer`` with ``replay_buffer_class``: the rollout buffer becomes
:class:`~sb3_genrl.genrl.hindsight_buffer.HindsightRolloutBuffer`, which stores with each pull its
``info["hindsight"] = (context', r')`` (the context for which its trajectory earns the best reward, and that reward;
:class:`~sb3_genrl.LatentActionWrapper` asks the task's ``hindsight(info)`` for it, or derives it from a goal-conditioned
env's own API: the last achieved goal as desired goal, the reward by ``compute_reward``). A relabelled pull is treated as
if ``pi(.|context')`` had drawn it: its ratio ``q/pi`` is taken at ``context'`` and its advantage is ``r' - V(context')``,
so it stays inside the E-step's KL bound. Relabelled pulls remain true after the policy has moved on (the trajectory
of ``alpha`` still reaches ``context'``), so :class:`HindsightRelabelling` keeps those of the last ``history`` batches
and reweighs them with the current policy and value function at every iteration; the pulls kept for the whole run
(:mod:`sb3_genrl.genrl.kept_pulls`, the demonstrations) join them. Optionally the policy's mean is also fitted to the
kept pulls (:mod:`sb3_genrl.genrl.regression`). The refits of the mean to the run's solving pulls are their own
component (:mod:`sb3_genrl.genrl.refits`). Under the KL-penalty E-step the ratio of a pull that ``pi`` makes unlikely
at its new context grows faster than the penalty, so relabelling needs the TRPO E-step.
"""

from __future__ import annotations

import collections
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy

from sb3_genrl.checks import is_finite_number, is_whole_number
from sb3_genrl.genrl.kept_pulls import KeptPulls
from sb3_genrl.genrl.regression import mean_parameters, regress_mean
from sb3_genrl.genrl.value import use_foreach

Batch = tuple[th.Tensor, th.Tensor, th.Tensor, th.Tensor]  # observations, actions, log pi(actions), advantages
DEFAULTS: dict[str, Any] = {
    "history": 1,
    "regression_steps": 0,
    "regression_lr": 1e-3,
    "regression_batch_size": 256,
    "regression_weighted": False,
    "refit_every": 0,
    "refit_start": None,
    "refit_steps": 4000,
}


def check_hindsight_kwargs(hindsight_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """Refuse hindsight settings that :class:`HindsightRelabelling` would not take, naming the setting.

    :param hindsight_kwargs: some of ``history``, ``regression_steps``, ``regression_lr``, ``regression_batch_size``,
        ``regression_weighted``, ``refit_every``, ``refit_start``, ``refit_steps``
    :return: a plain dict copy
    """
    if not isinstance(hindsight_kwargs, Mapping):
        raise ValueError(f"hindsight_kwargs must be a dict or None, got {hindsight_kwargs!r}")
    unknown = sorted(set(hindsight_kwargs) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"hindsight_kwargs: {', '.join(map(repr, unknown))} not among its settings ({', '.join(DEFAULTS)})")
    settings = DEFAULTS | dict(hindsight_kwargs)
    for key, minimum in (
        ("history", 0),
        ("regression_steps", 0),
        ("regression_batch_size", 1),
        ("refit_every", 0),
        ("refit_steps", 1),
    ):
        value = settings[key]
        if not is_whole_number(value) or value < minimum:
            raise ValueError(f"hindsight_kwargs['{key}'] must be an integer >= {minimum}, got {value!r}")
    start = settings["refit_start"]
    if start is not None and (not is_whole_number(start) or start < 1):
        raise ValueError(f"hindsight_kwargs['refit_start'] must be an integer >= 1 or None, got {start!r}")
    if start is not None and not settings["refit_every"]:
        raise ValueError("hindsight_kwargs['refit_start'] is the episode of the first refit, which needs refit_every > 0")
    learning_rate = settings["regression_lr"]
    if not is_finite_number(learning_rate) or learning_rate <= 0:
        raise ValueError(f"hindsight_kwargs['regression_lr'] must be a finite positive number, got {learning_rate!r}")
    if not isinstance(settings["regression_weighted"], bool | np.bool_):
        raise ValueError(
            f"hindsight_kwargs['regression_weighted'] must be True or False, got {settings['regression_weighted']!r}"
        )
    if settings["regression_weighted"] and not settings["regression_steps"]:
        raise ValueError(
            "hindsight_kwargs['regression_weighted'] weights the regression's pulls, which needs regression_steps > 0"
        )
    return dict(hindsight_kwargs)


class HindsightRelabelling:
    """The relabelled pulls of GenRL's last batches, and the fit of the policy's mean to them (see the module doc).

    :param policy: the policy (a Box context); its current distribution and value function weigh the kept pulls
    :param kept_pulls: the pulls kept for the whole run, joined after the relabelled ones (default None: none)
    :param history: batches whose relabelled pulls join the E-step: the current one and those before it (default 1;
        0: none, and the pulls need no ``info["hindsight"]``; the kept pulls and the refits work as with relabelling)
    :param regression_steps: Adam steps per iteration fitting the policy's mean to the kept pulls (default 0: none)
    :param regression_lr: Adam learning rate of that fit (default 1e-3)
    :param regression_batch_size: pulls per step of the fit, drawn with replacement from the kept ones (default 256)
    :param regression_weighted: weight each pull's error by the policy's density at it relative to its mode
        (default False; see :func:`~sb3_genrl.genrl.regression.regress_mean`)
    """

    def __init__(
        self,
        policy: ActorCriticPolicy,
        *,
        kept_pulls: KeptPulls | None = None,
        history: int = 1,
        regression_steps: int = 0,
        regression_lr: float = 1e-3,
        regression_batch_size: int = 256,
        regression_weighted: bool = False,
    ) -> None:
        check_hindsight_kwargs(
            {
                "history": history,
                "regression_steps": regression_steps,
                "regression_lr": regression_lr,
                "regression_batch_size": regression_batch_size,
                "regression_weighted": regression_weighted,
            }
        )
        if not isinstance(policy.observation_space, spaces.Box):
            raise ValueError(f"hindsight_kwargs relabels Box contexts; this env's context space is {policy.observation_space}")
        self.policy, self.kept_pulls, self.history = policy, kept_pulls, int(history)
        self.regression_steps, self.regression_lr = int(regression_steps), regression_lr
        self.regression_batch_size, self.regression_weighted = int(regression_batch_size), bool(regression_weighted)
        # (contexts, latent actions, rewards) relabelled in the last `history` batches
        self.memory: collections.deque[tuple[th.Tensor, th.Tensor, th.Tensor]] = collections.deque(maxlen=self.history)
        # Adam over the policy's mean; it keeps its moments from iteration to iteration (and is saved with the model)
        self.optimizer = th.optim.Adam(mean_parameters(policy), lr=regression_lr) if self.regression_steps else None

    def extend_batch(
        self,
        batch: Batch,
        relabelled: tuple[th.Tensor, th.Tensor, th.Tensor],
        advantage_mean: th.Tensor | float,
        advantage_std: th.Tensor | float,
    ) -> tuple[Batch, float]:
        """The E-step's batch with the relabelled pulls of this rollout and of the ``history - 1`` before it joined,
        then the kept pulls.

        Each joins as (context', latent action, log-probability under the current policy at context',
        ``(r' - V(context') - advantage_mean) / advantage_std``).

        :param batch: the rollout's pulls as played (observations, actions, log-probabilities, advantages)
        :param relabelled: this rollout's relabelled pulls, contexts', latent actions and rewards'
            (:meth:`~sb3_genrl.genrl.hindsight_buffer.HindsightRolloutBuffer.relabelled_pulls`)
        :return: the joined batch, and the pulls joined per pull played
        """
        self.memory.append(relabelled)  # (with history 0, none are kept)
        contexts, actions, rewards = self._kept()
        if not len(contexts):
            return batch, 0.0
        with th.no_grad():  # the current policy and value function, also for the pulls of earlier batches
            log_prob = self.policy.get_distribution(contexts).log_prob(actions)
            values = self.policy.predict_values(contexts).flatten()
        advantages = (rewards.to(values.dtype) - values - advantage_mean) / advantage_std
        joined_pulls = (contexts, actions, log_prob, advantages)
        joined = tuple(th.cat([played, extra]) for played, extra in zip(batch, joined_pulls, strict=True))
        return joined, len(contexts) / len(batch[0])  # type: ignore[return-value]

    def regress(self) -> list[float]:
        """Fit the policy's mean to the kept relabelled pulls (``regression_steps`` Adam steps); the minibatch losses
        (none without the regression or without kept pulls)."""
        if not self.regression_steps:
            return []
        contexts, actions, _ = self._kept()
        if not len(contexts):
            return []
        use_foreach(self.optimizer)  # type: ignore[arg-type]
        return regress_mean(
            self.policy,
            self.optimizer,
            contexts,
            actions,
            steps=self.regression_steps,  # type: ignore[arg-type]
            batch_size=self.regression_batch_size,
            weighted=self.regression_weighted,
        )

    def set_learning_rate(self) -> None:
        """Give the regression's Adam this component's ``regression_lr`` (after loading a saved optimizer state)."""
        for group in self.optimizer.param_groups if self.optimizer is not None else ():
            group["lr"] = self.regression_lr

    def _kept(self) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        """The kept relabelled pulls, oldest batch first, then those kept for the whole run: contexts, latent actions,
        rewards."""
        whole_run = [] if self.kept_pulls is None or self.kept_pulls.pulls is None else [self.kept_pulls.pulls]
        parts = [*self.memory, *whole_run]
        if not parts:  # history 0 and nothing kept for the run
            device = self.policy.device
            shape = self.policy.observation_space.shape
            return (
                th.zeros((0, *shape), device=device),
                th.zeros((0, *self.policy.action_space.shape), device=device),
                th.zeros(0, device=device),
            )
        return tuple(th.cat(part) for part in zip(*parts, strict=True))  # type: ignore[return-value]
