"""Hand-written base motions of the two tasks: a hit and a throw, as ``(horizon, 7)`` joint position deltas.

They are the scripted expert's motions: smooth in joint space (each phase is a raised-cosine velocity profile),
parametrised by a strength and a direction. The demonstration generator perturbs them.
"""

from __future__ import annotations

import numpy as np
from sb3_genrl.envs.basketball import BASKETBALL_HORIZON
from sb3_genrl.envs.hockey import HOCKEY_HORIZON


def bump(length: int, start: int, duration: int, total: float) -> np.ndarray:
    """Per-step increments that move a joint by ``total`` over ``duration`` steps with a raised-cosine velocity."""
    out = np.zeros(length)
    if duration <= 0:
        return out
    weights = 1.0 - np.cos(2.0 * np.pi * (np.arange(duration) + 0.5) / duration)
    end = min(length, start + duration)
    out[start:end] = (total * weights / weights.sum())[: end - start]
    return out


def scripted_hit(*, strength: float = 1.0, direction: float = 0.0, swing_start: int = 25) -> np.ndarray:
    """A hockey hit: turn the swing plane by ``direction`` (rad, forearm roll), wind up the wrist, swing through.

    :param strength: scales the swing's amplitude and speed; 0.75-1.3 sends the puck to x = 0.65-1.3 m, weaker hits
        fall short of the goal region
    :param direction: the shot's angle (rad) from the x axis, positive to the robot's right (negative y)
    :param swing_start: control step at which the forward swing starts
    """
    trajectory = np.zeros((HOCKEY_HORIZON, 7))
    trajectory[:, 4] = bump(HOCKEY_HORIZON, 4, 8, direction)
    backswing = 0.35 * strength
    trajectory[:, 5] = bump(HOCKEY_HORIZON, 10, 10, backswing)
    trajectory[:, 5] += bump(HOCKEY_HORIZON, swing_start, 6, -2 * backswing)  # through the puck
    trajectory[:, 5] += bump(HOCKEY_HORIZON, swing_start + 10, 12, backswing)  # back to vertical, slowly
    return trajectory


def scripted_throw(*, strength: float = 1.0, yaw: float = 0.0, throw_start: int = 20) -> np.ndarray:
    """A basketball throw: turn the base by ``yaw`` (rad), then swing shoulder, elbow and wrist forward fast.

    :param strength: scales the swing's amplitude (and so its speed)
    :param yaw: base rotation, positive turns the throw to the robot's left (positive y)
    :param throw_start: control step at which the swing starts
    """
    trajectory = np.zeros((BASKETBALL_HORIZON, 7))
    trajectory[:, 0] = bump(BASKETBALL_HORIZON, 2, 12, yaw)
    for joint, total in zip((1, 3, 5), (1.0, 0.8, 0.4), strict=True):
        trajectory[:, joint] = bump(BASKETBALL_HORIZON, throw_start, 6, total * strength)
    return trajectory
