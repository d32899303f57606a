"""Evaluation of generative models (paper section 5.2): precision and recall, DwPR, correlation with policy scores;
beyond the paper, density and coverage (Naeem et al., 2020), the prior rollout on the task and the ranked scorecard."""

from sb3_genrl.metrics.correlation import MEASURES, CorrelationRow, CorrelationTable, correlation_table, pearson
from sb3_genrl.metrics.density_coverage import DensityCoverage, density_coverage
from sb3_genrl.metrics.dwpr import DwPR, default_intervention_values, dwpr
from sb3_genrl.metrics.evaluate import GeneratorEvaluation, evaluate_generator, evaluate_generators, real_subset
from sb3_genrl.metrics.plots import labelled_scatter
from sb3_genrl.metrics.precision_recall import PrecisionRecall, precision_recall
from sb3_genrl.metrics.prior_rollout import PriorRollout, prior_rollout

__all__ = [
    "MEASURES",
    "CorrelationRow",
    "CorrelationTable",
    "DensityCoverage",
    "DwPR",
    "GeneratorEvaluation",
    "PrecisionRecall",
    "PriorRollout",
    "correlation_table",
    "default_intervention_values",
    "density_coverage",
    "dwpr",
    "evaluate_generator",
    "evaluate_generators",
    "labelled_scatter",
    "pearson",
    "precision_recall",
    "prior_rollout",
    "real_subset",
]
