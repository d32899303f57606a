"""GenRL's E-step (paper section 4, eq. 4-5): optimise the variational policy ``q_phi`` while ``pi_theta`` stays fixed.

Two variants: a TRPO step (natural gradient of eq. 5's surrogate within the trust region ``KL(q || pi) < delta``,
with sb3-contrib's conjugate gradient and a backtracking line search) and eq. 5 taken literally (surrogate minus a
KL penalty, maximised by Adam). Both evaluate ``q`` and ``pi`` as given; :meth:`GenRL.train` puts them in evaluation
mode, the mode that collected the batch.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np
import torch as th
from sb3_contrib.common.utils import conjugate_gradient_solver, flat_grad
from stable_baselines3.common.distributions import Distribution, kl_divergence
from stable_baselines3.common.policies import ActorCriticPolicy
from torch.nn.utils import parameters_to_vector, vector_to_parameters

from sb3_genrl.genrl.fisher import gaussian_fisher
from sb3_genrl.genrl.policies import actor_parameters

Batch = tuple[th.Tensor, th.Tensor, th.Tensor, th.Tensor]  # observations, actions, log pi(actions), advantages
# The analytic Fisher-vector product (sb3_genrl.genrl.fisher) halves the E-step's time and equals autograd's to
# rounding; False takes autograd's double backward pass for every policy (the product of runs made before it).
ANALYTIC_FISHER = True


def variational_copy(policy: ActorCriticPolicy, previous: ActorCriticPolicy | None) -> ActorCriticPolicy:
    """``q_phi`` for an E-step, equal to ``policy`` (phi <- theta): ``previous`` (an earlier call's, of the same
    architecture) given the policy's parameters, or a copy of the policy the first time (a deep copy at every E-step
    also copies the policy's optimizer, a few milliseconds each)."""
    if previous is None:
        return copy.deepcopy(policy)
    previous.load_state_dict(policy.state_dict())
    previous.set_training_mode(policy.training)
    return previous


def surrogate(
    q: ActorCriticPolicy, pi: ActorCriticPolicy, batch: Batch, pi_distribution: Distribution | None = None
) -> tuple[th.Tensor, th.Tensor]:
    """Eq. 5's terms: E_{alpha ~ pi}[q(alpha|s) / pi(alpha|s) A(s, alpha)] and E_s[KL(q(.|s) || pi(.|s))].

    :param q: the variational policy (gradients flow through it)
    :param pi: the fixed policy (no gradient)
    :param batch: observations, actions, their log-probabilities under the policy that collected them, advantages
    :param pi_distribution: ``pi``'s distribution at the batch's observations, when already computed
    """
    observations, actions, log_prob_pi, advantages = batch
    q_distribution = q.get_distribution(observations)
    ratio = th.exp(q_distribution.log_prob(actions) - log_prob_pi)
    if pi_distribution is None:
        with th.no_grad():
            pi_distribution = pi.get_distribution(observations)
    return (ratio * advantages).mean(), kl_divergence(q_distribution, pi_distribution).mean()


def _candidate(
    q: ActorCriticPolicy, pi: ActorCriticPolicy, batch: Batch, pi_distribution: Distribution
) -> tuple[float, float] | None:
    """Eq. 5's surrogate and KL for a line-search candidate, or ``None`` when its distribution is invalid."""
    try:
        objective, kl = surrogate(q, pi, batch, pi_distribution)
    except ValueError:  # torch.distributions rejected a non-finite mean or a non-positive standard deviation
        return None
    objective_value, kl_value = objective.item(), kl.item()
    return (objective_value, kl_value) if np.isfinite(objective_value) and np.isfinite(kl_value) else None


def trpo_e_step(
    q: ActorCriticPolicy,
    pi: ActorCriticPolicy,
    batch: Batch,
    *,
    target_kl: float,
    cg_max_steps: int,
    cg_damping: float,
    line_search_shrinking_factor: float,
    line_search_max_iter: int,
) -> dict[str, float]:
    """E-step, TRPO variant: maximise eq. 5's surrogate subject to KL(q || pi) < target_kl (Schulman et al. 2015).

    ``q``'s actor parameters are changed in place; when no step is acceptable (no candidate improves the surrogate
    within the bound, the quadratic KL model has no positive curvature, or candidates have invalid distributions)
    ``q`` stays equal to ``pi``.

    :return: ``policy_objective``, ``line_search_success``, ``accepted_fraction`` (of the full step), ``step_size``
    """
    with th.no_grad():  # pi is fixed: its distribution serves the whole step, the line search's candidates included
        pi_distribution = pi.get_distribution(batch[0])
    objective, kl = surrogate(q, pi, batch, pi_distribution)
    # Actor parameters of q: those the KL depends on (the value head is not part of q(alpha|s)).
    params, kl_hessian = kl_hessian_product(q, batch[0], pi_distribution, kl)
    grad_objective = flat_grad(objective, params, retain_graph=True)  # (the fallback differentiates the KL again)

    def fisher_vector_product(vector: th.Tensor) -> th.Tensor:
        return kl_hessian(vector) + cg_damping * vector

    # Natural-gradient direction F^-1 g (conjugate gradient), scaled so that the quadratic KL model equals target_kl.
    direction = conjugate_gradient_solver(fisher_vector_product, grad_objective, max_iter=cg_max_steps).detach()
    curvature = th.dot(direction, fisher_vector_product(direction)).item()
    objective_0 = objective.item()
    if not (np.isfinite(curvature) and curvature > 0 and bool(th.isfinite(direction).all())):
        # No step: F is positive definite in exact arithmetic, a non-positive curvature is numerical breakdown.
        return {"policy_objective": objective_0, "line_search_success": 0.0, "accepted_fraction": 0.0, "step_size": 0.0}
    max_step = float(np.sqrt(2 * target_kl / curvature))

    # Backtracking line search: accept the first step that improves the surrogate within the KL bound; a candidate
    # whose distribution is invalid (e.g. a standard deviation that underflows to 0) is rejected like any other.
    phi_0 = parameters_to_vector(params).detach().clone()
    fraction, new_objective = 1.0, objective_0
    with th.no_grad():
        for _ in range(line_search_max_iter):
            vector_to_parameters(phi_0 + fraction * max_step * direction, params)
            candidate = _candidate(q, pi, batch, pi_distribution)
            if candidate is not None and candidate[1] < target_kl and candidate[0] > objective_0:
                new_objective = candidate[0]
                break
            fraction *= line_search_shrinking_factor
        else:  # no acceptable step: q stays equal to pi
            vector_to_parameters(phi_0, params)
            fraction = 0.0
    return {
        "policy_objective": new_objective,
        "line_search_success": float(fraction > 0),
        "accepted_fraction": fraction,
        "step_size": fraction * max_step,
    }


def kl_hessian_product(
    q: ActorCriticPolicy,
    observations: th.Tensor,
    pi_distribution: Distribution,
    kl: th.Tensor,
) -> tuple[list[th.nn.Parameter], Callable[[th.Tensor], th.Tensor]]:
    """The parameters the KL depends on (``q``'s actor's, in order), and ``v -> H v`` for ``H`` the KL's Hessian in
    them at ``q = pi``: with :data:`ANALYTIC_FISHER`, the analytic Fisher-vector product of a diagonal Gaussian
    (:mod:`sb3_genrl.genrl.fisher`) where the policy's structure is a known one, else the double backward pass
    through autograd's graph of ``kl``."""
    named = actor_parameters(q)
    fisher = (
        gaussian_fisher(q, observations, pi_distribution.distribution.stddev, named)  # type: ignore[attr-defined]
        if ANALYTIC_FISHER
        else None
    )
    if fisher is not None:
        return named, fisher
    grads_kl = th.autograd.grad(kl, named, create_graph=True, allow_unused=True)
    params = [p for p, g in zip(named, grads_kl, strict=True) if g is not None]
    grad_kl = th.cat([g.reshape(-1) for g in grads_kl if g is not None])
    return params, lambda vector: flat_grad((grad_kl * vector).sum(), params, retain_graph=True)


def kl_penalty_e_step(
    q: ActorCriticPolicy,
    pi: ActorCriticPolicy,
    batch: Batch,
    *,
    kl_coef: float,
    n_epochs: int,
    batch_size: int,
    learning_rate: float,
) -> dict[str, float]:
    """E-step, KL-penalty variant: eq. 5 taken literally, E[q/pi A] - kl_coef KL(q || pi), by Adam on minibatches.

    :return: ``policy_objective``, the penalised objective on the whole batch after the last epoch
    """
    params = actor_parameters(q)
    optimizer = th.optim.Adam(params, lr=learning_rate)
    n = len(batch[0])
    for _ in range(n_epochs):
        permutation = th.randperm(n, device=batch[0].device)
        for start in range(0, n, batch_size):
            indices = permutation[start : start + batch_size]
            objective, kl = surrogate(q, pi, tuple(tensor[indices] for tensor in batch))  # type: ignore[arg-type]
            optimizer.zero_grad()
            (-(objective - kl_coef * kl)).backward()
            optimizer.step()
    with th.no_grad():
        objective, kl = surrogate(q, pi, batch)
    return {"policy_objective": (objective - kl_coef * kl).item()}
