"""Demonstration datasets (Minari directories) and their loaders: action arrays for the generators, transitions
for the PPO and SAC baselines."""

from sb3_genrl.data.minari_io import (
    dataset_info,
    load_actions,
    load_arrays,
    load_reached,
    load_transitions,
    read_metadata,
    write_dataset,
)
from sb3_genrl.data.trajectories import load_trajectories

__all__ = [
    "dataset_info",
    "load_actions",
    "load_arrays",
    "load_reached",
    "load_trajectories",
    "load_transitions",
    "read_metadata",
    "write_dataset",
]
