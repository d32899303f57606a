"""A synthetic family of smooth motor trajectories with two known factors, for tests, examples and benchmarks."""

from __future__ import annotations

import numpy as np


def sine_ramp_basis(horizon: int, action_dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The two ``(T, M)`` shapes of the family: ``sin(2 pi t / T + phase_j)`` and ``t / T``.

    Joint ``j`` has phase ``phase_j = 2 pi j / M``.
    """
    time = np.arange(horizon, dtype=np.float64)[:, None] / horizon
    phases = 2.0 * np.pi * np.arange(action_dim, dtype=np.float64)[None, :] / action_dim
    sine = np.sin(2.0 * np.pi * time + phases)
    ramp = np.broadcast_to(time, (horizon, action_dim)).copy()
    return sine, ramp


def sine_ramp_trajectories(
    n: int,
    horizon: int,
    action_dim: int,
    rng: np.random.Generator | int | None,
    amplitude_range: tuple[float, float] = (0.5, 1.5),
    slope_range: tuple[float, float] = (-1.0, 1.0),
) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``tau[t, j] = a * sin(2 pi t / T + phase_j) + b * t / T`` with ``a`` and ``b`` uniform.

    :param n: number of trajectories
    :param horizon: time steps ``T``
    :param action_dim: joints ``M``
    :param rng: random generator or seed
    :param amplitude_range: range of the amplitude ``a``
    :param slope_range: range of the slope ``b``
    :return: ``(trajectories, factors)``: float32 ``(n, T, M)`` and the ``(n, 2)`` factors ``(a, b)``
    """
    rng = np.random.default_rng(rng)
    factors = np.stack([rng.uniform(*amplitude_range, size=n), rng.uniform(*slope_range, size=n)], axis=1)
    sine, ramp = sine_ramp_basis(horizon, action_dim)
    trajectories = factors[:, 0, None, None] * sine + factors[:, 1, None, None] * ramp
    return trajectories.astype(np.float32), factors
