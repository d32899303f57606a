"""The study report's numbers: which models are ranked, the tables' rows, the ranking's stability, the correlations.

A model whose precision is below :data:`~sb3_genrl.metrics.scorecard.NOT_CONVERGED_PRECISION` is reported as not
converged: it keeps its rows in tables 1 and 4-5, but is left out of every correlation and of the stability, which
would otherwise measure under-training rather than the model family.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sb3_genrl.metrics import MEASURES, correlation_table
from sb3_genrl.metrics.bootstrap import DEFAULT_RESAMPLES, bootstrap_correlations, spearman
from sb3_genrl.metrics.scorecard import NOT_CONVERGED_PRECISION, converged

# Beyond the paper's measures: density and coverage, and the prior rollout's median best reward per goal.
SCORECARD_MEASURES = ("density", "coverage", "prior_median")
STABILITY_TARGET = 0.9  # Spearman's rho of the ranking at half the budget and at the full budget


def status(row: dict[str, Any]) -> str:
    return "ok" if converged(row) else "not converged"


def table1(rows: list[dict[str, Any]]) -> tuple[list[str], list[list[Any]]]:
    """Paper table 1 with GenRL's rewards: best (paper 6.1.3), best within half the budget, final."""
    header = [
        "model",
        "N_alpha",
        "beta / lambda",
        "best reward",
        "reward per seed",
        "best at half budget",
        "final reward (mean)",
        "status",
    ]
    return header, [
        [
            r["model"],
            r["latent_dim"],
            r["beta"] if r["type"] == "VAE" else r["info_weight"],
            r["score"],
            " / ".join(f"{x:.3f}" for x in r["rewards"]),
            r["half_score"],
            r["final"],
            status(r),
        ]
        for r in rows
    ]


def measures_table(rows: list[dict[str, Any]]) -> tuple[list[str], list[list[Any]]]:
    """Tables 4-5 (precision, recall, disentanglement) with density, coverage and the prior rollout."""
    header = ["model", *MEASURES, "density", "coverage", "prior median", "prior quartiles"]
    return header, [
        [
            r["model"],
            *(r[m] for m in MEASURES),
            r["density"],
            r["coverage"],
            r["prior_median"],
            f"{r['prior_q25']:.3f} .. {r['prior_q75']:.3f}",
        ]
        for r in rows
    ]


def selection_table(rows: list[dict[str, Any]]) -> tuple[list[str], list[list[Any]]]:
    """Each generator's model-selection error (paper appendix B) at its first and last evaluation and at the epoch
    kept, with its precision and status."""
    header = [
        "model",
        "evaluations",
        "selection MSE first",
        "selection MSE kept",
        "epoch kept",
        "selection MSE last",
        "precision",
        "status",
    ]
    table = []
    for r in rows:
        errors = [mse for _, mse in r["selection"]]
        kept = dict(map(tuple, r["selection"])).get(r["best_epoch"], math.nan)
        table.append(
            [
                r["model"],
                len(errors),
                errors[0] if errors else math.nan,
                kept,
                r["best_epoch"],
                errors[-1] if errors else math.nan,
                r["precision"],
                status(r),
            ]
        )
    return header, table


def stability(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Spearman's rho between the converged models' best rewards within half the budget and within all of it, with
    its 95% bootstrap interval."""
    ranked = [r for r in rows if converged(r)]
    half = np.array([r["half_score"] for r in ranked])
    full = np.array([r["score"] for r in ranked])
    rho, _ = spearman(half, full)
    _, interval = bootstrap_correlations(half, full) if len(ranked) >= 3 else (None, None)
    return {
        "models": len(ranked),
        "rho": rho,
        "low": interval.low if interval else math.nan,
        "high": interval.high if interval else math.nan,
        "target": STABILITY_TARGET,
        "stable": bool(math.isfinite(rho) and rho >= STABILITY_TARGET),
    }


def stability_line(result: dict[str, Any]) -> str:
    what = (
        f"Spearman's rho between the {result['models']} converged generators' best rewards within the first half "
        "of the budget and within all of it"
    )
    if not math.isfinite(result["rho"]):
        return f"{what}: undefined (fewer than 3 converged generators, or constant rewards)."
    verdict = "meets" if result["stable"] else "does not meet"
    return (
        f"{what}: **{result['rho']:.3f}** (95% bootstrap interval [{result['low']:.2f}, {result['high']:.2f}], "
        f"{DEFAULT_RESAMPLES} resamples); this {verdict} the target rho >= {result['target']}."
    )


def correlations(rows: list[dict[str, Any]]):
    """Tables 2-3 over the converged models: each paper measure against the best reward, per type and for all."""
    return correlation_table([r for r in rows if converged(r)], measure_names=list(MEASURES), score_key="score")


def predictions(rows: list[dict[str, Any]], score_key: str):
    """Every measure of the scorecard against one reward (``score`` or ``final``), over all converged models."""
    return correlation_table(
        [r for r in rows if converged(r)],
        measure_names=[*MEASURES, *SCORECARD_MEASURES],
        score_key=score_key,
        type_key="_no_type",
    )


def all_tasks_correlations(rows_by_task: dict[str, list[dict[str, Any]]]):
    """Paper table 6: each paper measure against the best reward over the converged models of every task together,
    pooled as the paper pools them (each task's own rewards)."""
    pooled = [{**r, "model": f"{task}/{r['model']}"} for task, rows in rows_by_task.items() for r in rows if converged(r)]
    return correlation_table(pooled, measure_names=list(MEASURES), score_key="score", type_key="_no_type")


def excluded_line(rows: list[dict[str, Any]]) -> str:
    names = [f"{r['model']} ({r['precision']:.3f})" for r in rows if not converged(r)]
    rule = (
        f"A generator whose precision is below {NOT_CONVERGED_PRECISION} is reported as not converged and left "
        "out of every correlation and of the stability"
    )
    return f"{rule}: {', '.join(names)}." if names else f"{rule}; every generator here reaches it."


def cpu_line(rows: list[dict[str, Any]]) -> str:
    """The CPU time the generators' stages took, summed over the models (from each stage's own record)."""
    totals = {
        stage: sum(r.get("cpu_seconds", {}).get(stage, math.nan) for r in rows)
        for stage in ("generator", "evaluation", "genrl")
    }
    total = sum(totals.values())
    parts = ", ".join(f"{stage} {seconds / 3600:.2f} h" for stage, seconds in totals.items())
    return (
        f"CPU time of the {len(rows)} generators' stages: {total / 3600:.2f} h ({parts}; one core each, as recorded "
        "when each stage ran; nan: a stage made by a version that recorded none). The demonstrations and the "
        "baselines are not counted."
    )
