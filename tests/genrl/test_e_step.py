"""GenRL's E-step (sb3_genrl/genrl/e_step.py, sb3_genrl/genrl/fisher.py): the TRPO step refuses what it cannot
take, and its analytic Fisher-vector product is the KL's Hessian."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch as th
from conftest import (
    FastReachEnv,
    LinearGenerator,
)

from sb3_genrl import GenRL
from sb3_genrl.genrl.policies import actor_parameters


def test_trpo_e_step_rejects_non_positive_curvature():
    from sb3_genrl.genrl.e_step import trpo_e_step

    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=64).learn(64)
    data = next(model.rollout_buffer.get(batch_size=None))
    batch = (data.observations, data.actions, data.old_log_prob, (data.advantages - data.advantages.mean()))
    q = copy.deepcopy(model.policy)
    before = th.nn.utils.parameters_to_vector(q.parameters()).detach().clone()
    # A damping of -1000 makes F + damping I negative definite: the quadratic KL model has no positive curvature.
    stats = trpo_e_step(
        q,
        model.policy,
        batch,
        target_kl=0.01,
        cg_max_steps=15,
        cg_damping=-1000.0,
        line_search_shrinking_factor=0.8,
        line_search_max_iter=10,
    )
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
    stats = trpo_e_step(
        q,
        model.policy,
        batch,
        target_kl=1e6,
        cg_max_steps=15,
        cg_damping=0.1,
        line_search_shrinking_factor=0.8,
        line_search_max_iter=10,
    )
    assert stats["line_search_success"] == 0.0 and stats["accepted_fraction"] == 0.0
    for parameter, original in zip(q.parameters(), model.policy.parameters(), strict=True):
        th.testing.assert_close(parameter, original, rtol=0, atol=0)


def _moved_policy(policy_name, activation=th.nn.Tanh):
    """A policy whose actor is moved off its initial weights (a state-dependent mean, a spread away from its start)."""
    policy = GenRL(
        policy_name,
        FastReachEnv(),
        LinearGenerator(),
        seed=0,
        policy_kwargs={"net_arch": {"pi": [16, 16], "vf": [8]}, "activation_fn": activation},
    ).policy
    generator = th.Generator().manual_seed(3)
    with th.no_grad():
        for parameter in actor_parameters(policy):
            parameter.add_(0.3 * th.randn(parameter.shape, generator=generator))
    return policy


@pytest.mark.parametrize(
    ("policy_name", "activation"), [("MlpPolicy", th.nn.Tanh), ("ContextStdPolicy", th.nn.Tanh), ("MlpPolicy", th.nn.ReLU)]
)
def test_analytic_fisher_vector_product_is_the_kl_hessians(policy_name, activation):
    """H v against autograd's double backward pass of the KL, in float64 (the Hessian computed independently)."""
    from sb3_contrib.common.utils import flat_grad
    from stable_baselines3.common.distributions import kl_divergence

    from sb3_genrl.genrl.fisher import gaussian_fisher

    pi = _moved_policy(policy_name, activation)
    generator = th.Generator().manual_seed(0)
    observations = th.rand(200, 2, generator=generator) * 1.6 - 0.8
    with th.no_grad():
        std = pi.get_distribution(observations).distribution.stddev
    fisher = gaussian_fisher(pi, observations, std, actor_parameters(pi))
    assert fisher is not None
    pi64, q64 = copy.deepcopy(pi).double(), copy.deepcopy(pi).double()
    with th.no_grad():
        pi_distribution = pi64.get_distribution(observations.double())
    kl = kl_divergence(q64.get_distribution(observations.double()), pi_distribution).mean()
    grad_kl = th.cat([g.reshape(-1) for g in th.autograd.grad(kl, actor_parameters(q64), create_graph=True)])
    for _ in range(3):
        vector = th.randn(len(grad_kl), generator=generator)
        expected = flat_grad((grad_kl * vector.double()).sum(), actor_parameters(q64), retain_graph=True)
        product = fisher(vector)
        assert product.dtype == th.float32 and expected.norm() > 1
        assert ((product.double() - expected).norm() / expected.norm()).item() < 1e-5


def test_trpo_e_step_with_the_analytic_product_takes_the_double_backward_step(monkeypatch):
    """The E-step's result with the analytic Fisher-vector product matches the one with autograd's (to rounding)."""
    from sb3_genrl.genrl import e_step

    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=64).learn(64)
    data = next(model.rollout_buffer.get(batch_size=None))
    advantages = data.advantages - data.advantages.mean()
    batch = (data.observations, data.actions, data.old_log_prob, advantages / advantages.std())
    results = []
    for analytic in (True, False):
        monkeypatch.setattr(e_step, "ANALYTIC_FISHER", analytic)
        if not analytic:  # and were it on, the autograd product all the same
            monkeypatch.setattr(e_step, "gaussian_fisher", lambda *args: None)
        q = copy.deepcopy(model.policy)
        th.manual_seed(0)
        stats = e_step.trpo_e_step(
            q,
            model.policy,
            batch,
            target_kl=0.01,
            cg_max_steps=15,
            cg_damping=0.1,
            line_search_shrinking_factor=0.8,
            line_search_max_iter=10,
        )
        results.append((stats, th.nn.utils.parameters_to_vector(actor_parameters(q)).detach()))
    (stats, phi), (expected_stats, expected_phi) = results
    assert stats["line_search_success"] == expected_stats["line_search_success"] == 1.0
    assert stats["accepted_fraction"] == expected_stats["accepted_fraction"]
    np.testing.assert_allclose(stats["step_size"], expected_stats["step_size"], rtol=1e-4)
    start = th.nn.utils.parameters_to_vector(actor_parameters(model.policy)).detach()
    assert ((phi - expected_phi).norm() / (expected_phi - start).norm()).item() < 1e-4


def test_the_e_step_takes_the_analytic_product_unless_it_is_switched_off(monkeypatch):
    from sb3_genrl.genrl import e_step

    calls = []
    analytic = e_step.gaussian_fisher
    monkeypatch.setattr(e_step, "gaussian_fisher", lambda *args: calls.append(1) or analytic(*args))
    assert e_step.ANALYTIC_FISHER is True
    GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=32).learn(64)
    assert len(calls) == 6  # 2 iterations of 3 E-steps (n_em_iterations)

    def refuse(*args):
        raise AssertionError("the analytic product was used")

    monkeypatch.setattr(e_step, "ANALYTIC_FISHER", False)
    monkeypatch.setattr(e_step, "gaussian_fisher", refuse)
    GenRL(FastReachEnv(), LinearGenerator(), seed=0, n_steps=32).learn(64)
