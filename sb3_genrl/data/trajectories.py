"""Motor trajectories ``(N, T, M)`` from an array, a ``.npy`` / ``.npz`` file or a demonstration dataset: the one
loader behind the generators' training (:func:`sb3_genrl.generative.train_generator`) and their evaluation
(:func:`sb3_genrl.metrics.evaluate_generators`)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from sb3_genrl.data.minari_io import load_actions

ARRAY_NAMES = ("actions", "trajectories")  # the arrays of a .npz file that are read when it holds several


def load_trajectories(data: np.ndarray | str | os.PathLike[str]) -> np.ndarray:
    """Motor trajectories ``(N, T, M)`` (N trajectories, horizon T, action dimension M).

    :param data: an array; a ``.npy`` file; a ``.npz`` file holding one array, or one named ``actions`` or
        ``trajectories``; or a demonstration dataset directory (its actions, :func:`sb3_genrl.data.load_actions`)
    :return: the trajectories (an array is returned as it is)
    """
    if not isinstance(data, str | os.PathLike):
        array = np.asarray(data)
    else:
        path = Path(data)
        if path.is_dir():
            array = load_actions(path)
        elif not path.exists():
            raise FileNotFoundError(f"no trajectories at {str(path)!r}: the path does not exist")
        elif path.suffix == ".npy":
            try:
                array = np.load(path, allow_pickle=False)
            except ValueError as error:  # an object array (which needs pickle), or not an array file
                raise ValueError(f"{str(path)!r} cannot be read as an array of trajectories: {error}") from None
        elif path.suffix == ".npz":
            array = _one_array(path)
        else:
            raise ValueError(f"{str(path)!r} is neither a demonstration dataset directory nor a .npy/.npz file")
    if array.ndim != 3:
        raise ValueError(f"trajectories must have shape (N, T, M) (N, horizon, action_dim), got {array.shape}")
    if array.dtype.kind not in "fiu":  # complex, boolean, text or object values are no actions
        raise ValueError(f"trajectories must hold real numbers, got dtype {array.dtype}")
    return array


def _one_array(path: Path) -> np.ndarray:
    with np.load(path, allow_pickle=False) as archive:
        names = list(archive.keys())
        name = names[0] if len(names) == 1 else next((key for key in ARRAY_NAMES if key in names), None)
        if name is None:
            raise ValueError(f"{str(path)!r} holds arrays {names}; expected one array or one named {ARRAY_NAMES}")
        return archive[name]
