"""Density and coverage of Naeem et al. (2020), exact and memory-bounded, from the same k-NN balls as precision/recall.

Both use only the real set's balls (radius: the distance to a real sample's ``k``-th nearest real neighbour):

- density: the number of real balls that hold a generated sample, averaged over the generated samples and divided
  by ``k``; about 1 when the generated samples are distributed like the real ones, above 1 where they crowd into
  dense real regions, below 1 where they fall outside;
- coverage: the share of real samples whose ball holds at least one generated sample (a recall that outliers among
  the generated samples cannot inflate).

The distances are computed as in :mod:`sb3_genrl.metrics.precision_recall`: float32 blocks, with every comparison
that the float32 rounding bound leaves open settled by the direct float64 distance, so the results equal a float64
brute force computation. Ties count as inside, as for precision and recall (the ``prdc`` package uses ``<``, which
differs only on exact ties).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from sb3_genrl.metrics.precision_recall import (
    DEFAULT_MEMORY_BUDGET_MB,
    _direct_sq_pairs,
    _float32_floor,
    _float32_tolerance,
    _pair_factors,
    _PreparedSet,
    prepared_sets,
    squared_radii,
)


@dataclasses.dataclass(frozen=True)
class DensityCoverage:
    """Result of :func:`density_coverage`.

    :param density: real balls holding a generated sample, averaged over the generated samples, divided by ``k``
        (>= 0, unbounded; about 1 for samples distributed like the real ones)
    :param coverage: share of real samples whose ball holds a generated sample, in [0, 1]
    :param k: neighbourhood size of the real balls
    :param num_real: number of real samples
    :param num_generated: number of generated samples
    """

    density: float
    coverage: float
    k: int
    num_real: int
    num_generated: int


def real_balls_holding(
    real: _PreparedSet, real_sq_radii: torch.Tensor, generated: _PreparedSet, block: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per generated sample, how many real balls hold it; per real sample, whether its ball holds a generated one.

    Block ``(i, j)`` holds the float32 margins ``|x_i - y_j|^2 - r_i^2``; margins within the rounding bound of 0 are
    settled by direct float64 distances.
    """
    if real.sq_scale != generated.sq_scale:
        raise ValueError("both point sets must be prepared with the same scale")
    n_real, n_gen = real.centred.shape[0], generated.centred.shape[0]
    dim, device = real.centred.shape[1], real.centred.device
    radii32 = (real_sq_radii * real.sq_scale).float()
    left, right = _pair_factors(real, real.sq_norms - radii32, generated, generated.sq_norms)
    tol = _float32_tolerance(dim) * (real.sq_norms + radii32 + generated.sq_norms.max()) + _float32_floor(dim)
    counts = torch.zeros(n_gen, dtype=torch.long, device=device)
    covered = torch.zeros(n_real, dtype=torch.bool, device=device)
    for i0 in range(0, n_real, block):
        i1 = min(i0 + block, n_real)
        row_tol = tol[i0:i1, None]
        for j0 in range(0, n_gen, block):
            j1 = min(j0 + block, n_gen)
            margin = torch.mm(left[i0:i1], right[j0:j1].T)
            inside = margin < -row_tol
            r_idx, c_idx = (margin.abs() <= row_tol).nonzero(as_tuple=True)
            if len(r_idx):
                direct = _direct_sq_pairs(real.original, generated.original, r_idx + i0, c_idx + j0, block)
                inside[r_idx, c_idx] = direct <= real_sq_radii[r_idx + i0]
            counts[j0:j1] += inside.sum(0)
            covered[i0:i1] |= inside.any(1)
    return counts, covered


def density_coverage(
    real: np.ndarray,
    generated: np.ndarray,
    k: int = 3,
    *,
    batch_size: int | None = None,
    device: torch.device | str = "auto",
    memory_budget_mb: float = DEFAULT_MEMORY_BUDGET_MB,
) -> DensityCoverage:
    """Density and coverage (Naeem et al. 2020) of ``generated`` against ``real``, exactly.

    :param real: real samples ``(N, D)`` or ``(N, T, M)`` (flattened per sample)
    :param generated: generated samples with the same per-sample size
    :param k: neighbourhood size (as for precision and recall: 3), ``1 <= k < min(len(real), len(generated))``
    :param batch_size: edge length of the distance blocks; ``None`` chooses it from ``memory_budget_mb``
    :param device: torch device; ``"auto"`` uses a GPU when there is one
    :param memory_budget_mb: memory for the distance blocks in MiB, used when ``batch_size`` is ``None``
    :return: a :class:`DensityCoverage`
    """
    real_set, gen_set, k, block = prepared_sets(real, generated, k, batch_size, device, memory_budget_mb)
    with torch.no_grad():
        counts, covered = real_balls_holding(real_set, squared_radii(real_set, k, block), gen_set, block)
    return DensityCoverage(
        density=float(counts.double().mean()) / k,
        coverage=float(covered.double().mean()),
        k=k,
        num_real=len(real_set.original),
        num_generated=len(gen_set.original),
    )
