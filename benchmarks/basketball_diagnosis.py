"""Where basketball's accuracy is lost: the demonstrations, the generator's latent map, or the GenRL policy search.

For one pipeline (a demonstration set, a generator trained on it, a GenRL policy over it) and the same held-out
baskets, measures:

- demonstrations: coverage of the basket region (25 cm cells), the share landing inside it, the distance from each
  basket to the nearest demonstration's landing point, and the swing timing (peak step, duration) read off the
  trajectories;
- generator: the best reachable distance to each basket over a dense grid of latent actions (see
  ``benchmarks/reachable.py``: exact for the reward, which takes the best of a throw's rim-height crossings), and
  the landing map (first crossing) over the grid: metres per unit of latent, folds (Jacobian determinant changing
  sign) and jumps (neighbouring grid points landing more than 1 m apart or one of them never coming down);
- GenRL: the deterministic policy's mean distance to the same baskets.

Prints a table, writes JSON and a PNG of the latent grid.

    python benchmarks/basketball_diagnosis.py --data /tmp/bb/demos --generator /tmp/bb/vae.pt --policy-episodes 3000
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import gymnasium as gym
import matplotlib
import numpy as np
import torch

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reachable import generator_limit, held_out_goals, nearest, summary  # noqa: E402
from sb3_genrl.envs.coverage import covered_cells, in_goal_region  # noqa: E402

from sb3_genrl import GenRL  # noqa: E402
from sb3_genrl.checks import COUNT, EXISTING, SEED, check_int, option  # noqa: E402
from sb3_genrl.data import load_actions, load_reached  # noqa: E402
from sb3_genrl.generative import load  # noqa: E402
from sb3_genrl.genrl import evaluate_on_goals  # noqa: E402
from sb3_genrl.utils import atomic_path, atomic_write_json  # noqa: E402

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
JUMP_M = 1.0  # neighbouring grid points landing further apart than this count as a jump


def swing_timing(actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per trajectory: the step at which the swing (shoulder, elbow, wrist pitch) is fastest, and its duration in
    steps (twice the swing's travel over its peak step, exact for one raised-cosine bump)."""
    speed = np.abs(actions[:, :, [1, 3, 5]]).sum(axis=2)
    peak = speed.argmax(axis=1)
    window = np.abs(np.arange(actions.shape[1])[None] - peak[:, None]) <= 6
    duration = 2.0 * (speed * window).sum(axis=1) / speed.max(axis=1)
    return peak, duration


def demonstrations(data: str, goals: np.ndarray) -> dict[str, object]:
    """Coverage, in-region share, nearest landing point per goal and the swing timing of a demonstration set."""
    reached = load_reached(data)
    peak, duration = swing_timing(load_actions(data))
    radius = np.linalg.norm(reached, axis=1)
    distances, _ = nearest([p[None] for p in reached], goals)
    steps, counts = np.unique(peak, return_counts=True)
    return {"n": len(reached), "coverage": float(covered_cells(reached, "basketball").mean()),
            "in_region": float(in_goal_region(reached, "basketball").mean()),
            "radius_p10_p90": [float(q) for q in np.percentile(radius, [10, 90])],
            "nearest": summary(distances), "swing_peak_steps": {int(s): int(c) for s, c in zip(steps, counts, strict=True)},
            "swing_duration_p10_p90": [float(q) for q in np.percentile(duration, [10, 90])]}


def landing_map(candidates: list[np.ndarray], grid: int) -> np.ndarray:
    """The first rim-height crossing of each grid point, ``(grid, grid, 2)``; NaN where the ball never comes down."""
    first = np.array([c[0] if len(c) else (np.nan, np.nan) for c in candidates])
    return first.reshape(grid, grid, 2)


def sensitivity(points: np.ndarray, spacing: float, weights: np.ndarray) -> dict[str, object]:
    """Metres of landing change per unit of latent, folds and jumps of a landing map over a 2-D grid.

    :param points: ``(g, g, 2)`` landing map
    :param spacing: latent distance between neighbouring grid points
    :param weights: ``(g, g)`` prior density at the grid points (for prior-weighted shares)
    """
    steps = [np.linalg.norm(np.diff(points, axis=a), axis=2) for a in (0, 1)]
    holes = [np.isnan(s) & ~(np.isnan(points).all(axis=2)[:-1] & np.isnan(points).all(axis=2)[1:]) if a == 0
             else np.isnan(s) & ~(np.isnan(points).all(axis=2)[:, :-1] & np.isnan(points).all(axis=2)[:, 1:])
             for a, s in enumerate(steps)]
    jumps = [(s > JUMP_M) | h for s, h in zip(steps, holes, strict=True)]
    n_pairs = sum(s.size for s in steps)
    d0, d1 = np.gradient(points, spacing, axis=0), np.gradient(points, spacing, axis=1)
    jacobian = np.stack([d0, d1], axis=-1)  # (g, g, 2 landing coords, 2 latent coords)
    smooth = np.isfinite(jacobian).all(axis=(2, 3))
    smooth[:-1] &= ~jumps[0]
    smooth[1:] &= ~jumps[0]
    smooth[:, :-1] &= ~jumps[1]
    smooth[:, 1:] &= ~jumps[1]
    singular = np.full(points.shape[:2] + (2,), np.nan)
    singular[smooth] = np.linalg.svd(jacobian[smooth], compute_uv=False)
    det = np.where(smooth, np.linalg.det(np.where(smooth[..., None, None], jacobian, 0.0)), np.nan)
    inside = in_goal_region(points.reshape(-1, 2), "basketball").reshape(points.shape[:2]) & smooth
    w = weights / weights.sum()
    positive = float(w[smooth & (det > 0)].sum() / w[smooth].sum())
    return {"m_per_latent_median": float(np.nanmedian(singular[inside, 0])),
            "m_per_latent_p90": float(np.nanpercentile(singular[inside, 0], 90)),
            "m_per_latent_small_median": float(np.nanmedian(singular[inside, 1])),
            "jump_pairs": int(sum(j.sum() for j in jumps)), "jump_pair_share": float(sum(j.sum() for j in jumps) / n_pairs),
            "jump_prior_mass": float((w[:-1] * jumps[0]).sum() + (w[:, :-1] * jumps[1]).sum()),
            "det_positive_prior_share": positive, "no_crossing_prior_mass": float(w[np.isnan(points[..., 0])].sum()),
            "_det": det, "_singular": singular, "_jumps": jumps}


def policy_distance(generator_path: str, episodes: int, seed: int, goal_seed: int, n_goals: int,
                    policy: str | None) -> tuple[np.ndarray, np.ndarray]:
    """Train (or load) a GenRL policy; its deterministic distances and latent actions for the held-out goals."""
    if policy is not None:
        model = GenRL.load(policy, generator=generator_path, device="cpu")
    else:
        model = GenRL(gym.make("GenRL/Basketball-v0"), generator_path, seed=seed, device="cpu")
        model.learn(episodes, progress_bar=False)
    goals, rewards, _ = evaluate_on_goals(model, "basketball", goals=n_goals, seed=goal_seed)
    latents, _ = model.predict(goals, deterministic=True)
    return -rewards, latents


def plot(path: str, grid_axis: np.ndarray, points: np.ndarray, sens: dict[str, object], encoded: np.ndarray | None,
         peak: np.ndarray | None, best: np.ndarray, policy_latents: np.ndarray | None) -> None:
    """Landing radius, angle and sensitivity over the latent grid, with jumps, demonstrations and the best latents."""
    extent = (grid_axis[0], grid_axis[-1], grid_axis[0], grid_axis[-1])
    radius = np.linalg.norm(points, axis=2)
    angle = np.degrees(np.arctan2(points[..., 1], points[..., 0]))
    figure, axes = plt.subplots(2, 2, figsize=(11, 10))
    panels = [(radius.T, "landing radius (m)", "viridis", (0, 10)), (angle.T, "landing angle (deg)", "twilight", (-180, 180)),
              (np.log10(sens["_singular"][..., 0]).T, "log10 m per unit latent", "magma", None)]
    for axis, (image, title, cmap, limits) in zip(axes.flat, panels, strict=False):
        shown = axis.imshow(image, origin="lower", extent=extent, cmap=cmap, interpolation="nearest",
                            vmin=None if limits is None else limits[0], vmax=None if limits is None else limits[1])
        figure.colorbar(shown, ax=axis, shrink=0.8)
        axis.set(title=title, xlabel="alpha_1", ylabel="alpha_2")
    jump = np.zeros(points.shape[:2], dtype=bool)
    jump[:-1] |= sens["_jumps"][0]
    jump[:, :-1] |= sens["_jumps"][1]
    folded = sens["_det"] < 0
    axis = axes[1, 1]
    axis.imshow(np.where(folded, 1.0, 0.0).T, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=3, alpha=0.6)
    jz = np.argwhere(jump)
    axis.scatter(grid_axis[jz[:, 0]], grid_axis[jz[:, 1]], s=0.3, c="red", label=f"jump > {JUMP_M:g} m or no landing")
    if encoded is not None:
        scatter = axis.scatter(encoded[:, 0], encoded[:, 1], s=1, c=peak, cmap="tab10", label="demonstrations (mean)")
        figure.colorbar(scatter, ax=axis, shrink=0.8, label="demonstration swing peak step")
    axis.scatter(best[:, 0], best[:, 1], s=4, marker="x", c="k", label="best grid latent per basket")
    if policy_latents is not None:
        axis.scatter(policy_latents[:, 0], policy_latents[:, 1], s=4, marker="+", c="tab:orange", label="GenRL latent")
    axis.set(title="folds (grey: det J < 0), jumps, demonstrations", xlabel="alpha_1", ylabel="alpha_2",
             xlim=extent[:2], ylim=extent[2:])
    axis.legend(loc="lower left", fontsize=7, markerscale=4)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=90)




def print_table(result: dict[str, object]) -> None:
    demos, limit, genrl = result["demonstrations"], result["generator"]["best_reachable"], result.get("genrl")
    print(f"\nbasketball, {result['goals']} held-out baskets (seed {result['goal_seed']}): distance in m")
    print(f"{'what':<55} {'mean':>6} {'median':>7} {'p90':>6}")
    rows = [("nearest demonstration landing point", demos["nearest"]),
            (f"generator best reachable ({result['generator']['n_latents']} latents)", limit)]
    if genrl is not None:
        rows.append((f"GenRL deterministic ({genrl['episodes']} episodes)", genrl["distance"]))
    for name, values in rows:
        print(f"{name:<55} {values['mean']:>6.3f} {values['median']:>7.3f} {values['p90']:>6.3f}")
    sens = result["generator"]["sensitivity"]
    print(f"demonstrations: coverage {demos['coverage']:.1%}, in region {demos['in_region']:.1%}, "
          f"swing peak steps {demos['swing_peak_steps']}")
    print(f"landing map: {sens['m_per_latent_median']:.2f} m per unit latent (median; p90 {sens['m_per_latent_p90']:.2f}),"
          f" jumps {sens['jump_pairs']} pairs ({sens['jump_prior_mass']:.1%} prior mass), det > 0 on "
          f"{sens['det_positive_prior_share']:.1%} of the prior mass, no landing {sens['no_crossing_prior_mass']:.1%}")
    if genrl is not None:
        print(f"ratio GenRL / generator best reachable: {genrl['ratio']:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, type=EXISTING,
                        help="basketball Minari dataset the generator was trained on")
    parser.add_argument("--generator", required=True, type=EXISTING,
                        help="the trained generator (2-D latent for the maps)")
    parser.add_argument("--policy", type=EXISTING, default=None, help="a trained GenRL policy (default: train one)")
    parser.add_argument("--policy-episodes", type=option(check_int, int, minimum=0), default=3000,
                        help="GenRL episodes (0: no policy)")
    parser.add_argument("--seed", type=SEED, default=0, help="GenRL seed")
    parser.add_argument("--goals", type=COUNT, default=300)
    parser.add_argument("--goal-seed", type=SEED, default=12345, help="seed of the held-out baskets")
    parser.add_argument("--grid", type=option(check_int, int, minimum=2), default=201,
                        help="latent grid points per axis over [-3, 3]")
    parser.add_argument("--name", default="basketball_diagnosis", help="output name under benchmarks/results")
    args = parser.parse_args()
    if os.path.basename(args.name) != args.name or args.name in ("", ".", ".."):
        parser.error(f"argument --name: {args.name!r} must be a plain file name (no folder)")
    torch.set_num_threads(1)
    began = time.perf_counter()
    goals = held_out_goals("basketball", args.goals, args.goal_seed)
    result: dict[str, object] = {"data": os.path.abspath(args.data), "generator_path": os.path.abspath(args.generator),
                                 "goals": args.goals, "goal_seed": args.goal_seed,
                                 "demonstrations": demonstrations(args.data, goals)}
    generator = load(args.generator, device="cpu")
    limit = generator_limit(generator, "basketball", goals, grid=args.grid)
    grid_axis = np.linspace(-3.0, 3.0, args.grid)
    points = landing_map(limit["candidates"], args.grid)
    weights = np.exp(-0.5 * (grid_axis[:, None] ** 2 + grid_axis[None, :] ** 2))
    sens = sensitivity(points, grid_axis[1] - grid_axis[0], weights)
    radius = np.linalg.norm(points, axis=2)
    order = np.argsort(radius[np.isfinite(radius)])
    cumulative = np.cumsum((weights / weights[np.isfinite(radius)].sum())[np.isfinite(radius)][order])
    prior_radius = [float(radius[np.isfinite(radius)][order][np.searchsorted(cumulative, q)]) for q in (0.1, 0.9)]
    result["generator"] = {"latent_dim": generator.latent_dim, "beta": getattr(generator, "beta", None),
                           "best_epoch": generator.best_epoch, "n_latents": limit["n_latents"],
                           "best_reachable": limit["summary"], "coarser_grid_means": limit["coarser_grid_means"],
                           "prior_radius_p10_p90": prior_radius,
                           "sensitivity": {k: v for k, v in sens.items() if not k.startswith("_")}}
    encoded = peak = policy_latents = None
    if hasattr(generator, "encode"):
        actions = load_actions(args.data)
        encoded = generator.encode(actions)[0]
        peak = swing_timing(actions)[0]
    if args.policy is not None or args.policy_episodes > 0:
        distances, policy_latents = policy_distance(args.generator, args.policy_episodes, args.seed, args.goal_seed,
                                                    args.goals, args.policy)
        gap = np.linalg.norm(policy_latents - limit["best_latents"], axis=1)
        result["genrl"] = {"episodes": args.policy_episodes, "seed": args.seed, "distance": summary(distances),
                           "ratio": float(distances.mean() / limit["summary"]["mean"]),
                           "latent_gap_to_best_mean": float(gap.mean())}
    result["seconds"] = round(time.perf_counter() - began, 1)
    os.makedirs(RESULTS, exist_ok=True)
    atomic_write_json(os.path.join(RESULTS, args.name + ".json"), result)
    plot(os.path.join(RESULTS, args.name + ".png"), grid_axis, points, sens, encoded, peak, limit["best_latents"],
         policy_latents)
    print_table(result)


if __name__ == "__main__":
    main()
