"""Evaluation of trained generators (paper section 6.1.2): precision/recall against demonstrations and DwPR, and
beyond the paper density and coverage (Naeem et al., 2020) from the same samples and, given a task, the prior rollout
(:mod:`sb3_genrl.metrics.prior_rollout`).

Results are written after each model, so an interrupted evaluation keeps every model it finished.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from sb3_genrl.checks import (
    check_device,
    check_fraction,
    check_input_path,
    check_not_in_input,
    check_output_dir,
    check_positive_int,
    check_seed,
)
from sb3_genrl.data import load_trajectories
from sb3_genrl.generative import load
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.markdown import markdown_table
from sb3_genrl.metrics.correlation import MEASURES
from sb3_genrl.metrics.density_coverage import DensityCoverage, density_coverage
from sb3_genrl.metrics.dwpr import DEFAULT_DWPR_SAMPLES, DEFAULT_INTERVENTIONS, DwPR, decode_batched, dwpr
from sb3_genrl.metrics.plots import labelled_scatter
from sb3_genrl.metrics.precision_recall import PrecisionRecall, precision_recall
from sb3_genrl.metrics.prior_rollout import (
    DEFAULT_CONTEXTS,
    DEFAULT_DRAWS,
    PRIOR_ROLLOUT_SEED,
    PriorRollout,
    prior_rollout,
)
from sb3_genrl.metrics.scorecard import NOT_CONVERGED_PRECISION, RANK_MEASURES, scorecard_markdown
from sb3_genrl.task_ids import task_env_id
from sb3_genrl.utils import atomic_write_json, atomic_write_text

# Paper section 6.1.2: 15000 generated against 15000 fixed, randomly chosen training trajectories, k = 3.
DEFAULT_SAMPLES = 15000
# The paper's measures, then density and coverage (not part of the paper's correlation analysis).
TABLE_COLUMNS = ("model", *MEASURES, "density", "coverage")
# The prior rollout's columns, after those when a task was given.
PRIOR_COLUMNS = ("prior_median", "prior_q25", "prior_q75", "prior_mean", "prior_episodes", "prior_seconds")
# ... and the share of goals some draw solves, where every model's env reports success (info["is_success"])
PRIOR_SUCCESS = "prior_success"


@dataclasses.dataclass(frozen=True, eq=False)
class GeneratorEvaluation:
    """Measures of one generator.

    :param name: model name (file stem or given name)
    :param precision_recall: precision and recall against the real trajectories
    :param dwpr: disentanglement with precision and recall
    :param density_coverage: density and coverage of the same generated samples against the same real ones
    :param prior: the prior rollout on a task (None: no task given)
    """

    name: str
    precision_recall: PrecisionRecall
    dwpr: DwPR
    density_coverage: DensityCoverage
    prior: PriorRollout | None = None

    def row(self) -> dict[str, float | str]:
        """The table row: the model's name, its :data:`~sb3_genrl.metrics.MEASURES`, density and coverage, and the
        prior rollout's :data:`PRIOR_COLUMNS` when there is one."""
        values = (
            self.precision_recall.precision,
            self.precision_recall.recall,
            self.dwpr.delta_1,
            self.dwpr.delta_2,
            self.dwpr.mean_delta,
        )
        summary = {} if self.prior is None else self.prior.summary()
        prior = {key: summary[key] for key in (*PRIOR_COLUMNS, PRIOR_SUCCESS) if key in summary}
        return {
            "model": self.name,
            **dict(zip(MEASURES, values, strict=True)),
            "density": self.density_coverage.density,
            "coverage": self.density_coverage.coverage,
            **prior,
        }

    def details(self) -> dict[str, Any]:
        """The row plus the per-dimension DwPR values and the sample sizes (JSON-ready)."""
        return {
            **self.row(),
            "delta": self.dwpr.delta.tolist(),
            "dwpr_precision": self.dwpr.precision.tolist(),
            "dwpr_recall": self.dwpr.recall.tolist(),
            "intervention_values": self.dwpr.intervention_values.tolist(),
            "k": self.dwpr.k,
            "num_real": self.precision_recall.num_real,
            "num_generated": self.precision_recall.num_generated,
            "dwpr_n": self.dwpr.n,
            **({} if self.prior is None else {**self.prior.summary(), "prior_best": self.prior.best.tolist()}),
        }


def _named_generators(
    models: Sequence[str | os.PathLike | TrajectoryGenerator] | Mapping[str, str | os.PathLike | TrajectoryGenerator],
) -> list[tuple[str, str | os.PathLike | TrajectoryGenerator]]:
    if isinstance(models, Mapping):
        named = list(models.items())
    else:
        named = [
            (Path(model).stem if isinstance(model, str | os.PathLike) else f"{type(model).__name__}{index + 1}", model)
            for index, model in enumerate(models)
        ]
    names = [name for name, _ in named]
    if len(set(names)) != len(names):
        raise ValueError(f"model names must be unique, got {names}; pass a mapping name -> model")
    for name, model in named:
        if isinstance(model, str | os.PathLike):
            check_input_path(model, f"model {name!r}")
    return named


def _as_generator(model: str | os.PathLike | TrajectoryGenerator, device: torch.device | str) -> TrajectoryGenerator:
    if isinstance(model, TrajectoryGenerator):
        return model

    return load(model, device=device)


def write_results(
    evaluations: Sequence[GeneratorEvaluation],
    out_dir: str | os.PathLike,
    rank_by: str | None = None,
    min_precision: float | None = None,
) -> None:
    """Write ``results.csv``, ``results.md``, ``scorecard.md`` (ranked by ``rank_by``,
    :func:`~sb3_genrl.metrics.scorecard.rank_key`, with models below ``min_precision`` last; None: the default
    threshold), the two scatter plots and, last, ``results.json`` into ``out_dir`` (each file atomically)."""
    if min_precision is None:
        min_precision = NOT_CONVERGED_PRECISION

    out = Path(out_dir)
    rows = [evaluation.row() for evaluation in evaluations]
    columns = TABLE_COLUMNS
    if all(evaluation.prior for evaluation in evaluations):
        columns += PRIOR_COLUMNS + ((PRIOR_SUCCESS,) if all(PRIOR_SUCCESS in row for row in rows) else ())
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=columns)
    writer.writeheader()
    writer.writerows({key: repr(row[key]) if isinstance(row[key], float) else row[key] for key in columns} for row in rows)
    atomic_write_text(out / "results.csv", table.getvalue(), newline="")
    markdown = markdown_table(
        columns, [[row[column] for column in columns] for row in rows], align="l" + "r" * (len(columns) - 1)
    )
    atomic_write_text(out / "results.md", markdown + "\n")
    atomic_write_text(out / "scorecard.md", scorecard_markdown(rows, rank_by, min_precision) + "\n")
    labels = [str(row["model"]) for row in rows]
    labelled_scatter(
        [row["precision"] for row in rows],
        [row["recall"] for row in rows],
        labels,
        out / "precision_recall.png",
        xlabel="precision",
        ylabel="recall",
        title="Precision and recall",
    )
    labelled_scatter(
        [row["delta_1"] for row in rows],
        [row["mean_delta"] for row in rows],
        labels,
        out / "disentanglement.png",
        xlabel="delta_1",
        ylabel="mean delta (delta tilde)",
        title="Disentanglement (DwPR)",
    )
    details = [evaluation.details() for evaluation in evaluations]
    atomic_write_json(out / "results.json", details)  # last: its presence marks a complete evaluation


def real_subset(real: np.ndarray, n: int, seed: int | np.random.SeedSequence = 0) -> np.ndarray:
    """The real trajectories that precision and recall compare against: ``n`` drawn without replacement (in their
    original order), or all of them when there are at most ``n``.

    The subset depends on ``seed`` and the data only, so every model evaluated with the same seed is compared with
    the same fixed random subset (paper section 6.1.2).

    :param real: real trajectories ``(N, T, M)``
    :param n: subset size
    :param seed: seed of the draw
    """
    if len(real) <= n:
        return real
    return real[np.sort(np.random.default_rng(seed).choice(len(real), size=n, replace=False))]


def evaluate_generator(
    generator: TrajectoryGenerator,
    real: np.ndarray,
    *,
    n: int = DEFAULT_SAMPLES,
    k: int = 3,
    dwpr_n: int = DEFAULT_DWPR_SAMPLES,
    interventions: int = DEFAULT_INTERVENTIONS,
    seed: int = 0,
    name: str = "model",
    device: torch.device | str = "auto",
    batch_size: int | None = None,
    task: str | Callable[[], gym.Env] | None = None,
    contexts: int = DEFAULT_CONTEXTS,
    draws: int = DEFAULT_DRAWS,
    prior_seed: int = PRIOR_ROLLOUT_SEED,
) -> GeneratorEvaluation:
    """Precision/recall, density and coverage of ``n`` prior samples of one generator against ``real``, and its DwPR.

    This is the one evaluation of a generator: :func:`evaluate_generators` (``genrl evaluate``, the quickstart)
    and the study call it. The prior samples and the DwPR draws come from ``seed`` alone (not from the model's
    place in a list), so a model gets the same measures evaluated alone or with others.

    :param generator: the trained generator
    :param real: the real trajectories ``(N, T, M)`` to compare with, all of them (see :func:`real_subset`)
    :param n: generated samples for precision and recall (paper: 15000)
    :param k: neighbourhood size (paper: 3)
    :param dwpr_n: prior samples per intervention for DwPR (paper: 10000)
    :param interventions: number of DwPR interventions per latent dimension (paper: 5)
    :param seed: seed of the prior samples and of DwPR
    :param name: the model's name in the result
    :param device: torch device for the distances; ``"auto"`` uses a GPU when there is one
    :param batch_size: edge length of the distance blocks (default: from the memory budget)
    :param task: a task for the prior rollout, or a callable that makes its env (a task from outside the package,
        ``functools.partial(sb3_genrl.envs.external.make_task_env, task, horizon=T)``; None: none)
    :param contexts: the prior rollout's goals
    :param draws: its prior draws per goal
    :param prior_seed: seed of its goals (:data:`~sb3_genrl.metrics.prior_rollout.PRIOR_ROLLOUT_SEED`)
    """
    if np.ndim(real) != 3:
        raise ValueError(f"real trajectories must have shape (N, T, M), got {np.shape(real)}")
    if (generator.horizon, generator.action_dim) != real.shape[1:]:
        raise ValueError(
            f"model {name!r} generates (horizon, action_dim) = {(generator.horizon, generator.action_dim)}"
            f", the real trajectories have {real.shape[1:]}"
        )
    prior_rng, dwpr_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    generated = decode_batched(generator, generator.sample_prior(n, prior_rng))
    pr = precision_recall(real, generated, k, batch_size=batch_size, device=device)
    dc = density_coverage(real, generated, k, batch_size=batch_size, device=device)
    disentanglement = dwpr(generator, dwpr_n, interventions, k, seed=dwpr_rng, batch_size=batch_size, device=device)
    prior = None if task is None else prior_rollout(generator, task, contexts=contexts, draws=draws, seed=prior_seed)
    return GeneratorEvaluation(name, pr, disentanglement, dc, prior)


def _check_settings(
    named: list,
    *,
    n: int,
    k: int,
    dwpr_n: int,
    interventions: int,
    seed: int,
    device: torch.device | str,
    task: str | Callable[[], gym.Env] | None,
    contexts: int,
    draws: int,
    prior_seed: int,
    rank_by: str | None,
    min_precision: float | None,
) -> None:
    """Refuse :func:`evaluate_generators`' arguments before any work, naming the one at fault."""
    if not named:
        raise ValueError("no models given")
    for name, value in (("n", n), ("k", k), ("dwpr_n", dwpr_n), ("interventions", interventions)):
        check_positive_int(value, name)
    if k >= n:
        raise ValueError(f"k must be smaller than n (a point is not its own neighbour), got k={k} with n={n}")
    check_seed(seed)
    check_device(device)
    if task is not None:
        _check_prior_task(task, contexts, draws, prior_seed)
    _check_rank_by(rank_by, task)
    if min_precision is not None:
        check_fraction(min_precision, "min_precision")


def evaluate_generators(
    models: Sequence[str | os.PathLike | TrajectoryGenerator] | Mapping[str, str | os.PathLike | TrajectoryGenerator],
    data: str | os.PathLike | np.ndarray,
    *,
    n: int = DEFAULT_SAMPLES,
    k: int = 3,
    dwpr_n: int = DEFAULT_DWPR_SAMPLES,
    interventions: int = DEFAULT_INTERVENTIONS,
    seed: int = 0,
    out_dir: str | os.PathLike,
    device: torch.device | str = "auto",
    batch_size: int | None = None,
    task: str | Callable[[], gym.Env] | None = None,
    contexts: int = DEFAULT_CONTEXTS,
    draws: int = DEFAULT_DRAWS,
    prior_seed: int = PRIOR_ROLLOUT_SEED,
    rank_by: str | None = None,
    min_precision: float | None = None,
) -> list[GeneratorEvaluation]:
    """Precision/recall, density/coverage against real trajectories and DwPR of each generator, written as each
    model completes.

    The real set is ``n`` trajectories drawn once with ``seed`` (:func:`real_subset`; there must be at least
    ``n``) and shared by every model; each model is evaluated by :func:`evaluate_generator` with the same ``seed``.
    Files in ``out_dir``: ``results.csv`` and ``results.md`` (precision, recall, delta_1, delta_2, mean_delta,
    density and coverage per model, and with ``task`` the prior rollout's median, quartiles and cost),
    ``scorecard.md`` (the same ranked, :mod:`sb3_genrl.metrics.scorecard`), ``results.json`` (also the
    per-dimension deltas and each goal's best prior reward), ``precision_recall.png`` and ``disentanglement.png``
    (the paper's scatter plots).

    :param models: generator files (loaded with ``sb3_genrl.generative.load``) or generator objects, or a mapping
        name -> either; names default to file stems
    :param data: real trajectories ``(N, T, M)``, read by :func:`sb3_genrl.data.load_trajectories` (an array, a
        ``.npy``/``.npz`` file or a dataset path); they must number at least ``n
    :param n: real and generated samples for precision and recall (paper: 15000)
    :param k: neighbourhood size (paper: 3)
    :param dwpr_n: prior samples per intervention for DwPR (paper: 10000)
    :param interventions: number of DwPR interventions per latent dimension (paper: 5)
    :param seed: seed of the real subset, the prior samples and DwPR
    :param out_dir: output folder (created)
    :param device: torch device for loading and distances; ``"auto"`` uses a GPU when there is one
    :param batch_size: edge length of the distance blocks (default: from the memory budget)
    :param task: a task for the prior rollout, or a callable that makes its env (a task from outside the package,
        ``functools.partial(sb3_genrl.envs.external.make_task_env, task, horizon=T)``; None: none)
    :param contexts: the prior rollout's goals
    :param draws: its prior draws per goal
    :param prior_seed: seed of its goals
    :param rank_by: the measure ``scorecard.md`` ranks by (None: recall;
        :data:`~sb3_genrl.metrics.scorecard.RANK_MEASURES`)
    :param min_precision: ``scorecard.md`` marks a model below this precision not converged and ranks it last
        (None: :data:`~sb3_genrl.metrics.scorecard.NOT_CONVERGED_PRECISION`; 0: no model)
    :return: the evaluations, in model order
    """
    named = _named_generators(models)
    _check_settings(
        named,
        n=n,
        k=k,
        dwpr_n=dwpr_n,
        interventions=interventions,
        seed=seed,
        device=device,
        task=task,
        contexts=contexts,
        draws=draws,
        prior_seed=prior_seed,
        rank_by=rank_by,
        min_precision=min_precision,
    )
    out = check_output_dir(out_dir)
    check_not_in_input(out, data, "out_dir", "the evaluation's files would join the dataset's own")
    real = load_trajectories(data)
    _check_sample_sizes(real, n, dwpr_n, interventions, data)
    real = real_subset(real, n, seed)
    generators = [(name, _as_generator(model, device)) for name, model in named]  # a bad file: refused before out
    out.mkdir(parents=True, exist_ok=True)
    evaluations: list[GeneratorEvaluation] = []
    for name, model in generators:
        evaluations.append(
            evaluate_generator(
                model,
                real,
                n=n,
                k=k,
                dwpr_n=dwpr_n,
                interventions=interventions,
                seed=seed,
                name=name,
                device=device,
                batch_size=batch_size,
                task=task,
                contexts=contexts,
                draws=draws,
                prior_seed=prior_seed,
            )
        )
        write_results(evaluations, out, rank_by, min_precision)
    return evaluations


def _check_rank_by(rank_by: str | None, task: str | Callable[[], gym.Env] | None) -> None:
    """Refuse a measure the scorecard cannot rank by, before any work."""
    if rank_by is not None and rank_by not in RANK_MEASURES:
        raise ValueError(f"rank_by must be one of {', '.join(RANK_MEASURES)}, got {rank_by!r}")
    if rank_by == "prior_median" and task is None:
        raise ValueError("rank_by='prior_median' needs a task: the prior rollout runs only with one")


def _check_prior_task(task: str | Callable[[], gym.Env], contexts: int, draws: int, prior_seed: int) -> None:
    """Refuse an unknown task, or bad prior-rollout sizes, before any work."""
    check_positive_int(contexts, "contexts")
    check_positive_int(draws, "draws")
    check_seed(prior_seed)
    if isinstance(task, str) or not callable(task):
        task_env_id(task)  # raises, naming the registered tasks


def _check_sample_sizes(real: np.ndarray, n: int, dwpr_n: int, interventions: int, data: Any) -> None:
    """Refuse an empty real set, more samples than the real data holds, or DwPR sets that cannot fit in this machine's
    memory."""
    if len(real) == 0:
        name = repr(str(data)) if isinstance(data, str | os.PathLike) else "the trajectories array"
        raise ValueError(f"{name} holds no trajectories (shape {real.shape}); the evaluation needs at least n = {n}")
    if n > len(real):
        raise ValueError(f"n = {n} is more than the {len(real)} real trajectories; pass n <= {len(real)}")
    # DwPR holds a reference set and one latent dimension's set of n * D decoded float32 trajectories at a time.
    needed = 2 * dwpr_n * interventions * int(np.prod(real.shape[1:])) * 4
    available = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    if needed > available:
        raise ValueError(
            f"dwpr_n = {dwpr_n} needs about {needed / 2**30:.0f} GiB for its decoded trajectories, more "
            f"than this machine's {available / 2**30:.0f} GiB of memory"
        )
