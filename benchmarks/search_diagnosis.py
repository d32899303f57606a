"""Where GenRL's search stops on a small goal-conditioned bandit whose limit is known, and which stage stops it.

The bandit (:class:`PointMassBandit`): the context is a goal ``g`` uniform in ``[-1, 1]^2``; a latent action ``alpha``
(3 numbers, prior N(0, 1)) is decoded by a small fixed generator (:class:`BentGenerator`, a random two-layer tanh
decoder) into 8 per-step velocities of a point mass; the reward is minus the distance from where the point mass ends
to the goal. Some goals lie outside what the generator reaches. "The best its generator reaches" is, for each goal,
the smallest distance over 10^4 prior draws (clipped to GenRL's latent box of +-3) (:func:`prior_best`).

For ``GenRL(env, generator)`` with no settings, the benchmark records per iteration (:class:`DiagnosedGenRL`):

- ``ratio``: the mean distance of the policy's mean on the held-out goals over the mean of their best of the prior;
- ``improving_share``: the share of an iteration's pulls whose reward beats that of the policy's mean at their goal
  (the mean is played at every goal of the batch for this; those plays are not training episodes);
- ``z_best_pull`` / ``z_improving``: how far, in the policy's standard deviations, the best pull of the iteration and the
  improving pulls lie from the policy's mean (the norm of ``(alpha - mu) / sigma``);
- ``z_target``: at each diagnosis goal, the nearest of the prior's draws within 1.5 times the best distance, in the
  policy's standard deviations from its mean (how far the mean must still move), and ``spread_hits``: the share of
  goals where one of 16 draws from the policy's own spread gets within 1.5 times the best distance;
- ``mean_step``: how far the mean moved in the iteration (in the standard deviations of the start of the iteration,
  averaged over the batch's goals), and ``iterations_needed`` = median ``z_target`` / ``mean_step``;
- the E-step: achieved ``KL`` of each E-step against ``target_kl``, the step size and the line search's accepted
  fraction; the value baseline's explained variance (of the values the batch was collected with); the spread
  (the mean standard deviation) and its change per iteration;
- the normalised advantages: their largest value, the share above 1, the share of batches where no pull reached the
  goal within ``--success-distance``; under the sparse variant (reward 0 within ``--success-distance``, else -1) from a
  run on that reward.

Diagnosis goals are drawn with :data:`~sb3_genrl.hyperparams.TUNING_GOAL_SEED`. The comparison of GenRL's default with
the option it motivates (``latent_critic_kwargs={}``, :mod:`sb3_genrl.genrl.latent_critic`) and with a longer value
fit (``n_critic_updates=200``), 3 seeds each with no other setting, is measured on held-out goals
(:data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`) that chose nothing.

    python -m benchmarks.search_diagnosis
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces

from sb3_genrl.checks import COUNT, JSON_OUT
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.genrl import GenRL
from sb3_genrl.hyperparams import EVAL_GOAL_SEED, TUNING_GOAL_SEED
from sb3_genrl.markdown import markdown_table
from sb3_genrl.provenance import provenance
from sb3_genrl.utils import atomic_write_json

PRIOR_DRAWS = 10_000
PRIOR_SEED = 1  # the prior draws of the generator's limit (neither the goals' seeds nor a training seed)
TARGET = 1.5  # the target: within 1.5 times the best of the prior
SPREAD_DRAWS = 16
SCALES = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)  # the scales of the search for the nearest solving latent action
SCALE_DRAWS = 256


class BentGenerator(TrajectoryGenerator):
    """A small fixed nonlinear generator of point-mass velocity trajectories: a random two-layer tanh decoder.

    ``tau(alpha) = speed * tanh(W2 tanh(W1 alpha + b1) + b2)``, reshaped to ``(horizon, 2)``, with weights drawn from
    ``np.random.default_rng(weights_seed)``. Its reach (the sum of the velocities) is a bent, unevenly covered region
    that holds most but not all of ``[-1, 1]^2``, and each point it reaches has a one-dimensional set of latent actions.

    :param latent_dim: dimension of the latent action (default 3)
    :param horizon: time steps (default 8)
    :param hidden: width of the hidden layer (default 16)
    :param speed: the largest velocity per step and axis (default 0.3)
    :param weights_seed: seed of the fixed weights (default 1)
    """

    def __init__(
        self, *, latent_dim: int = 3, horizon: int = 8, hidden: int = 16, speed: float = 0.3, weights_seed: int = 1
    ) -> None:
        super().__init__(horizon=horizon, action_dim=2, latent_dim=latent_dim, prior="normal")
        rng = np.random.default_rng(weights_seed)
        self.w1 = rng.standard_normal((hidden, latent_dim)) / np.sqrt(latent_dim)
        self.b1 = 0.5 * rng.standard_normal(hidden)
        self.w2 = 1.5 * rng.standard_normal((horizon * 2, hidden)) / np.sqrt(hidden)
        self.b2 = 0.3 * rng.standard_normal(horizon * 2)
        self.speed = float(speed)
        self.config = dict(latent_dim=latent_dim, horizon=horizon, hidden=hidden, speed=speed, weights_seed=weights_seed)

    def decode(self, alpha: np.ndarray) -> np.ndarray:
        alpha = self.check_latent(alpha).astype(np.float64)
        hidden = np.tanh(alpha @ self.w1.T + self.b1)
        velocities = self.speed * np.tanh(hidden @ self.w2.T + self.b2)
        return velocities.reshape(len(alpha), self.horizon, 2).astype(np.float32)

    def reached(self, alpha: np.ndarray) -> np.ndarray:
        """Where the point mass ends for each latent action: ``(n, 2)``."""
        return self.decode(alpha).astype(np.float64).sum(axis=1)

    def save(self, path: str) -> None:
        raise NotImplementedError("BentGenerator is rebuilt from its config, not saved")


class PointMassBandit(gym.Env):
    """A point mass moved by per-step velocities towards a goal in ``[-1, 1]^2``; one episode is one trajectory.

    Context: the goal (``get_context``). Reward at the end: minus the distance to the goal, or with
    ``success_distance`` the sparse variant, 0 within that distance and -1 beyond. The fast path
    ``play_trajectories`` plays a whole batch; ``step`` moves the point mass one step (velocities clipped to
    ``[-1, 1]``).

    :param horizon: steps per episode (default 8, :class:`BentGenerator`'s)
    :param success_distance: None (default: dense reward) or the distance within which the sparse reward is 0
    """

    metadata: dict[str, Any] = {"render_modes": []}
    context_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def __init__(self, horizon: int = 8, success_distance: float | None = None) -> None:
        if success_distance is not None and not success_distance > 0:
            raise ValueError(f"success_distance must be positive or None, got {success_distance!r}")
        self.horizon = horizon
        self.success_distance = success_distance
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(4,), dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        goal = (options or {}).get("goal")
        self.goal = self.np_random.uniform(-1.0, 1.0, size=2) if goal is None else np.asarray(goal, dtype=np.float64)
        self.position = np.zeros(2)
        self.t = 0
        return self._observation(), {}

    def get_context(self) -> np.ndarray:
        return self.goal.astype(np.float32)

    def reward(self, distance: np.ndarray) -> np.ndarray:
        """The reward for final distances to the goal: dense, or sparse with ``success_distance``."""
        if self.success_distance is None:
            return -distance
        return -(distance > self.success_distance).astype(np.float64)

    def play_trajectories(
        self, trajectories: np.ndarray, goals: np.ndarray, *, n_threads: int = 1
    ) -> tuple[np.ndarray, list[dict[str, Any]]]:
        reached = np.clip(np.asarray(trajectories, dtype=np.float64), -1.0, 1.0).sum(axis=1)
        distance = np.linalg.norm(reached - np.asarray(goals, dtype=np.float64), axis=1)
        infos = [{"distance": float(d), "reached": point} for d, point in zip(distance, reached, strict=True)]
        return self.reward(distance), infos

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.position = self.position + np.clip(action, -1.0, 1.0)
        self.t += 1
        terminated = self.t >= self.horizon
        distance = float(np.linalg.norm(self.position - self.goal))
        reward = float(self.reward(np.array(distance))) if terminated else 0.0
        return self._observation(), reward, terminated, False, {"distance": distance, "reached": self.position.copy()}

    def _observation(self) -> np.ndarray:
        return np.concatenate([self.goal, self.position]).astype(np.float32)


def goals(n: int, seed: int) -> np.ndarray:
    """``n`` goals uniform in ``[-1, 1]^2`` from ``np.random.default_rng(seed)``: ``(n, 2)`` float32."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n, 2)).astype(np.float32)


def prior_draws(generator: BentGenerator, draws: int = PRIOR_DRAWS, latent_clip: float = 3.0) -> np.ndarray:
    """The prior draws of the generator's limit, clipped to GenRL's latent box: ``(draws, latent_dim)``."""
    return np.clip(generator.sample_prior(draws, rng=PRIOR_SEED), -latent_clip, latent_clip)


def distances(points: np.ndarray, goal_array: np.ndarray) -> np.ndarray:
    """``(len(goal_array), len(points))`` Euclidean distances."""
    return np.linalg.norm(goal_array[:, None, :].astype(np.float64) - points[None, :, :], axis=-1)


def prior_best(generator: BentGenerator, goal_array: np.ndarray, draws: int = PRIOR_DRAWS) -> np.ndarray:
    """Per goal, the smallest distance to it over ``draws`` prior draws: what the generator allows."""
    return distances(generator.reached(prior_draws(generator, draws)), goal_array).min(axis=1)


def mean_distances(model: GenRL, goal_array: np.ndarray) -> np.ndarray:
    """The distance of the policy's mean (its deterministic latent action, clipped to the box) to each goal."""
    alpha, _ = model.predict(goal_array, deterministic=True)
    return np.linalg.norm(model.generator.reached(alpha) - goal_array, axis=1)  # type: ignore[union-attr]


class DiagnosedGenRL(GenRL):
    """GenRL that records, at each iteration, what its search sees and does (see the module's list).

    :param diagnosis_goals: goals ``(n, 2)`` at which the policy's mean, spread and the prior's near-best draws are
        compared at each iteration
    :param success_distance: the distance within which a pull counts as reaching its goal (for the advantages' counts)
    :param kwargs: GenRL's arguments
    """

    def __init__(self, *args: Any, diagnosis_goals: np.ndarray, success_distance: float, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.diagnosis_goals = diagnosis_goals
        self.success_distance = success_distance
        draws = prior_draws(self.generator)  # type: ignore[arg-type]
        goal_distances = distances(self.generator.reached(draws), diagnosis_goals)  # type: ignore[union-attr]
        best = goal_distances.min(axis=1)
        self.best = best
        self._last_mean: np.ndarray | None = None
        self._last_step: np.ndarray | None = None
        self.records: list[dict[str, Any]] = []
        self._e_steps: list[dict[str, float]] = []
        self._spread_rng = np.random.default_rng(0)

    def _distribution(self, contexts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with th.no_grad():
            distribution = self.policy.get_distribution(th.as_tensor(contexts, device=self.device)).distribution
        return distribution.mean.cpu().numpy().astype(np.float64), distribution.stddev.cpu().numpy().astype(np.float64)

    def _reached_distance(self, alpha: np.ndarray, goal_array: np.ndarray) -> np.ndarray:
        box = self.action_space
        return np.linalg.norm(self.generator.reached(np.clip(alpha, box.low, box.high)) - goal_array, axis=1)

    def _e_step(self, q: Any, batch: Any) -> dict[str, float]:
        stats = super()._e_step(q, batch)
        with th.no_grad():
            kl = th.distributions.kl_divergence(
                q.get_distribution(batch[0]).distribution, self.policy.get_distribution(batch[0]).distribution
            )
        self._e_steps.append({**stats, "achieved_kl": kl.sum(-1).mean().item(), "advantages": batch[3].cpu().numpy()})
        return stats

    def train(self) -> None:
        data = next(self.rollout_buffer.get(batch_size=None))
        contexts = data.observations.cpu().numpy().astype(np.float64)
        actions = data.actions.cpu().numpy().astype(np.float64)
        mean, std = self._distribution(contexts)
        pull_distance = self._reached_distance(actions, contexts)
        mean_distance = self._reached_distance(mean, contexts)
        improving = pull_distance < mean_distance
        z_pull = np.linalg.norm((actions - mean) / std, axis=1)
        best_pull = int(np.argmax(mean_distance - pull_distance))
        record = self._goal_diagnosis()
        self._e_steps = []
        super().train()
        after, std_after = self._distribution(contexts)
        advantages = self._e_steps[0]["advantages"]
        values, returns = self.rollout_buffer.values.flatten(), self.rollout_buffer.returns.flatten()
        reached = pull_distance <= self.success_distance
        record.update(
            improving_share=float(improving.mean()),
            z_improving=float(np.median(z_pull[improving])) if improving.any() else float("nan"),
            z_best_pull=float(z_pull[best_pull]),
            best_pull_gain=float(mean_distance[best_pull] - pull_distance[best_pull]),
            mean_step=float(np.mean(np.linalg.norm((after - mean) / std, axis=1))),
            std=float(std.mean()),
            std_change=float(std_after.mean() / std.mean()),
            achieved_kl=[e["achieved_kl"] for e in self._e_steps],
            step_size=[e["step_size"] for e in self._e_steps if "step_size" in e],
            accepted_fraction=[e["accepted_fraction"] for e in self._e_steps if "accepted_fraction" in e],
            explained_variance=float(1 - np.var(returns - values) / max(np.var(returns), 1e-12)),
            advantage_max=float(advantages.max()),
            advantage_share_above_1=float((advantages > 1).mean()),
            reached_share=float(reached.mean()),
            advantage_of_reached=float(advantages[reached].mean()) if reached.any() else float("nan"),
            mean_reward=float(self.rollout_buffer.rewards.mean()),
        )
        record["iterations_needed"] = record["z_solving_median"] / max(record["mean_step"], 1e-12)
        self.records.append(record)

    def _goal_diagnosis(self) -> dict[str, Any]:
        """At the diagnosis goals: the mean's ratio to the prior's best and its share of goals within the target,
        whether one of 16 draws of the policy's spread meets the target, how far (in the policy's standard deviations)
        the nearest latent action that meets the target lies from the mean, and the mean's step since the last
        iteration against the one before (the cosine of the two, in standard deviations)."""
        goal_array = self.diagnosis_goals.astype(np.float64)
        mean, std = self._distribution(self.diagnosis_goals)
        mean_distance = self._reached_distance(mean, goal_array)
        target = TARGET * self.best
        n, dim = mean.shape
        noise = self._spread_rng.standard_normal((n, SPREAD_DRAWS, dim))
        spread_distance = self._reached_distance(
            (mean[:, None] + std[:, None] * noise).reshape(-1, dim), np.repeat(goal_array, SPREAD_DRAWS, 0)
        )
        spread_hits = (spread_distance.reshape(n, SPREAD_DRAWS) <= target[:, None]).any(axis=1)
        z_solving = np.full(n, np.inf)  # the smallest scale s at which a draw mu + s sigma eps meets the target
        z_solving[mean_distance <= target] = 0.0
        noise = self._spread_rng.standard_normal((n, SCALE_DRAWS, dim))
        for scale in reversed(SCALES):
            alpha = (mean[:, None] + scale * std[:, None] * noise).reshape(-1, dim)
            hits = (
                self._reached_distance(alpha, np.repeat(goal_array, SCALE_DRAWS, 0)).reshape(n, SCALE_DRAWS) <= target[:, None]
            ).any(axis=1)
            z_solving[hits & (z_solving > 0)] = scale
        step = (mean - self._last_mean) / std if self._last_mean is not None else None
        cosine = float("nan")
        if step is not None and self._last_step is not None:
            norms = np.linalg.norm(step, axis=1) * np.linalg.norm(self._last_step, axis=1)
            cosine = float(np.median(np.sum(step * self._last_step, axis=1) / np.maximum(norms, 1e-12)))
        self._last_mean, self._last_step = mean, step
        return {
            "episodes": int(self.num_timesteps),
            "ratio": float(mean_distance.mean() / self.best.mean()),
            "mean_hits": float((mean_distance <= target).mean()),
            "spread_hits": float(spread_hits.mean()),
            "z_solving_median": float(np.median(z_solving)),
            "z_solving_within_1": float((z_solving <= 1).mean()),
            "z_solving_within_4": float((z_solving <= 4).mean()),
            "z_solving_beyond": float(np.isinf(z_solving).mean()),
            "step_cosine": cosine,
        }


# The settings compared on the held-out goals: GenRL's default, and the option the diagnosis motivates
VARIANTS: dict[str, dict[str, Any]] = {
    "default": {},
    "latent_critic_kwargs={}": {"latent_critic_kwargs": {}},
    "n_critic_updates=200": {"n_critic_updates": 200},
    "pulls_per_context=2": {"pulls_per_context": 2},
}
PHASES = ((1, 10), (11, 30), (31, 60), (61, 100))  # iterations summarised together


def diagnose(seed: int, iterations: int, success_distance: float, sparse: bool) -> list[dict[str, Any]]:
    """Per-iteration records of ``GenRL(env, generator)`` with no settings (:class:`DiagnosedGenRL`) on the dense
    bandit, or with ``sparse`` on its sparse variant (0 within ``success_distance``, else -1)."""
    env = PointMassBandit(success_distance=success_distance if sparse else None)
    model = DiagnosedGenRL(
        env,
        BentGenerator(),
        seed=seed,
        diagnosis_goals=goals(128, TUNING_GOAL_SEED),
        success_distance=success_distance,
    )
    model.learn(model.n_steps * iterations)
    return model.records


def phase_summary(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The median of every record over each of :data:`PHASES` (lists: their mean first)."""
    rows = []
    for first, last in PHASES:
        chunk = records[first - 1 : last]
        if not chunk:
            continue
        row: dict[str, Any] = {"iterations": f"{first}-{first + len(chunk) - 1}"}
        for key in chunk[0]:
            values = [float(np.mean(r[key])) if isinstance(r[key], list) else r[key] for r in chunk]
            row[key] = float(np.nanmedian(values)) if not all(np.isnan(values)) else float("nan")
        rows.append(row)
    return rows


def compare(variant: str, seed: int, episodes: int, every: int, held_out: np.ndarray, best: np.ndarray) -> dict:
    """One run of a :data:`VARIANTS` entry, evaluated on the held-out goals every ``every`` episodes."""
    generator = BentGenerator()
    model = GenRL(PointMassBandit(), generator, seed=seed, **VARIANTS[variant])
    points, seconds = [], 0.0
    while model.num_timesteps < episodes:
        start = time.process_time()
        model.learn(every, reset_num_timesteps=False)
        seconds += time.process_time() - start
        distance = mean_distances(model, held_out)
        points.append(
            {
                "episodes": int(model.num_timesteps),
                "ratio": float(distance.mean() / best.mean()),
                "median_goal_ratio": float(np.median(distance / best)),
                "within_target": float((distance <= TARGET * best).mean()),
                "cpu_seconds": seconds,
            }
        )
    return {"variant": variant, "seed": seed, "points": points}


def without_nan(value: Any) -> Any:
    """``value`` with every NaN (an iteration with nothing to measure) as None, so that the JSON is strict."""
    if isinstance(value, dict):
        return {key: without_nan(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [without_nan(item) for item in value]
    if isinstance(value, float | np.floating) and np.isnan(value):
        return None
    return value


def arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iterations", type=COUNT, default=100, help="iterations of the diagnosis runs")
    parser.add_argument("--episodes", type=COUNT, default=6400, help="episodes of each compared run")
    parser.add_argument("--every", type=COUNT, default=1600, help="episodes between evaluations of the compared runs")
    parser.add_argument("--seeds", type=COUNT, default=3, help="seeds of each compared variant")
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS), help="variants compared")
    parser.add_argument(
        "--diagnosis", action=argparse.BooleanOptionalAction, default=True, help="the per-iteration diagnosis runs"
    )
    parser.add_argument("--held-out", type=COUNT, default=256, help="held-out goals")
    parser.add_argument("--success-distance", type=float, default=0.05, help="success of the sparse variant")
    parser.add_argument("--out", type=JSON_OUT, default="benchmarks/results/search_diagnosis.json")
    args = parser.parse_args(argv)
    if not args.success_distance > 0:
        parser.error(f"--success-distance must be > 0, got {args.success_distance}")
    return args


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = arguments(argv)
    th.set_num_threads(1)
    begin = time.perf_counter()
    diagnosis = {
        name: diagnose(0, args.iterations, args.success_distance, sparse)
        for name, sparse in ((("dense", False), ("sparse", True)) if args.diagnosis else ())
    }
    held_out = goals(args.held_out, EVAL_GOAL_SEED)
    best = prior_best(BentGenerator(), held_out)
    runs = [compare(v, seed, args.episodes, args.every, held_out, best) for v in args.variants for seed in range(args.seeds)]
    summary = {
        variant: {
            key: float(np.mean([run["points"][-1][key] for run in runs if run["variant"] == variant]))
            for key in ("ratio", "median_goal_ratio", "within_target", "cpu_seconds")
        }
        for variant in args.variants
    }
    shown = ("ratio", "z_solving_median", "spread_hits", "mean_hits", "mean_step", "step_cosine", "std", "explained_variance")
    for name, records in diagnosis.items():
        print(f"diagnosis, {name} reward, GenRL with no settings (seed 0, medians per phase)")
        rows = phase_summary(records)
        print(markdown_table(("iterations", *shown), [[r["iterations"], *(f"{r[k]:.3g}" for k in shown)] for r in rows]))
    print(f"held-out goals ({args.held_out}, seed {EVAL_GOAL_SEED}), {args.episodes} episodes, {args.seeds} seeds")
    print(
        markdown_table(
            ("variant", "ratio", "median goal ratio", "within 1.5x", "CPU s"),
            [
                [
                    v,
                    f"{s['ratio']:.2f}",
                    f"{s['median_goal_ratio']:.2f}",
                    f"{s['within_target']:.2f}",
                    f"{s['cpu_seconds']:.0f}",
                ]
                for v, s in summary.items()
            ],
        )
    )
    result = {
        "benchmark": "search_diagnosis",
        "command": "python -m " + " ".join(["benchmarks.search_diagnosis", *(argv if argv is not None else sys.argv[1:])]),
        **provenance(),
        "machine": platform.machine(),
        "generator": BentGenerator().config,
        "prior_draws": PRIOR_DRAWS,
        "prior_seed": PRIOR_SEED,
        "target": TARGET,
        "diagnosis_goal_seed": TUNING_GOAL_SEED,
        "held_out_goal_seed": EVAL_GOAL_SEED,
        "held_out_best_mean": float(best.mean()),
        "settings": vars(args) | {"out": None},
        "diagnosis": {name: {"phases": phase_summary(r), "iterations": r} for name, r in diagnosis.items()},
        "variants": {variant: VARIANTS[variant] for variant in args.variants},
        "runs": runs,
        "summary": summary,
        "seconds": time.perf_counter() - begin,
    }
    atomic_write_json(args.out, without_nan(result), default=float)
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
