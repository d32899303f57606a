"""Improved precision and recall of Kynkaanniemi et al. (2019), exact and memory-bounded (paper section 5.2.1).

A set's manifold is the union of balls around its points, each with radius equal to the distance to the point's
``k``-th nearest neighbour within its own set. Precision is the share of generated samples inside the real manifold,
recall the share of real samples inside the generated manifold (paper eq. (prec_and_recall)).

Distances are computed block by block as ``|x|^2 + |y|^2 - 2 x.y^T`` with float32 matrix products (BLAS or GPU);
no ``N x N`` matrix is ever held. Float32 rounding does not change a result: every decision whose float32 margin lies
within the worst-case rounding bound is settled with the direct float64 sum of squared coordinate differences of
the original values, which also decides exact ties. The float32 values are centred and scaled by a power of two
(exact, order-preserving) so that they neither overflow nor underflow, whatever the magnitude of the samples.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch
from stable_baselines3.common.utils import get_device

# Unit roundoff of float32, and the absolute rounding error of a float32 result in the subnormal range.
_U32 = 2.0**-24
_SUBNORMAL32 = 2.0**-149
DEFAULT_MEMORY_BUDGET_MB = 256.0
# Bytes of temporaries per element of a distance block (the block, a margin buffer, reductions).
_BYTES_PER_BLOCK_ELEMENT = 12
# Positions per group of :func:`_merge_nearest`'s reduction pass.
_GROUP_SIZE = 16
# Float32 nearest neighbours kept per point beyond its k nearest: a radius is settled from the kept ones unless that
# many more lie within the rounding bound of the k-th (then the point's row is recomputed).
_EXTRA_CANDIDATES = 2


@dataclasses.dataclass(frozen=True, eq=False)
class PrecisionRecall:
    """Result of :func:`precision_recall`.

    :param precision: share of generated samples inside the real manifold, in [0, 1]
    :param recall: share of real samples inside the generated manifold, in [0, 1]
    :param k: neighbourhood size used for the radii
    :param num_real: number of real samples
    :param num_generated: number of generated samples
    :param real_radii: ``(num_real,)`` float64 distances to the k-th nearest real neighbour, when requested
    :param generated_radii: ``(num_generated,)`` float64 distances to the k-th nearest generated neighbour, when requested
    """

    precision: float
    recall: float
    k: int
    num_real: int
    num_generated: int
    real_radii: np.ndarray | None = None
    generated_radii: np.ndarray | None = None


class _PreparedSet(NamedTuple):
    """A point set on the device: original values, centred and scaled float32 values and their squared norms."""

    original: torch.Tensor  # (n, d) float32 or float64 as given, used (in float64) for the exact direct distances
    centred: torch.Tensor  # (n, d) float32 (x - shift) * scale, used for the fast matrix products
    sq_norms: torch.Tensor  # (n,) float32
    sq_scale: float  # scale**2: float32 squared distances are the original ones times sq_scale


def as_points(samples: np.ndarray, name: str) -> np.ndarray:
    """Return ``samples`` ``(N, D)`` or ``(N, T, M)`` as a finite ``(N, T*M)`` array, or raise a ``ValueError``.

    Float32 (and narrower float) samples stay float32, which float64 holds exactly; other types become float64.
    """
    array = np.asarray(samples)
    dtype = np.float32 if array.dtype in (np.float16, np.float32) else np.float64
    array = array.astype(dtype, copy=False)
    if array.ndim < 2:
        raise ValueError(f"{name} must have shape (N, D) or (N, T, M), got shape {array.shape}")
    array = array.reshape(array.shape[0], -1)
    if array.shape[0] == 0 or array.shape[1] == 0:
        raise ValueError(f"{name} must hold at least one non-empty sample, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains non-finite values (nan or inf)")
    return array


def block_size(num_points: int, batch_size: int | None, memory_budget_mb: float) -> int:
    """Edge length of the square distance blocks: ``batch_size`` if given, else from the budget, balanced over blocks."""
    if batch_size is not None:
        if int(batch_size) != batch_size or batch_size < 1:
            raise ValueError(f"batch_size must be a positive integer, got {batch_size!r}")
        return int(min(batch_size, num_points))
    if memory_budget_mb <= 0:
        raise ValueError(f"memory_budget_mb must be positive, got {memory_budget_mb!r}")
    edge = max(1, int((memory_budget_mb * 2**20 / _BYTES_PER_BLOCK_ELEMENT) ** 0.5))
    num_blocks = -(-num_points // edge)
    return -(-num_points // num_blocks)


def _rows_per_chunk(dim: int) -> int:
    return max(1, 2**22 // max(1, dim))  # rows per float64 chunk (32 MiB)


def power_of_two_scale(point_sets: Sequence[tuple[str, np.ndarray]], shift: np.ndarray) -> float:
    """The power of two that brings the largest ``|x - shift|`` coordinate into ``[0.5, 1)`` (1 when all are 0).

    Scaling by a power of two is exact and keeps every comparison of distances, so the float32 products work on
    values of order 1 whatever the samples' magnitude. Raises a ``ValueError`` when squared distances would overflow
    float64, where no exact answer exists.
    """
    largest = 0.0
    for _, points in point_sets:
        # Rounding is monotone, so the largest |x - shift| of a column is that of its largest or smallest value.
        above = points.max(0).astype(np.float64) - shift
        below = shift - points.min(0).astype(np.float64)
        largest = max(largest, float(np.maximum(above, below).max()))
    dim = point_sets[0][1].shape[1]
    limit = float(np.sqrt(np.finfo(np.float64).max / (16 * dim)))
    if largest > limit:
        names = " and ".join(name for name, _ in point_sets)
        raise ValueError(
            f"{names} samples lie up to {largest:.3g} from the real mean: their squared distances would "
            f"overflow float64 (the limit for {dim} values per sample is {limit:.3g}); rescale the samples"
        )
    return 1.0 if largest == 0 else float(np.ldexp(1.0, -np.frexp(largest)[1]))


def prepare(points: np.ndarray, shift: np.ndarray, scale: float, device: torch.device) -> _PreparedSet:
    """Move a ``(N, D)`` point set to ``device``, translate it by ``-shift`` and scale it by ``scale`` (a power of two;
    in float64, then rounded to float32)."""
    original = torch.as_tensor(points, device=device)
    shift_t = torch.as_tensor(shift, dtype=torch.float64, device=device)
    centred = torch.empty(original.shape, dtype=torch.float32, device=device)
    sq_norms = torch.empty(len(original), dtype=torch.float32, device=device)
    step = _rows_per_chunk(original.shape[1])
    buffer = torch.empty(min(step, len(original)), original.shape[1], dtype=torch.float64, device=device)
    for start in range(0, len(original), step):
        chunk = original[start : start + step]
        work = torch.sub(chunk, shift_t, out=buffer[: len(chunk)]).mul_(scale)
        centred[start : start + step] = work
        sq_norms[start : start + step] = work.copy_(centred[start : start + step]).square_().sum(1)
    return _PreparedSet(original, centred, sq_norms, scale * scale)


def _float32_tolerance(dim: int) -> float:
    # Error bound of a float32 squared distance |x|^2 + |y|^2 - 2 x.y, relative to |x|^2 + |y|^2: the dot
    # products (gamma_D each) plus the rounding of the centred inputs and of the additions.
    return (2 * dim + 16) * _U32


def _float32_floor(dim: int) -> float:
    # The same operations' absolute error bound where their results fall in float32's subnormal range.
    return (2 * dim + 16) * _SUBNORMAL32


def _pair_factors(
    a: _PreparedSet, a_offset: torch.Tensor, b: _PreparedSet, b_offset: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Factors with ``left[i] . right[j] = a_offset[i] + b_offset[j] - 2 a_i . b_j``.

    One float32 matrix product of blocks of these factors gives a block of squared distances (offsets ``|x|^2``)
    or of margins, without any further pass over the block.
    """
    left = torch.cat([a.centred, a_offset[:, None], torch.ones_like(a_offset)[:, None]], dim=1)
    right = torch.cat([-2.0 * b.centred, torch.ones_like(b_offset)[:, None], b_offset[:, None]], dim=1)
    return left, right


def _direct_sq_pairs(a: torch.Tensor, b: torch.Tensor, a_rows: torch.Tensor, b_rows: torch.Tensor, chunk: int) -> torch.Tensor:
    """Float64 squared distances ``|a[a_rows[p]] - b[b_rows[p]]|^2`` as the direct sum of squared differences."""
    out = torch.empty(len(a_rows), dtype=torch.float64, device=a.device)
    for p0 in range(0, len(a_rows), chunk):
        diff = a[a_rows[p0 : p0 + chunk]].double()  # a copy (indexing copies), so the in-place steps are safe
        out[p0 : p0 + chunk] = diff.sub_(b[b_rows[p0 : p0 + chunk]]).square_().sum(1)
    return out


def _kth_per_row(rows: torch.Tensor, values: torch.Tensor, num_rows: int, k: int | torch.Tensor) -> torch.Tensor:
    """The k-th smallest of ``values`` per row index in ``rows`` (every row index in range occurs at least k times);
    ``k`` is one rank for all rows or a ``(num_rows,)`` tensor of ranks."""
    order = torch.argsort(values, stable=True)
    order = order[torch.argsort(rows[order], stable=True)]
    counts = torch.bincount(rows, minlength=num_rows)
    starts = torch.cumsum(counts, 0) - counts
    return values[order][starts + k - 1]


def _row_chunk(block: int, num_others: int) -> int:
    # Rows recomputed at once against a whole set: a (rows, num_others) float32 buffer within the block budget.
    return max(1, block * block // num_others)


def _merge_nearest(
    block: torch.Tensor, row_start: int, col_start: int, values: torch.Tensor, indices: torch.Tensor, dims: tuple[int, ...]
) -> None:
    """Merge a contiguous block's smallest values per row (``1`` in ``dims``) and per column (``0``; both need a
    square block) into the running smallest ``values`` and their point ``indices``, ``(num_points, keep)`` each,
    sorted; the block's rows are the points from ``row_start``, its columns those from ``col_start``.

    A line's positions are split into ``length // _GROUP_SIZE`` interleaved groups (position ``p`` in group
    ``p % groups``, the last ``length % _GROUP_SIZE`` positions on their own): one reduction pass over the block,
    along its contiguous dimension, gives each group's minimum, a line's ``keep`` smallest values lie in its
    ``keep`` groups of smallest minimum and its own positions, and only those are ranked. Rows and columns are
    ranked together, so that a block costs a few passes whatever its shape.
    """
    keep = values.shape[1]
    device = block.device
    # Per dimension: its lines (a view of the block, one line per row), the points they are, the point of their
    # first position, and their rows in the stacked tensors below.
    line_sets = []
    num_lines = 0
    for dim in dims:
        lines = block if dim == 1 else block.T
        points = slice(row_start, row_start + len(lines)) if dim == 1 else slice(col_start, col_start + len(lines))
        line_sets.append((dim, lines, points, col_start if dim == 1 else row_start, slice(num_lines, num_lines + len(lines))))
        num_lines += len(lines)
    length = line_sets[0][1].shape[1]
    groups = length // _GROUP_SIZE
    if groups > 2 * keep:
        main = groups * _GROUP_SIZE
        group_min = torch.empty(num_lines, groups, device=device)
        for dim, _, _, _, stacked in line_sets:
            if dim == 1:  # the minimum runs over the middle dimension, along whole contiguous runs of groups
                torch.amin(block[:, :main].unflatten(1, (_GROUP_SIZE, groups)), 1, out=group_min[stacked])
            else:  # computed along the rows, then copied (written through a transposed view, it is slow)
                group_min[stacked] = block[:main].unflatten(0, (_GROUP_SIZE, groups)).amin(0).T
        chosen = torch.topk(group_min, keep, dim=1, largest=False, sorted=False).indices
        positions = torch.empty(num_lines, keep * _GROUP_SIZE + length - main, dtype=torch.long, device=device)
        members = torch.arange(0, main, groups, device=device)
        torch.add(chosen[:, :, None], members, out=positions[:, : keep * _GROUP_SIZE].view(-1, keep, _GROUP_SIZE))
        positions[:, keep * _GROUP_SIZE :] = torch.arange(main, length, device=device)
    else:
        positions = torch.arange(length, device=device).expand(num_lines, -1)
    candidates = torch.empty(positions.shape, device=device)
    for _, lines, _, _, stacked in line_sets:
        torch.gather(lines, 1, positions[stacked], out=candidates[stacked])
    best = torch.topk(candidates, min(keep, length), dim=1, largest=False)
    found = positions.gather(1, best.indices)
    for _, _, points, first_neighbour, stacked in line_sets:
        merged = torch.topk(torch.cat([values[points], best.values[stacked]], dim=1), keep, dim=1, largest=False)
        merged_indices = torch.cat([indices[points], found[stacked] + first_neighbour], dim=1)
        values[points] = merged.values
        indices[points] = merged_indices.gather(1, merged.indices)


def _exact_sq_radii_rows(
    points: _PreparedSet, factors: tuple[torch.Tensor, torch.Tensor], rows: torch.Tensor, k: int, tol: torch.Tensor, block: int
) -> torch.Tensor:
    """Exact squared k-th neighbour distances of ``rows``: every neighbour whose float32 value is within twice the
    error bound of the float32 k-th value is a candidate, and the candidates are compared by direct distances."""
    left, right = factors
    exact = torch.empty(len(rows), dtype=torch.float64, device=rows.device)
    step = _row_chunk(block, len(right))
    for r0 in range(0, len(rows), step):
        r = rows[r0 : r0 + step]
        sq = torch.mm(left[r], right.T)
        sq[torch.arange(len(r), device=sq.device), r] = torch.inf
        kth = torch.topk(sq, k, dim=1, largest=False).values[:, -1]
        r_idx, c_idx = (sq <= (kth + 2 * tol[r])[:, None]).nonzero(as_tuple=True)
        values = _direct_sq_pairs(points.original, points.original, r[r_idx], c_idx, step)
        exact[r0 : r0 + step] = _kth_per_row(r_idx, values, len(r), k)
    return exact


def squared_radii(points: _PreparedSet, k: int, block: int) -> torch.Tensor:
    """Exact squared distance of every point to its k-th nearest neighbour in its own set (own index excluded).

    One pass over the upper block triangle of the set's float32 distance matrix keeps the ``k + 2`` smallest
    values of each point (:func:`_merge_nearest`): each off-diagonal block serves its rows and its columns. When
    the last kept value is clear of the k-th by twice the error bound, the kept candidates hold every possible k-th
    neighbour and the direct distances of those near the k-th give the exact radius; other rows (rare: two more
    neighbours within the bound of the k-th) are recomputed (:func:`_exact_sq_radii_rows`).
    """
    n, dim = points.centred.shape
    keep = min(k + _EXTRA_CANDIDATES, n - 1)
    device = points.centred.device
    left, right = _pair_factors(points, points.sq_norms, points, points.sq_norms)
    values = torch.full((n, keep), torch.inf, device=device)
    indices = torch.full((n, keep), -1, dtype=torch.long, device=device)
    buffer = torch.empty(min(block, n) ** 2, device=device)  # one block's products, reused: no page faults per block
    for i0 in range(0, n, block):
        i1 = min(i0 + block, n)
        for j0 in range(i0, n, block):
            j1 = min(j0 + block, n)
            sq = torch.mm(left[i0:i1], right[j0:j1].T, out=buffer[: (i1 - i0) * (j1 - j0)].view(i1 - i0, j1 - j0))
            if j0 == i0:
                sq.fill_diagonal_(torch.inf)
                _merge_nearest(sq, i0, j0, values, indices, (1,))
            elif i1 - i0 == j1 - j0:
                _merge_nearest(sq, i0, j0, values, indices, (1, 0))
            else:
                _merge_nearest(sq, i0, j0, values, indices, (1,))
                _merge_nearest(sq, i0, j0, values, indices, (0,))
    del sq, buffer  # the memory budget goes to the recomputed rows
    tol = _float32_tolerance(dim) * (points.sq_norms + points.sq_norms.max()) + _float32_floor(dim)
    # Exact distances lie within tol of the float32 ones, so with V the k-th float32 value, the k-th exact one lies
    # in [V - tol, V + tol]: candidates below V - 2 tol are among the k nearest, those above V + 2 tol are not, and
    # the radius is the (k - below)-th smallest direct distance of the candidates in between. A row is certain when
    # its last candidate lies above V + 2 tol (or when it kept every other point).
    low = (values[:, k - 1] - 2 * tol)[:, None]
    high = (values[:, k - 1] + 2 * tol)[:, None]
    certain = values[:, -1] > high[:, 0] if keep < n - 1 else torch.ones(n, dtype=torch.bool, device=device)
    r_idx, c_idx = ((values >= low) & (values <= high)).nonzero(as_tuple=True)
    direct = _direct_sq_pairs(points.original, points.original, r_idx, indices[r_idx, c_idx], block)
    exact = _kth_per_row(r_idx, direct, n, k - (values < low).sum(1))
    rows = (~certain).nonzero(as_tuple=True)[0]
    if len(rows):
        exact[rows] = _exact_sq_radii_rows(points, (left, right), rows, k, tol, block)
    return exact


def _exact_inside(
    points: _PreparedSet,
    rows: torch.Tensor,
    factors: tuple[torch.Tensor, torch.Tensor],
    own_radii: torch.Tensor,
    others: _PreparedSet,
    other_sq_radii: torch.Tensor,
    tol: torch.Tensor,
    block: int,
) -> torch.Tensor:
    """Exact test of ``rows`` of ``points`` against the balls of ``others``: margins clear of 0 by the float32 bound
    ``tol`` decide, the others are settled by direct distances.

    ``factors`` are :func:`membership`'s (``points``' first): their products plus ``own_radii`` (float32 units) are
    the margins ``|x - y|^2 - radius(y)^2``, computed as :func:`membership`'s pass computes them.
    """
    own, other = factors
    inside = torch.zeros(len(rows), dtype=torch.bool, device=rows.device)
    step = _row_chunk(block, len(other))
    for r0 in range(0, len(rows), step):
        r = rows[r0 : r0 + step]
        margin = torch.mm(own[r], other.T).add_(own_radii[r, None])
        inside[r0 : r0 + step] = (margin < -tol[r, None]).any(1)
        r_idx, c_idx = (margin.abs() <= tol[r, None]).nonzero(as_tuple=True)
        direct = _direct_sq_pairs(points.original, others.original, r[r_idx], c_idx, step)
        inside[r0 + r_idx[direct <= other_sq_radii[c_idx]]] = True
    return inside


def membership(
    real: _PreparedSet, real_sq_radii: torch.Tensor, generated: _PreparedSet, generated_sq_radii: torch.Tensor, block: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Which generated samples lie in the real manifold and which real samples lie in the generated one.

    One pass over the real-generated float32 blocks keeps, for each sample, the smallest margin
    ``|x - y|^2 - radius^2`` over the other set; samples whose margin is within the error bound of 0 are
    recomputed and their borderline pairs settled by direct distances (:func:`_exact_inside`).

    :return: ``(generated_inside_real, real_inside_generated)`` boolean tensors
    """
    if real.sq_scale != generated.sq_scale:
        raise ValueError("both point sets must be prepared with the same scale")
    n_real, n_gen = real.centred.shape[0], generated.centred.shape[0]
    device = real.centred.device
    r_real = (real_sq_radii * real.sq_scale).float()  # in the units of the float32 values
    r_gen = (generated_sq_radii * generated.sq_scale).float()
    # Real row i, generated column j: q = |x_i - y_j|^2 - r_real_i - r_gen_j, so that the smallest q of a column
    # plus r_gen_j is that generated sample's margin and the smallest q of a row plus r_real_i the real one's.
    left, right = _pair_factors(real, real.sq_norms - r_real, generated, generated.sq_norms - r_gen)
    gen_margin = torch.full((n_gen,), torch.inf, device=device)
    real_margin = torch.full((n_real,), torch.inf, device=device)
    buffer = torch.empty(min(block, n_real) * min(block, n_gen), device=device)
    for i0 in range(0, n_real, block):
        i1 = min(i0 + block, n_real)
        for j0 in range(0, n_gen, block):
            j1 = min(j0 + block, n_gen)
            q = torch.mm(left[i0:i1], right[j0:j1].T, out=buffer[: (i1 - i0) * (j1 - j0)].view(i1 - i0, j1 - j0))
            torch.minimum(gen_margin[j0:j1], q.amin(0), out=gen_margin[j0:j1])
            torch.minimum(real_margin[i0:i1], q.amin(1), out=real_margin[i0:i1])
    del q, buffer  # the memory budget goes to the borderline rows
    gen_margin += r_gen
    real_margin += r_real
    results = []
    for points, margin, factors, own_radii, others, other_radii in (
        (generated, gen_margin, (right, left), r_gen, real, real_sq_radii),
        (real, real_margin, (left, right), r_real, generated, generated_sq_radii),
    ):
        dim = points.centred.shape[1]
        tol = _float32_tolerance(dim) * (
            points.sq_norms + own_radii + others.sq_norms.max() + (other_radii.max() * others.sq_scale).float()
        ) + _float32_floor(dim)
        inside = margin < -tol
        rows = (margin.abs() <= tol).nonzero(as_tuple=True)[0]
        if len(rows):
            inside[rows] = _exact_inside(points, rows, factors, own_radii, others, other_radii, tol, block)
        results.append(inside)
    return results[0], results[1]


def _checked_sets(real: np.ndarray, generated: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Check :func:`precision_recall`'s sets and ``k``; return the real and generated ``(N, D)`` points and ``k``."""
    real_points = as_points(real, "real")
    gen_points = as_points(generated, "generated")
    if real_points.shape[1] != gen_points.shape[1]:
        raise ValueError(
            f"real and generated samples must have the same size, got {real_points.shape[1]} "
            f"and {gen_points.shape[1]} values per sample"
        )
    if int(k) != k or k < 1:
        raise ValueError(f"k must be a positive integer, got {k!r}")
    k = int(k)
    smallest = min(len(real_points), len(gen_points))
    if k >= smallest:
        raise ValueError(
            f"k must be smaller than both set sizes (a point is not its own neighbour), got k={k} "
            f"with {len(real_points)} real and {len(gen_points)} generated samples"
        )
    return real_points, gen_points, k


def prepared_sets(
    real: np.ndarray,
    generated: np.ndarray,
    k: int,
    batch_size: int | None,
    device: torch.device | str,
    memory_budget_mb: float,
) -> tuple[_PreparedSet, _PreparedSet, int, int]:
    """Both sets checked (:func:`_checked_sets`), centred on the real mean and scaled by one power of two, on the
    device; with ``k`` as an int and the edge length of the distance blocks."""
    real_points, gen_points, k = _checked_sets(real, generated, k)
    torch_device = get_device(device)
    block = block_size(max(len(real_points), len(gen_points)), batch_size, memory_budget_mb)
    shift = real_points.mean(0, dtype=np.float64)
    scale = power_of_two_scale((("real", real_points), ("generated", gen_points)), shift)
    return prepare(real_points, shift, scale, torch_device), prepare(gen_points, shift, scale, torch_device), k, block


def precision_recall(
    real: np.ndarray,
    generated: np.ndarray,
    k: int = 3,
    *,
    batch_size: int | None = None,
    device: torch.device | str = "auto",
    return_radii: bool = False,
    memory_budget_mb: float = DEFAULT_MEMORY_BUDGET_MB,
) -> PrecisionRecall:
    """Improved precision and recall (Kynkaanniemi et al. 2019) of ``generated`` against ``real``, exactly.

    A sample's radius is the distance to its ``k``-th nearest neighbour in its own set, excluding exactly the
    sample's own index: a duplicate of the sample counts as a neighbour at distance 0 (so ``k`` copies of a
    point give it radius 0). A sample is inside the other set's manifold when its distance to at least one point of
    that set is ``<=`` that point's radius: ties count as inside, as in the original implementation (the ``prdc``
    package uses ``<`` instead, which differs only on exact ties).

    Float precision: blocks are computed in float32 as ``|x|^2 + |y|^2 - 2 x.y^T`` after centring both sets on
    the real set's mean and scaling them by a power of two (largest coordinate in ``[0.5, 1)``; exact, and it keeps
    every comparison), so any magnitude works whose squared distances fit in float64 (larger values raise a
    ``ValueError``). Each float32 value is within a worst-case rounding bound (``(2D + 16) * 2**-24`` times
    ``|x|^2 + |y|^2``, plus the radii for margins) of the exact one. Every comparison that this bound leaves open (a
    radius whose k-th and (k+1)-th float32 candidates are that close, a sample whose margin to a ball is that
    close to 0) is settled with the direct float64 sum of squared differences of the original values. Results
    therefore equal a float64 brute force computation, exact ties and duplicates included; only the few borderline
    samples (typically a few percent) cost extra work.

    Memory: square blocks of ``batch_size`` rows and columns (by default the largest fitting
    ``memory_budget_mb``) are streamed; the memory used does not grow with ``N^2``.

    :param real: real samples ``(N, D)`` or ``(N, T, M)`` (flattened per sample)
    :param generated: generated samples with the same per-sample size
    :param k: neighbourhood size (paper: 3), ``1 <= k < min(len(real), len(generated))``
    :param batch_size: edge length of the distance blocks; ``None`` chooses it from ``memory_budget_mb``
    :param device: torch device; ``"auto"`` uses a GPU when there is one
    :param return_radii: also return the k-th neighbour distances of both sets
    :param memory_budget_mb: memory for the distance blocks in MiB, used when ``batch_size`` is ``None``
    :return: a :class:`PrecisionRecall`
    """
    real_set, gen_set, k, block = prepared_sets(real, generated, k, batch_size, device, memory_budget_mb)
    with torch.no_grad():
        real_radii = squared_radii(real_set, k, block)
        gen_radii = squared_radii(gen_set, k, block)
        gen_inside, real_inside = membership(real_set, real_radii, gen_set, gen_radii, block)
    return PrecisionRecall(
        precision=float(gen_inside.double().mean()),
        recall=float(real_inside.double().mean()),
        k=int(k),
        num_real=len(real_set.original),
        num_generated=len(gen_set.original),
        real_radii=real_radii.sqrt().cpu().numpy() if return_radii else None,
        generated_radii=gen_radii.sqrt().cpu().numpy() if return_radii else None,
    )
