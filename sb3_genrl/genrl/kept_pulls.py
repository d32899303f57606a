"""Pulls kept for a whole GenRL run: the demonstrations of :class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback`.

Each kept pull ``(context, latent action, reward)`` joins, after the relabelled pulls of the last ``history`` batches,
every E-step's batch and every regression of the mean of :class:`~sb3_genrl.genrl.hindsight.HindsightRelabelling`, and
is never aged out, as demonstrations stay in SAC+HER's replay buffer. They are saved in the run's checkpoints (not in the
model's zip).
"""

from __future__ import annotations

import torch as th
from gymnasium import spaces


class KeptPulls:
    """The pulls kept for the whole run (see the module doc); ``pulls`` is None until :meth:`keep` is called.

    :param observation_space: the context space (a ``Box``)
    :param action_space: the latent action space
    :param device: torch device the pulls are kept on (the policy's)
    """

    def __init__(self, observation_space: spaces.Box, action_space: spaces.Box, device: th.device | str) -> None:
        self.observation_space, self.action_space, self.device = observation_space, action_space, device
        self.pulls: tuple[th.Tensor, th.Tensor, th.Tensor] | None = None

    def keep(self, contexts: th.Tensor, actions: th.Tensor, rewards: th.Tensor) -> None:
        """Keep these pulls (contexts, latent actions, rewards) for the whole run, in place of any kept before."""
        space, n = self.observation_space, len(rewards)
        shapes = (tuple(contexts.shape), tuple(actions.shape), tuple(rewards.shape))
        if shapes != ((n, *space.shape), (n, *self.action_space.shape), (n,)):
            raise ValueError(
                f"KeptPulls.keep: contexts, actions and rewards of shapes {shapes}, expected "
                f"(n, *{space.shape}), (n, *{self.action_space.shape}) and (n,)"
            )
        device = self.device
        self.pulls = (contexts.to(device, th.float32), actions.to(device, th.float32), rewards.to(device, th.float32))
