"""Tests of sb3_genrl.metrics.density_coverage against a float64 brute force and against the ``prdc`` package."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import cdist
from test_metrics import POINT_SETS, point_sets

from sb3_genrl.metrics import density_coverage


def brute_force(real: np.ndarray, generated: np.ndarray, k: int) -> tuple[float, float]:
    """Naeem et al. (2020), eq. 3-4, from full float64 distance matrices (own index excluded, ties inside)."""
    real = real.reshape(len(real), -1).astype(np.float64)
    generated = generated.reshape(len(generated), -1).astype(np.float64)
    own = cdist(real, real)
    np.fill_diagonal(own, np.inf)
    radii = np.sort(own, axis=1)[:, k - 1]
    inside = cdist(real, generated) <= radii[:, None]  # (real ball i, generated sample j)
    return float(inside.sum(0).mean() / k), float(inside.any(1).mean())


@pytest.mark.parametrize("kind", POINT_SETS)
@pytest.mark.parametrize("k", [1, 3, 5])
def test_density_coverage_matches_brute_force(kind: str, k: int) -> None:
    real, generated = point_sets(kind, np.random.default_rng(10 + k))
    density, coverage = brute_force(real, generated, k)
    assert 0 < coverage  # the sets overlap: the comparison is not between zeros
    for batch_size in (1, 4, 17, None):
        result = density_coverage(real, generated, k, batch_size=batch_size, device="cpu")
        assert (result.density, result.coverage) == (density, coverage), (kind, batch_size, result)
        assert (result.k, result.num_real, result.num_generated) == (k, len(real), len(generated))


def test_density_coverage_equal_prdc() -> None:
    import prdc  # the reference implementation (the test extra installs it)

    rng = np.random.default_rng(0)
    real, generated = rng.normal(size=(300, 8)), rng.normal(0.2, 0.9, size=(250, 8))
    for k in (3, 5):
        expected = prdc.compute_prdc(real, generated, nearest_k=k)
        result = density_coverage(real, generated, k, device="cpu")
        assert result.density == pytest.approx(expected["density"], abs=1e-12)
        assert result.coverage == pytest.approx(expected["coverage"], abs=1e-12)


def test_density_and_coverage_of_known_cases() -> None:
    rng = np.random.default_rng(1)
    real = rng.normal(size=(80, 3))
    same = density_coverage(real, real.copy(), 3, device="cpu")
    assert same.coverage == 1.0  # each real ball holds its own centre
    far = density_coverage(real, real + 100.0, 3, device="cpu")
    assert (far.density, far.coverage) == (0.0, 0.0)
    # Generated samples crowded on one real sample: high density there, low coverage (a few balls hold them).
    crowded = density_coverage(real, np.repeat(real[:1], 40, axis=0), 3, device="cpu")
    assert crowded.coverage < 0.1 and crowded.density == pytest.approx(brute_force(real, real[[0] * 40], 3)[0])


def test_density_coverage_refuses_bad_inputs() -> None:
    real = np.zeros((10, 2))
    with pytest.raises(ValueError, match="same size"):
        density_coverage(real, np.zeros((10, 3)))
    with pytest.raises(ValueError, match="k must be smaller than both set sizes"):
        density_coverage(real, np.zeros((3, 2)), k=3)
    with pytest.raises(ValueError, match="non-finite"):
        density_coverage(real, np.full((10, 2), np.nan))
