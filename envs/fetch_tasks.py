"""Gymnasium-Robotics' four Fetch tasks as tasks of the package (:class:`~sb3_genrl.envs.spec.TaskSpec`): the envs
and experts of :mod:`sb3_genrl.envs.fetch` with the demonstrations and the evaluation of
:mod:`sb3_genrl.envs.demonstrations.fetch`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from sb3_genrl.envs.demonstrations.fetch import evaluate_success, make_arrays
from sb3_genrl.envs.fetch import (
    FAMILIES,
    FETCH_ACTION_DIM,
    FETCH_HORIZON,
    GOAL_BOXES,
    PERTURBATION,
    is_valid,
    make_fetch_pick_and_place,
    make_fetch_push,
    make_fetch_reach,
    make_fetch_slide,
)
from sb3_genrl.envs.spec import TaskSpec


def _task(name: str, short: str, maker: Callable[..., Any]) -> TaskSpec:
    low, high = (np.asarray(corner, dtype=np.float64) for corner in GOAL_BOXES[name])

    def in_goal_region(points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        return np.all((points >= low) & (points <= high), axis=1)

    family = FAMILIES[name]
    return TaskSpec(
        name=short,
        env_id=family.env_id,
        env_class=maker,
        horizon=FETCH_HORIZON,
        goal_low=low,
        goal_high=high,
        in_goal_region=in_goal_region,
        cell_size=0.03 if name == "Slide" else 0.02,
        sample_expert=family.expert,
        perturbation_scales=PERTURBATION,
        is_valid=is_valid,
        action_dim=FETCH_ACTION_DIM,
        demonstrations=make_arrays,
        evaluate=evaluate_success,
        generator_preset="VAE-FETCH",
        video=False,
        demonstration_recipe={"aim_margin": family.aim_margin},
    )


TASKS = (
    _task("Reach", "fetch-reach", make_fetch_reach),
    _task("Push", "fetch-push", make_fetch_push),
    _task("Slide", "fetch-slide", make_fetch_slide),
    _task("PickAndPlace", "fetch-pick-and-place", make_fetch_pick_and_place),
)
