"""Training helpers shared by every generative model: data checks, held-out split, normalisation, model selection.

These are pure array-in/array-out functions; the epoch loop that uses them lives in
:class:`~sb3_genrl.generative.torch_generator.TorchTrajectoryGenerator`.
"""

from __future__ import annotations

import math

import numpy as np

# A joint whose training actions never change gets a unit scale instead of a zero one.
MIN_STD = 1e-6  # floor of the normalisation's standard deviation (raw action units)
# Default floor of each entry's normalisation std, as a fraction of the largest entry's (see normalisation_statistics).
STD_FLOOR = 0.05


def check_trajectories(trajectories: np.ndarray, horizon: int, action_dim: int) -> np.ndarray:
    """Return ``trajectories`` as a finite ``(N, horizon, action_dim)`` float32 array or raise a ``ValueError``.

    :param trajectories: motor trajectories, one per row, in raw action units
    :param horizon: expected number of time steps ``T``
    :param action_dim: expected number of joints ``M``
    """
    array = np.asarray(trajectories)
    if not np.issubdtype(array.dtype, np.number):
        raise ValueError(f"trajectories must be a numeric array, got dtype {array.dtype}")
    if array.ndim != 3 or array.shape[1:] != (horizon, action_dim):
        raise ValueError(
            f"trajectories must have shape (N, {horizon}, {action_dim}) (N, horizon, action_dim), got {array.shape}"
        )
    if array.shape[0] < 2:
        raise ValueError(f"at least 2 trajectories are needed for training, got {array.shape[0]}")
    if not np.all(np.isfinite(array)):
        raise ValueError("trajectories contain non-finite values (nan or inf)")
    return array.astype(np.float32, copy=False)


def split_train_validation(
    trajectories: np.ndarray, validation_fraction: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Randomly split trajectories into a training set and a held-out set used for model selection.

    :param trajectories: ``(N, T, M)`` array
    :param validation_fraction: fraction of the trajectories held out, in ``[0, 1)``; at least one trajectory is held
        out when it is positive, and at least two are kept for training
    :param rng: random generator drawing the permutation
    :return: ``(train, held_out)``; ``held_out`` has zero rows when ``validation_fraction`` is 0
    """
    if not 0.0 <= validation_fraction < 1.0:
        raise ValueError(f"validation_fraction must be in [0, 1), got {validation_fraction}")
    n = len(trajectories)
    n_held_out = int(round(validation_fraction * n))
    if validation_fraction > 0:
        n_held_out = max(n_held_out, 1)
    if n - n_held_out < 2:
        raise ValueError(
            f"validation_fraction={validation_fraction} leaves {n - n_held_out} of {n} trajectories for "
            "training; at least 2 are needed"
        )
    permutation = rng.permutation(n)
    return trajectories[permutation[n_held_out:]], trajectories[permutation[:n_held_out]]


def normalisation_statistics(trajectories: np.ndarray, std_floor: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of every (time step, joint) entry over the trajectories.

    The models see ``(tau - mean) / std`` entry by entry, so each output is learnt on the scale of its own
    spread. ``std_floor`` bounds each std from below by that fraction of the largest one: an entry that varies
    much less than the motion (noise on a joint held still) then stays small after normalisation instead of
    weighing as much as the motion in the models' losses. An entry that never varies gets at least
    ``std = MIN_STD`` and is reproduced exactly.

    :param trajectories: ``(N, T, M)`` array
    :param std_floor: floor of each std as a fraction of the largest, in ``[0, 1]``
    :return: ``(mean, std)``, two float32 arrays of shape ``(T, M)``
    """
    if not 0.0 <= std_floor <= 1.0:
        raise ValueError(f"std_floor must be in [0, 1], got {std_floor!r}")
    mean = trajectories.mean(axis=0, dtype=np.float64)
    std = trajectories.std(axis=0, dtype=np.float64)
    std = np.maximum(std, max(std_floor * float(std.max()), MIN_STD))
    return mean.astype(np.float32), std.astype(np.float32)


def selection_mse(generated: np.ndarray, reference: np.ndarray, chunk_size: int = 1024) -> float:
    """Model-selection error of paper appendix B: mean squared error between generated trajectories and their nearest
    reference (held-out) trajectories.

    Each generated trajectory is matched to the reference trajectory with the smallest Euclidean distance over the
    flattened trajectory; the result is the squared error per element, averaged over elements and generated
    trajectories.

    :param generated: ``(n, T, M)`` generated trajectories
    :param reference: ``(m, T, M)`` held-out trajectories, same units as ``generated``
    :param chunk_size: reference trajectories compared at once (bounds memory)
    """
    generated = np.asarray(generated, dtype=np.float64).reshape(len(generated), -1)
    reference = np.asarray(reference, dtype=np.float64).reshape(len(reference), -1)
    if generated.shape[1] != reference.shape[1] or len(generated) == 0 or len(reference) == 0:
        raise ValueError(f"need non-empty trajectory sets of equal size, got {generated.shape} and {reference.shape}")
    best = np.full(len(generated), np.inf)
    generated_norms = np.sum(generated**2, axis=1)
    for start in range(0, len(reference), chunk_size):
        chunk = reference[start : start + chunk_size]
        squared = generated_norms[:, None] - 2.0 * generated @ chunk.T + np.sum(chunk**2, axis=1)[None, :]
        best = np.minimum(best, squared.min(axis=1))
    return float(np.maximum(best, 0.0).mean() / generated.shape[1])


def minibatch_indices(n: int, batch_size: int, permutation: np.ndarray, *, even: bool = False) -> list[np.ndarray]:
    """Split a permutation of ``range(n)`` into minibatches of ``batch_size`` and a remainder, dropping a last batch of
    one (batch norm needs two); ``even``: into as many batches, of sizes that differ by at most one."""
    if batch_size < 2:
        raise ValueError(f"batch_size must be at least 2 (batch normalisation), got {batch_size}")
    if even:
        return [batch for batch in np.array_split(permutation[:n], math.ceil(n / batch_size)) if len(batch) >= 2]
    batches = [permutation[start : start + batch_size] for start in range(0, n, batch_size)]
    return [batch for batch in batches if len(batch) >= 2]
