"""How well a set of demonstrations covers a task's goal region: a share of covered cells, a JSON file and a plot.

The goal region's bounding box is cut into square cells of the task's ``cell_size``; the cells whose centres lie
inside the region count. A cell is covered when some demonstration's reached point lies within one cell size of
its centre.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from sb3_genrl.envs.registry import get_task
from sb3_genrl.envs.spec import TaskSpec

from sb3_genrl.data import dataset_info, load_reached
from sb3_genrl.utils import atomic_path, atomic_write_json


def in_goal_region(points: np.ndarray, task: str | TaskSpec) -> np.ndarray:
    """Per point ``(x, y)``: whether it lies in the task's goal region.

    :param points: ``(N, 2)`` points (m)
    :param task: a task name from :data:`sb3_genrl.envs.TASKS` (or its spec)
    """
    return np.asarray(get_task(task).in_goal_region(np.asarray(points, dtype=np.float64).reshape(-1, 2)), dtype=bool)


def region_cells(task: str | TaskSpec) -> np.ndarray:
    """Centres ``(K, 2)`` of the grid cells (of the task's ``cell_size``) that lie inside the task's goal region."""
    spec = get_task(task)
    cell, low, high = spec.cell_size, np.asarray(spec.goal_low), np.asarray(spec.goal_high)
    counts = np.round((high - low) / cell).astype(int)
    xs = low[0] + (np.arange(counts[0]) + 0.5) * cell
    ys = low[1] + (np.arange(counts[1]) + 0.5) * cell
    centres = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    return centres[in_goal_region(centres, spec)]


def covered_cells(reached: np.ndarray, task: str | TaskSpec) -> np.ndarray:
    """Per cell of :func:`region_cells`: whether some reached point lies within one cell size of its centre."""
    from scipy.spatial import cKDTree  # scipy.spatial costs about 0.5 s; `import sb3_genrl` reaches this module

    spec = get_task(task)
    centres = region_cells(spec)
    reached = np.asarray(reached, dtype=np.float64).reshape(-1, 2)
    reached = reached[np.all(np.isfinite(reached), axis=1)]
    if len(reached) == 0:
        return np.zeros(len(centres), dtype=bool)
    distance, _ = cKDTree(reached).query(centres, k=1)
    return distance <= spec.cell_size


def coverage_fraction(reached: np.ndarray, task: str | TaskSpec) -> float:
    """Share of the goal region's cells covered by the reached points (see the module docstring)."""
    return float(covered_cells(reached, task).mean())


def coverage_report(
    source: np.ndarray | str | os.PathLike[str],
    task: str | TaskSpec | None,
    out_dir: str | os.PathLike[str],
    *,
    final_dir: str | os.PathLike[str] | None = None,
) -> dict[str, Any]:
    """Write ``coverage.json`` and ``coverage.png`` (reached points over the goal region) into ``out_dir``.

    :param source: a dataset directory or the reached points ``(N, 2)``
    :param task: a task name from :data:`sb3_genrl.envs.TASKS` (or its spec); read from the dataset when None
    :param out_dir: where to write the two files (created if needed)
    :param final_dir: the folder the report names as the files' location (default ``out_dir``), for a report
        written into a temporary folder that is renamed to ``final_dir`` afterwards
    :return: the report: ``task``, ``episodes``, ``cell_size``, ``cells``, ``covered_cells``, ``coverage``,
        ``in_region`` (share of reached points inside the region) and the two file paths
    """
    if isinstance(source, str | os.PathLike):
        info = dataset_info(source)
        if task is not None and get_task(task).name != info["task"]:
            raise ValueError(f"dataset {str(source)!r} holds task {info['task']!r}, not {get_task(task).name!r}")
        task, reached = info["task"], load_reached(source)
    else:
        reached = np.asarray(source, dtype=np.float64).reshape(-1, 2)
    if task is None:
        raise ValueError("task is needed when the reached points are given as an array")
    spec = get_task(task)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    named = out_dir if final_dir is None else Path(final_dir)
    covered = covered_cells(reached, spec)
    report = {
        "task": spec.name,
        "episodes": int(len(reached)),
        "cell_size": spec.cell_size,
        "cells": int(len(covered)),
        "covered_cells": int(covered.sum()),
        "coverage": float(covered.mean()),
        "in_region": float(in_goal_region(reached, spec).mean()) if len(reached) else 0.0,
        "json": str(named / "coverage.json"),
        "png": str(named / "coverage.png"),
    }
    with atomic_path(out_dir / "coverage.png") as tmp:
        _plot(reached, spec, covered, tmp, report["coverage"])
    atomic_write_json(out_dir / "coverage.json", report, indent=1)
    return report


def _plot(reached: np.ndarray, spec: TaskSpec, covered: np.ndarray, path: Path, coverage: float) -> None:
    """Reached points, uncovered cells and the goal region's outline, drawn without pyplot's global state."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    centres = region_cells(spec)
    figure = Figure(figsize=spec.figure_size)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    shown = reached[np.random.default_rng(0).permutation(len(reached))[:20000]] if len(reached) > 20000 else reached
    axes.scatter(shown[:, 0], shown[:, 1], s=1, alpha=0.3, color="C0", label="reached")
    axes.scatter(*centres[~covered].T, s=8, marker="x", color="C3", label="uncovered cell")
    if spec.region_patch is None:
        low, size = np.asarray(spec.goal_low), np.asarray(spec.goal_high) - np.asarray(spec.goal_low)
        axes.add_patch(Rectangle(tuple(low), size[0], size[1], fill=False, color="k", label="goal region"))
    else:
        axes.add_patch(spec.region_patch())
    axes.set_aspect("equal")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_title(f"{spec.name}: {len(reached)} demonstrations, {100 * coverage:.1f}% of cells covered", fontsize=10)
    axes.legend(loc="upper right", fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
