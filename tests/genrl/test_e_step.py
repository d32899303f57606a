"""GenRL's E-step (sb3_genrl/genrl/e_step.py): the TRPO step refuses what it cannot take."""

from __future__ import annotations

import copy

import numpy as np
import torch as th
from conftest import (
    FastReachEnv,
    LinearGenerator,
)

from sb3_genrl import GenRL


def test_trpo_e_step_rejects_non_positive_curvature():
    from sb3_genrl.genrl.e_step import trpo_e_step

    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=64).learn(64)
    data = next(model.rollout_buffer.get(batch_size=None))
    batch = (data.observations, data.actions, data.old_log_prob, (data.advantages - data.advantages.mean()))
    q = copy.deepcopy(model.policy)
    before = th.nn.utils.parameters_to_vector(q.parameters()).detach().clone()
    # A damping of -1000 makes F + damping I negative definite: the quadratic KL model has no positive curvature.
    stats = trpo_e_step(q, model.policy, batch, target_kl=0.01, cg_max_steps=15, cg_damping=-1000.0,
                        line_search_shrinking_factor=0.8, line_search_max_iter=10)
    assert stats["line_search_success"] == 0.0 and stats["step_size"] == 0.0 and np.isfinite(stats["policy_objective"])
    th.testing.assert_close(th.nn.utils.parameters_to_vector(q.parameters()).detach(), before, rtol=0, atol=0)


def test_trpo_e_step_rejects_candidates_whose_distribution_is_invalid():
    from sb3_genrl.genrl.e_step import trpo_e_step

    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0)
    observations = th.zeros(64, 2, device=model.device)
    with th.no_grad():
        pi = model.policy.get_distribution(observations)
        offsets = th.cat([th.full((32, 2), 0.1), th.full((32, 2), 2.0)]) * th.tensor([[1.0, -1.0]])
        actions = pi.distribution.mean + offsets.to(model.device)
        advantages = th.cat([th.ones(32), -th.ones(32)]).to(model.device)
        batch = (observations, actions, pi.log_prob(actions), advantages)
    # Actions near the mean are good, far ones bad: the natural step narrows the policy, and with a KL bound of
    # 1e6 every candidate's standard deviation underflows to 0, which torch.distributions refuses.
    q = copy.deepcopy(model.policy)
    stats = trpo_e_step(q, model.policy, batch, target_kl=1e6, cg_max_steps=15, cg_damping=0.1,
                        line_search_shrinking_factor=0.8, line_search_max_iter=10)
    assert stats["line_search_success"] == 0.0 and stats["accepted_fraction"] == 0.0
    for parameter, original in zip(q.parameters(), model.policy.parameters(), strict=True):
        th.testing.assert_close(parameter, original, rtol=0, atol=0)
