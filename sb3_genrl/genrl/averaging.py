"""A moving average of the policy's weights over GenRL's iterations (Polyak-Ruppert averaging).

Once GenRL's policy is narrow, its mean keeps moving by about a trust region's step per iteration around where the
search settles; the average of the last iterations' weights sits nearer the centre than any single iterate. The
average is kept beside the policy that explores: rollouts use the current policy, ``GenRL.predict`` the average.

After ``n`` iterations the average is ``sum_i d^(n-i) theta_i / sum_i d^(n-i)`` over the policies ``theta_1..n``
after each iteration: an exponential moving average with decay ``d``, corrected for its start as Adam corrects its
moments (the initial policy gets no weight), so the first iterations are not pulled towards it.
"""

from __future__ import annotations

import copy

from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.utils import polyak_update


def averaged_copy(policy: ActorCriticPolicy) -> ActorCriticPolicy:
    """A copy of ``policy`` to hold the average: in evaluation mode, no gradients, no optimiser state of its own."""
    average = copy.deepcopy(policy)
    average.set_training_mode(False)
    average.requires_grad_(False)
    return average


def update_average(average: ActorCriticPolicy, policy: ActorCriticPolicy, decay: float, n: int) -> None:
    """Fold ``policy``, the ``n``-th iterate (``n >= 1``), into ``average`` (see the module doc).

    The weight of the new iterate is ``(1 - d) / (1 - d^n)``: 1 for the first, ``1 - d`` in the long run. Buffers
    (batch norm's running statistics) are copied from ``policy``.
    """
    tau = (1.0 - decay) / (1.0 - decay**n)
    polyak_update(policy.parameters(), average.parameters(), tau)
    for buffer, target in zip(policy.buffers(), average.buffers(), strict=True):
        target.copy_(buffer)
