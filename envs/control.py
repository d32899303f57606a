"""The arm's control and the stability test, as pure functions on arrays: the commanded joint positions of each
control and physics step, and whether a simulation's sensor readings show it went unstable."""

from __future__ import annotations

import os

import numpy as np
from sb3_genrl.envs.arm import JOINT_RANGE

# Limits beyond which a simulation counts as unstable (the arm's joints and the task object): far above what any
# commanded motion produces (bang-bang commands at the action bounds stay below 80 rad/s), reached only when the
# integration diverges.
MAX_JOINT_SPEED = 200.0  # rad/s
MAX_OBJECT_SPEED = 100.0  # m/s


def next_command(command: np.ndarray, delta: np.ndarray, max_delta: float) -> tuple[np.ndarray, np.ndarray]:
    """Add per-step deltas (clipped to the action box) to the commanded joint positions, within the joint limits.

    :return: the new commands ``(B, 7)`` and, per row, whether the action box or a joint limit clipped it
    """
    step = np.clip(delta, -max_delta, max_delta)
    target = command + step
    new = np.clip(target, JOINT_RANGE[:, 0], JOINT_RANGE[:, 1])
    clipped = np.any(step != delta, axis=1) | np.any(new != target, axis=1)
    return new, clipped


def ramp(previous: np.ndarray, new: np.ndarray, frame_skip: int) -> np.ndarray:
    """Commanded positions of each physics step: a linear ramp from ``previous`` to ``new`` over a control step,
    as a robot's joint interpolator does. ``(..., 7)`` inputs give ``(..., frame_skip, 7)``."""
    fraction = np.arange(1, frame_skip + 1, dtype=np.float64) / frame_skip
    return previous[..., None, :] + fraction[:, None] * (new - previous)[..., None, :]


def unstable_rows(rows: np.ndarray) -> np.ndarray:
    """Per row: non-finite readings, the clock running backwards (MuJoCo reset a diverged state), or runaway speeds."""
    rows = np.asarray(rows)
    bad = ~np.all(np.isfinite(rows), axis=1)
    clock = rows[:, 0]
    bad[1:] |= np.diff(clock) <= 0
    bad |= np.abs(rows[:, 7:14]).max(axis=1, initial=0.0) > MAX_JOINT_SPEED
    bad |= np.linalg.norm(rows[:, 4:7], axis=1) > MAX_OBJECT_SPEED
    return bad


def is_unstable(rows: np.ndarray) -> bool:
    """Whether any row of sensor readings shows that the simulation went unstable (see :func:`unstable_rows`)."""
    return bool(unstable_rows(rows).any())


def default_threads() -> int:
    """The cores this process may run on (the default number of simulation threads)."""
    return max(1, len(os.sched_getaffinity(0)))
