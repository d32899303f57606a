"""Disentanglement with precision and recall, DwPR (paper section 5.2.2).

For each latent dimension ``l`` the generator decodes ``n`` prior samples for each of ``D`` interventions
``alpha_l = I_d``; the union ``T^l`` of these ``n * D`` trajectories is compared with a reference set of ``n * D``
trajectories decoded from the prior: ``delta(l) = precision(reference, T^l) - recall(reference, T^l)`` (eq.
(disentanglement)). A well disentangled dimension fixes one aspect of the trajectories: its intervened samples stay
realistic (high precision) but cover only part of the reference (low recall).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from stable_baselines3.common.utils import get_device

from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.metrics.precision_recall import (
    DEFAULT_MEMORY_BUDGET_MB,
    as_points,
    block_size,
    membership,
    power_of_two_scale,
    prepare,
    squared_radii,
)

# Paper section 6.1.2: D = 5 interventions on n = 10000 prior samples each, k = 3.
DEFAULT_INTERVENTIONS = 5
DEFAULT_DWPR_SAMPLES = 10000
DECODE_BATCH_SIZE = 1024


@dataclasses.dataclass(frozen=True, eq=False)
class DwPR:
    """Result of :func:`dwpr`.

    :param delta: ``(latent_dim,)`` disentanglement ``delta(l) = precision(l) - recall(l)`` per latent dimension
    :param precision: ``(latent_dim,)`` precision of the intervened set against the reference, per dimension
    :param recall: ``(latent_dim,)`` recall of the intervened set against the reference, per dimension
    :param delta_1: highest ``delta(l)``
    :param delta_2: second highest ``delta(l)`` (0 when ``latent_dim == 1``, see :func:`dwpr`)
    :param mean_delta: ``(delta_1 + delta_2) / 2``, the paper's delta tilde
    :param intervention_values: ``(D,)`` values ``I_d`` given to the intervened dimension
    :param n: prior samples per intervention (reference set size ``n * D``)
    :param k: neighbourhood size
    """

    delta: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    delta_1: float
    delta_2: float
    mean_delta: float
    intervention_values: np.ndarray
    n: int
    k: int


def default_intervention_values(prior: str, interventions: int) -> np.ndarray:
    """Equal-probability intervention values: the prior's quantiles at ``(d - 0.5) / D`` for ``d = 1..D``.

    Each value stands for an equal share of the prior's mass, so the ``D`` interventions together cover the range
    the dimension takes under the prior the way the reference samples do. For the standard normal prior and
    ``D = 5`` they are ``(-1.28, -0.52, 0, 0.52, 1.28)``; for U(-1, 1) ``(-0.8, -0.4, 0, 0.4, 0.8)``.

    :param prior: ``"normal"`` or ``"uniform"``
    :param interventions: number ``D`` of interventions
    :return: ``(D,)`` float32 values
    """
    if int(interventions) != interventions or interventions < 1:
        raise ValueError(f"interventions must be a positive integer, got {interventions!r}")
    levels = (np.arange(1, interventions + 1) - 0.5) / interventions
    if prior == "normal":
        from scipy.stats import norm  # scipy.stats costs about 0.5 s; every `genrl` command reaches this module

        return norm.ppf(levels).astype(np.float32)
    if prior == "uniform":
        return (2.0 * levels - 1.0).astype(np.float32)
    raise ValueError(f"prior must be 'normal' or 'uniform', got {prior!r}")


def decode_batched(generator: TrajectoryGenerator, latents: np.ndarray, batch_size: int = DECODE_BATCH_SIZE) -> np.ndarray:
    """Decode ``(n, latent_dim)`` latents in batches into a ``(n, horizon * action_dim)`` float32 array."""
    out = np.empty((len(latents), generator.horizon * generator.action_dim), dtype=np.float32)
    for start in range(0, len(latents), batch_size):
        batch = np.asarray(generator.decode(latents[start : start + batch_size]))
        out[start : start + len(batch)] = batch.reshape(len(batch), -1)
    return out


def top_two(delta: np.ndarray) -> tuple[float, float]:
    """``(delta_1, delta_2)``: the two highest values; ``delta_2 = 0`` when there is a single dimension."""
    ordered = np.sort(np.asarray(delta, dtype=np.float64))[::-1]
    second = float(ordered[1]) if len(ordered) > 1 else 0.0
    return float(ordered[0]), second


def dwpr(
    generator: TrajectoryGenerator,
    n: int = DEFAULT_DWPR_SAMPLES,
    interventions: int = DEFAULT_INTERVENTIONS,
    k: int = 3,
    *,
    seed: int | np.random.Generator | None = 0,
    intervention_values: np.ndarray | None = None,
    batch_size: int | None = None,
    device: torch.device | str = "auto",
    memory_budget_mb: float = DEFAULT_MEMORY_BUDGET_MB,
) -> DwPR:
    """Disentanglement with precision and recall of a generator (paper section 5.2.2).

    The reference set holds ``n * D`` trajectories decoded from prior samples. For each latent dimension ``l`` and
    each intervention value ``I_d``, ``n`` fresh prior samples get ``alpha_l = I_d``; the ``n * D`` decoded
    trajectories form ``T^l``, and ``delta(l) = precision(reference, T^l) - recall(reference, T^l)`` with the
    reference as the real set. The reference's radii are computed once and reused for every dimension.

    Intervention values: the paper does not list them; by default they are the prior's equal-probability
    quantiles (:func:`default_intervention_values`), so that together they span the dimension's range under the
    prior like the reference does, without favouring extreme or central values.

    With a single latent dimension there is no second dimension to disentangle a second aspect of the task;
    ``delta_2`` is then 0, the value of a dimension that controls nothing, and ``mean_delta = delta_1 / 2``.

    :param generator: the trajectory generator
    :param n: prior samples per intervention (paper: 10000)
    :param interventions: number ``D`` of intervention values (paper: 5); ignored when ``intervention_values`` is given
    :param k: neighbourhood size (paper: 3)
    :param seed: seed or generator for the prior samples
    :param intervention_values: explicit ``(D,)`` values ``I_d``
    :param batch_size: edge length of the distance blocks (see :func:`~sb3_genrl.metrics.precision_recall`)
    :param device: torch device for the distances; ``"auto"`` uses a GPU when there is one
    :param memory_budget_mb: memory for the distance blocks in MiB, used when ``batch_size`` is ``None``
    :return: a :class:`DwPR`
    """
    values = _checked_intervention_values(generator, n, interventions, k, intervention_values)
    n, k = int(n), int(k)
    rng = np.random.default_rng(seed)
    torch_device = get_device(device)
    block = block_size(n * len(values), batch_size, memory_budget_mb)
    precision, recall = _precision_recall_per_dimension(generator, values, n, k, rng, torch_device, block)
    delta = precision - recall  # eq. (disentanglement)
    delta_1, delta_2 = top_two(delta)
    return DwPR(
        delta=delta,
        precision=precision,
        recall=recall,
        delta_1=delta_1,
        delta_2=delta_2,
        mean_delta=(delta_1 + delta_2) / 2,
        intervention_values=values,
        n=int(n),
        k=int(k),
    )


def _checked_intervention_values(
    generator: TrajectoryGenerator, n: int, interventions: int, k: int, intervention_values: np.ndarray | None
) -> np.ndarray:
    """Check :func:`dwpr`'s ``n``, ``k`` and interventions; return the ``(D,)`` float32 intervention values."""
    if int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    if intervention_values is None:
        values = default_intervention_values(generator.prior, interventions)
    else:
        values = np.asarray(intervention_values, dtype=np.float32).reshape(-1)
        if len(values) == 0 or not np.all(np.isfinite(values)):
            raise ValueError(f"intervention_values must be a non-empty finite sequence, got {intervention_values!r}")
    size = n * len(values)
    if int(k) != k or k < 1 or k >= size:
        raise ValueError(f"k must be a positive integer smaller than n * D = {size}, got {k!r}")
    return values


def _precision_recall_per_dimension(
    generator: TrajectoryGenerator,
    values: np.ndarray,
    n: int,
    k: int,
    rng: np.random.Generator,
    torch_device: torch.device,
    block: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the ``(latent_dim,)`` precision and recall of each dimension's intervened set against the reference."""
    size = n * len(values)
    reference = as_points(decode_batched(generator, generator.sample_prior(size, rng)), "reference trajectories")
    shift = reference.mean(0, dtype=np.float64)
    reference_set = prepare(reference, shift, power_of_two_scale([("reference", reference)], shift), torch_device)
    precision = np.empty(generator.latent_dim)
    recall = np.empty(generator.latent_dim)
    with torch.no_grad():
        reference_radii = squared_radii(reference_set, k, block)
        for dim in range(generator.latent_dim):
            latents = generator.sample_prior(size, rng)
            latents[:, dim] = np.repeat(values, n)  # n samples per intervention alpha_l = I_d
            intervened = as_points(decode_batched(generator, latents), f"trajectories intervened on dimension {dim}")
            scale = power_of_two_scale([("reference", reference), ("intervened", intervened)], shift)
            if scale * scale != reference_set.sq_scale:  # both sets in the same float32 units
                reference_set = prepare(reference, shift, scale, torch_device)
            intervened_set = prepare(intervened, shift, scale, torch_device)
            intervened_radii = squared_radii(intervened_set, k, block)
            inside_reference, reference_inside = membership(
                reference_set, reference_radii, intervened_set, intervened_radii, block
            )
            precision[dim] = float(inside_reference.double().mean())
            recall[dim] = float(reference_inside.double().mean())
    return precision, recall
