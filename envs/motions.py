"""Building blocks of the scripted experts' motions, shared by every task.

A motion is a ``(horizon, 7)`` array of per-step joint position deltas; each phase of a scripted motion is a
raised-cosine velocity profile (:func:`bump`), so the motions are smooth in joint space.
"""

from __future__ import annotations

import numpy as np


def bump(length: int, start: int, duration: int, total: float) -> np.ndarray:
    """Per-step increments that move a joint by ``total`` over ``duration`` steps with a raised-cosine velocity.

    :param length: control steps of the motion
    :param start: first control step of the bump
    :param duration: control steps the bump lasts (cut at ``length``)
    :param total: joint travel of the whole bump (rad)
    :return: ``(length,)`` increments
    """
    out = np.zeros(length)
    if duration <= 0:
        return out
    weights = 1.0 - np.cos(2.0 * np.pi * (np.arange(duration) + 0.5) / duration)
    end = min(length, start + duration)
    out[start:end] = (total * weights / weights.sum())[: end - start]
    return out
