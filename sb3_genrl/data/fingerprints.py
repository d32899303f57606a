"""Short hashes that tie a result to the exact inputs it used: a generator to its demonstrations, a policy to its
generator."""

from __future__ import annotations

import hashlib
import os

import numpy as np

from sb3_genrl.data.minari_io import load_actions


def dataset_fingerprint(dataset: str | os.PathLike) -> str:
    """A short hash of a demonstration dataset's action trajectories (the generators' training data).

    :param dataset: the dataset directory
    """
    actions = load_actions(dataset)
    digest = hashlib.sha256(f"{actions.shape}{actions.dtype}".encode())
    digest.update(np.ascontiguousarray(actions).tobytes())
    return digest.hexdigest()[:16]


def file_fingerprint(path: str | os.PathLike) -> str:
    """A short hash of a file's bytes (a generator, a policy).

    :param path: the file
    """
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()[:16]
