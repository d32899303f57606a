"""Evaluation of trained generators (paper section 6.1.2): precision/recall against demonstrations and DwPR.

Results are written after each model, so an interrupted evaluation keeps every model it finished.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch

from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.metrics.dwpr import DEFAULT_DWPR_SAMPLES, DEFAULT_INTERVENTIONS, DwPR, decode_batched, dwpr
from sb3_genrl.metrics.plots import labelled_scatter
from sb3_genrl.metrics.precision_recall import PrecisionRecall, precision_recall
from sb3_genrl.utils import atomic_write_json, atomic_write_text

# Paper section 6.1.2: 15000 generated against 15000 fixed, randomly chosen training trajectories, k = 3.
DEFAULT_SAMPLES = 15000
TABLE_COLUMNS = ("model", "precision", "recall", "delta_1", "delta_2", "mean_delta")


@dataclasses.dataclass(frozen=True, eq=False)
class GeneratorEvaluation:
    """Measures of one generator.

    :param name: model name (file stem or given name)
    :param precision_recall: precision and recall against the real trajectories
    :param dwpr: disentanglement with precision and recall
    """

    name: str
    precision_recall: PrecisionRecall
    dwpr: DwPR

    def row(self) -> dict[str, float | str]:
        """The table row: model, precision, recall, delta_1, delta_2, mean_delta."""
        return {"model": self.name, "precision": self.precision_recall.precision, "recall": self.precision_recall.recall,
                "delta_1": self.dwpr.delta_1, "delta_2": self.dwpr.delta_2, "mean_delta": self.dwpr.mean_delta}


def load_real_trajectories(data: str | os.PathLike | np.ndarray) -> np.ndarray:
    """Real action trajectories ``(N, T, M)`` from an array, a ``.npy`` file or a dataset (``sb3_genrl.data.load_actions``)."""
    if isinstance(data, np.ndarray):
        return data
    path = Path(data)
    if path.suffix == ".npy":
        if not path.is_file():
            raise FileNotFoundError(f"no such file: {path}")
        return np.load(path)
    try:
        from sb3_genrl.data import load_actions
    except ImportError as error:
        raise ValueError(f"cannot read dataset {str(path)!r}: sb3_genrl.data.load_actions is not available; "
                         "pass a .npy array of shape (N, T, M) instead") from error
    return np.asarray(load_actions(str(path)))


def _named_generators(models: Sequence[str | os.PathLike | TrajectoryGenerator] | Mapping[str, str | os.PathLike
                      | TrajectoryGenerator]) -> list[tuple[str, str | os.PathLike | TrajectoryGenerator]]:
    if isinstance(models, Mapping):
        return list(models.items())
    named = []
    for index, model in enumerate(models):
        name = Path(model).stem if isinstance(model, str | os.PathLike) else f"{type(model).__name__}{index + 1}"
        named.append((name, model))
    names = [name for name, _ in named]
    if len(set(names)) != len(names):
        raise ValueError(f"model names must be unique, got {names}; pass a mapping name -> model")
    return named


def _as_generator(model: str | os.PathLike | TrajectoryGenerator, device: torch.device | str) -> TrajectoryGenerator:
    if isinstance(model, TrajectoryGenerator):
        return model
    from sb3_genrl.generative import load

    return load(model, device=device)


def write_results(evaluations: Sequence[GeneratorEvaluation], out_dir: str | os.PathLike) -> None:
    """Write ``results.csv``, ``results.md``, the two scatter plots and, last, ``results.json`` into ``out_dir``
    (each file atomically)."""
    out = Path(out_dir)
    rows = [evaluation.row() for evaluation in evaluations]
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=TABLE_COLUMNS)
    writer.writeheader()
    writer.writerows({key: repr(value) if isinstance(value, float) else value for key, value in row.items()}
                     for row in rows)
    atomic_write_text(out / "results.csv", table.getvalue(), newline="")
    lines = ["| " + " | ".join(TABLE_COLUMNS) + " |", "|---" + "|---:" * (len(TABLE_COLUMNS) - 1) + "|"]
    lines += ["| " + " | ".join([str(row["model"])] + [f"{row[c]:.3f}" for c in TABLE_COLUMNS[1:]]) + " |" for row in rows]
    atomic_write_text(out / "results.md", "\n".join(lines) + "\n")
    labels = [str(row["model"]) for row in rows]
    labelled_scatter([row["precision"] for row in rows], [row["recall"] for row in rows], labels,
                     out / "precision_recall.png", xlabel="precision", ylabel="recall", title="Precision and recall")
    labelled_scatter([row["delta_1"] for row in rows], [row["mean_delta"] for row in rows], labels,
                     out / "disentanglement.png", xlabel="delta_1", ylabel="mean delta (delta tilde)",
                     title="Disentanglement (DwPR)")
    details = [{**evaluation.row(), "delta": evaluation.dwpr.delta.tolist(),
                "dwpr_precision": evaluation.dwpr.precision.tolist(), "dwpr_recall": evaluation.dwpr.recall.tolist(),
                "intervention_values": evaluation.dwpr.intervention_values.tolist(), "k": evaluation.dwpr.k,
                "num_real": evaluation.precision_recall.num_real,
                "num_generated": evaluation.precision_recall.num_generated, "dwpr_n": evaluation.dwpr.n}
               for evaluation in evaluations]
    atomic_write_json(out / "results.json", details)  # last: its presence marks a complete evaluation


def evaluate_generators(models: Sequence[str | os.PathLike | TrajectoryGenerator] | Mapping[str, str | os.PathLike
                        | TrajectoryGenerator], data: str | os.PathLike | np.ndarray, *, n: int = DEFAULT_SAMPLES,
                        k: int = 3, dwpr_n: int = DEFAULT_DWPR_SAMPLES, interventions: int = DEFAULT_INTERVENTIONS,
                        seed: int = 0, out_dir: str | os.PathLike, device: torch.device | str = "auto",
                        batch_size: int | None = None) -> list[GeneratorEvaluation]:
    """Precision/recall against real trajectories and DwPR of each generator, written as each model completes.

    The real set is ``n`` trajectories drawn once without replacement (all of them when there are fewer) and
    shared by every model; each model decodes ``n`` prior samples. Files in ``out_dir``: ``results.csv`` and
    ``results.md`` (precision, recall, delta_1, delta_2, mean_delta per model), ``results.json`` (also the
    per-dimension deltas), ``precision_recall.png`` and ``disentanglement.png`` (the paper's scatter plots).

    :param models: generator files (loaded with ``sb3_genrl.generative.load``) or generator objects, or a mapping
        name -> either; names default to file stems
    :param data: real trajectories ``(N, T, M)``: an array, a ``.npy`` file or a dataset path
    :param n: real and generated samples for precision and recall (paper: 15000)
    :param k: neighbourhood size (paper: 3)
    :param dwpr_n: prior samples per intervention for DwPR (paper: 10000)
    :param interventions: number of DwPR interventions per latent dimension (paper: 5)
    :param seed: seed of the real subset, the prior samples and DwPR
    :param out_dir: output folder (created)
    :param device: torch device for loading and distances; ``"auto"`` uses a GPU when there is one
    :param batch_size: edge length of the distance blocks (default: from the memory budget)
    :return: the evaluations, in model order
    """
    named = _named_generators(models)
    if not named:
        raise ValueError("no models given")
    real = load_real_trajectories(data)
    if real.ndim != 3:
        raise ValueError(f"real trajectories must have shape (N, T, M), got {real.shape}")
    rng = np.random.default_rng(seed)
    if len(real) > n:
        real = real[np.sort(rng.choice(len(real), size=n, replace=False))]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    evaluations: list[GeneratorEvaluation] = []
    for index, (name, model) in enumerate(named):
        generator = _as_generator(model, device)
        if (generator.horizon, generator.action_dim) != real.shape[1:]:
            raise ValueError(f"model {name!r} generates (horizon, action_dim) = {(generator.horizon, generator.action_dim)}"
                             f", the real trajectories have {real.shape[1:]}")
        model_seed = np.random.SeedSequence([seed, index])
        prior_rng, dwpr_rng = (np.random.default_rng(s) for s in model_seed.spawn(2))
        generated = decode_batched(generator, generator.sample_prior(n, prior_rng))
        pr = precision_recall(real, generated, k, batch_size=batch_size, device=device)
        disentanglement = dwpr(generator, dwpr_n, interventions, k, seed=dwpr_rng, batch_size=batch_size, device=device)
        evaluations.append(GeneratorEvaluation(name, pr, disentanglement))
        write_results(evaluations, out)
    return evaluations
