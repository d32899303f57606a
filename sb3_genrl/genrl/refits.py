"""Refits of GenRL's policy mean to the pulls of the run that solved their own context.

Switched on by ``hindsight_kwargs["refit_every"]`` (the pulls' success, ``info["is_success"]``, is stored by
:class:`~sb3_genrl.genrl.hindsight_buffer.HindsightRolloutBuffer`). Each solving pull is an exact (context, latent action)
pair of the map the mean should learn, as a demonstration is. Fitted from its initial weights rather than moved a few
steps from where it is, the mean becomes the regression of what the run has found so far, without what earlier fits put
in it (a fit continued for long over-fits; :mod:`sb3_genrl.genrl.demonstrations`); between refits the E-step searches
around it. The demonstrations can join every refit's pairs (``DemonstrationCallback(refit=True)`` sets
:attr:`Refits.demonstrations`), so that a refit made while the run has found few solving pulls still covers the contexts
they solve.
"""

from __future__ import annotations

import numpy as np
import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy

from sb3_genrl.genrl.hindsight import check_hindsight_kwargs
from sb3_genrl.genrl.hindsight_buffer import HindsightRolloutBuffer
from sb3_genrl.genrl.regression import fit_mean, mean_parameters


class Refits:
    """The run's solving pulls, and the refits of the policy's mean to them (see the module doc).

    :param policy: the policy whose mean is refitted (its weights as they are now are the ones every refit starts from)
    :param every: episodes between refits (``hindsight_kwargs["refit_every"]``, at least 1)
    :param start: the episode of the first refit (``refit_start``; default None: ``every``)
    :param steps: Adam steps of each refit (``refit_steps``, default 4000)
    :param learning_rate: Adam learning rate of each refit (``regression_lr``, default 1e-3)
    :param batch_size: pulls per step, drawn with replacement (``regression_batch_size``, default 256)
    """

    def __init__(
        self,
        policy: ActorCriticPolicy,
        *,
        every: int,
        start: int | None = None,
        steps: int = 4000,
        learning_rate: float = 1e-3,
        batch_size: int = 256,
    ) -> None:
        check_hindsight_kwargs(
            {
                "refit_every": every,
                "refit_start": start,
                "refit_steps": steps,
                "regression_lr": learning_rate,
                "regression_batch_size": batch_size,
            }
        )
        if not every:
            raise ValueError("hindsight_kwargs['refit_every'] must be an integer >= 1 for the refits, got 0")
        self.policy, self.every, self.steps = policy, int(every), int(steps)
        self.start = self.every if start is None else int(start)
        self.learning_rate, self.batch_size = learning_rate, int(batch_size)
        # (contexts, latent actions) of the pulls that solved their own context, one entry per batch, for the whole run
        self.solved: list[tuple[th.Tensor, th.Tensor]] = []
        # pairs that join every refit, after the solving pulls: the demonstrations' (contexts, latent actions), set by
        # DemonstrationCallback(refit=True) at every training start (not in a run's checkpoint)
        self.demonstrations: tuple[th.Tensor, th.Tensor] | None = None
        # the weights of the policy's mean as it was made, from which every refit starts
        self.initial_mean = [parameter.detach().clone() for parameter in mean_parameters(policy)]

    def refit(self, rollout_buffer: HindsightRolloutBuffer, episodes: int) -> dict[str, float]:
        """Keep this rollout's pulls that solved their own context; when the run's episode count ``episodes`` has just
        reached ``start``, or ``start`` plus a multiple of ``every``, refit the policy's mean to all those kept so far
        (and to :attr:`demonstrations`): from its initial weights, by ``steps`` steps of a new Adam, as the
        demonstrations are fitted.

        :param rollout_buffer: the rollout's buffer, storing the pulls' success
        :param episodes: the episodes played so far, this rollout's among them
        :return: ``refit_pairs`` and ``refit_loss`` (the mean of the last 100 minibatches') when it refitted, else {}
        """
        self.solved.append(rollout_buffer.solving_pulls())
        played = rollout_buffer.buffer_size * rollout_buffer.n_envs
        if self._refits_due(episodes) == self._refits_due(episodes - played):
            return {}
        extra = [] if self.demonstrations is None else [self.demonstrations]
        contexts, actions = (th.cat(part) for part in zip(*self.solved, *extra, strict=True))
        if not len(actions):
            return {"refit_pairs": 0.0}
        with th.no_grad():
            for parameter, initial in zip(mean_parameters(self.policy), self.initial_mean, strict=True):
                parameter.copy_(initial)
        losses = fit_mean(
            self.policy,
            contexts,
            actions,
            steps=self.steps,
            learning_rate=self.learning_rate,
            batch_size=self.batch_size,
        )
        return {"refit_pairs": float(len(actions)), "refit_loss": float(np.mean(losses[-100:]))}

    def _refits_due(self, episodes: int) -> int:
        """How many refits a run of ``episodes`` episodes has made (at ``start``, then every ``every``)."""
        return 0 if episodes < self.start else (episodes - self.start) // self.every + 1
