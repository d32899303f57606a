"""How well a set of demonstrations covers a task's goal region: a share of covered cells, a JSON file and a plot.

The goal region is cut into square cells (hockey 5 cm, basketball 25 cm); the cells whose centres lie inside the
region count. A cell is covered when some demonstration's reached point lies within one cell size of its centre.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from sb3_genrl.envs.basketball import BASKET_ANGLE_RANGE, BASKET_RADIUS_RANGE
from sb3_genrl.envs.hockey import HOCKEY_GOAL_HIGH, HOCKEY_GOAL_LOW
from scipy.spatial import cKDTree

CELL_SIZE = {"hockey": 0.05, "basketball": 0.25}  # m


def in_goal_region(points: np.ndarray, task: str) -> np.ndarray:
    """Per point ``(x, y)``: whether it lies in the task's goal region (hockey rectangle, basketball half-annulus)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if task == "hockey":
        return np.all((points >= HOCKEY_GOAL_LOW) & (points <= HOCKEY_GOAL_HIGH), axis=1)
    if task == "basketball":
        radius = np.linalg.norm(points, axis=1)
        angle = np.arctan2(points[:, 1], points[:, 0])
        return ((radius >= BASKET_RADIUS_RANGE[0]) & (radius <= BASKET_RADIUS_RANGE[1])
                & (angle >= BASKET_ANGLE_RANGE[0]) & (angle <= BASKET_ANGLE_RANGE[1]))
    raise ValueError(f"unknown task {task!r}; expected 'hockey' or 'basketball'")


def region_cells(task: str) -> np.ndarray:
    """Centres ``(K, 2)`` of the grid cells (size :data:`CELL_SIZE`) that lie inside the task's goal region."""
    if task not in CELL_SIZE:
        raise ValueError(f"unknown task {task!r}; expected one of {sorted(CELL_SIZE)}")
    cell = CELL_SIZE[task]
    if task == "hockey":
        low, high = HOCKEY_GOAL_LOW, HOCKEY_GOAL_HIGH
    else:
        low, high = np.array([0.0, -BASKET_RADIUS_RANGE[1]]), np.array([BASKET_RADIUS_RANGE[1]] * 2)
    counts = np.round((high - low) / cell).astype(int)
    xs = low[0] + (np.arange(counts[0]) + 0.5) * cell
    ys = low[1] + (np.arange(counts[1]) + 0.5) * cell
    centres = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    return centres[in_goal_region(centres, task)]


def covered_cells(reached: np.ndarray, task: str) -> np.ndarray:
    """Per cell of :func:`region_cells`: whether some reached point lies within one cell size of its centre."""
    centres = region_cells(task)
    reached = np.asarray(reached, dtype=np.float64).reshape(-1, 2)
    reached = reached[np.all(np.isfinite(reached), axis=1)]
    if len(reached) == 0:
        return np.zeros(len(centres), dtype=bool)
    distance, _ = cKDTree(reached).query(centres, k=1)
    return distance <= CELL_SIZE[task]


def coverage_fraction(reached: np.ndarray, task: str) -> float:
    """Share of the goal region's cells covered by the reached points (see the module docstring)."""
    return float(covered_cells(reached, task).mean())


def coverage_report(source: np.ndarray | str | os.PathLike[str], task: str | None, out_dir: str | os.PathLike[str],
                    ) -> dict[str, Any]:
    """Write ``coverage.json`` and ``coverage.png`` (reached points over the goal region) into ``out_dir``.

    :param source: a dataset directory or the reached points ``(N, 2)``
    :param task: ``"hockey"`` or ``"basketball"``; read from the dataset when None
    :param out_dir: where to write the two files (created if needed)
    :return: the report: ``task``, ``episodes``, ``cell_size``, ``cells``, ``covered_cells``, ``coverage``,
        ``in_region`` (share of reached points inside the region) and the two file paths
    """
    if isinstance(source, str | os.PathLike):
        from sb3_genrl.data import dataset_info, load_reached

        info = dataset_info(source)
        if task is not None and task != info["task"]:
            raise ValueError(f"dataset {str(source)!r} holds task {info['task']!r}, not {task!r}")
        task, reached = info["task"], load_reached(source)
    else:
        reached = np.asarray(source, dtype=np.float64).reshape(-1, 2)
    if task not in CELL_SIZE:
        raise ValueError(f"unknown task {task!r}; expected one of {sorted(CELL_SIZE)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    covered = covered_cells(reached, task)
    report = {"task": task, "episodes": int(len(reached)), "cell_size": CELL_SIZE[task], "cells": int(len(covered)),
              "covered_cells": int(covered.sum()), "coverage": float(covered.mean()),
              "in_region": float(in_goal_region(reached, task).mean()) if len(reached) else 0.0,
              "json": str(out_dir / "coverage.json"), "png": str(out_dir / "coverage.png")}
    _plot(reached, task, covered, out_dir / "coverage.png", report["coverage"])
    (out_dir / "coverage.json").write_text(json.dumps(report, indent=1))
    return report


def _plot(reached: np.ndarray, task: str, covered: np.ndarray, path: Path, coverage: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle, Wedge

    centres = region_cells(task)
    figure, axes = plt.subplots(figsize=(6, 6) if task == "hockey" else (6, 8))
    shown = reached[np.random.default_rng(0).permutation(len(reached))[:20000]] if len(reached) > 20000 else reached
    axes.scatter(shown[:, 0], shown[:, 1], s=1, alpha=0.3, color="tab:blue", label="reached")
    axes.scatter(*centres[~covered].T, s=8, marker="x", color="tab:red", label="uncovered cell")
    if task == "hockey":
        size = HOCKEY_GOAL_HIGH - HOCKEY_GOAL_LOW
        axes.add_patch(Rectangle(tuple(HOCKEY_GOAL_LOW), size[0], size[1], fill=False, color="k", label="goal region"))
    else:
        axes.add_patch(Wedge((0, 0), BASKET_RADIUS_RANGE[1], np.degrees(BASKET_ANGLE_RANGE[0]),
                             np.degrees(BASKET_ANGLE_RANGE[1]), width=BASKET_RADIUS_RANGE[1] - BASKET_RADIUS_RANGE[0],
                             fill=False, color="k", label="goal region"))
    axes.set_aspect("equal")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_title(f"{task}: {len(reached)} demonstrations, {100 * coverage:.1f}% of cells covered", fontsize=10)
    axes.legend(loc="upper right", fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)
