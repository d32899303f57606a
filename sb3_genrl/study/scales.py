"""Scale presets of the study (paper section 6 at three sizes), and the settings a scale gives one task."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from sb3_genrl.envs import basketball, hockey
from sb3_genrl.study.quickstart import task_settings

_HOCKEY, _BASKETBALL = hockey.TASK.name, basketball.TASK.name


@dataclass(frozen=True)
class StudyScale:
    """How big each stage of the study is.

    A setting given per task (``policy_episodes``, ``seeds``) is a number for every task or a mapping from task name
    to number; :func:`task_scale` reads a task's.

    :param demo_episodes: demonstrations per task (paper: 40000)
    :param generator_epochs: training epochs of each generator (paper: 5000)
    :param eval_every: epochs between model-selection evaluations
    :param pr_samples: samples per set for precision/recall (paper: 15000)
    :param dwpr_samples: samples per intervention for DwPR (paper: 10000, 5 interventions)
    :param policy_episodes: GenRL episodes per run, per task
    :param batch_episodes: GenRL episodes per EM iteration (None: each task's own, from ``hyperparams/genrl.yml``)
    :param seeds: GenRL seeds per generator, per task (paper: 3)
    :param baseline_episodes: episodes of the baseline comparison runs (0: no comparison)
    :param bc_eval_goals: held-out goals on which the behaviour-cloned policy is evaluated before PPO
    :param prior_contexts: goals of the prior rollout (:mod:`sb3_genrl.metrics.prior_rollout`)
    :param prior_draws: prior draws per goal of the prior rollout
    """

    demo_episodes: int
    generator_epochs: int
    eval_every: int
    pr_samples: int
    dwpr_samples: int
    policy_episodes: int | Mapping[str, int]
    batch_episodes: int | None = None
    seeds: int | Mapping[str, int] = 3
    baseline_episodes: int = 0
    bc_eval_goals: int = 100
    prior_contexts: int = 64
    prior_draws: int = 16

    def as_dict(self) -> dict:
        return {key: dict(value) if isinstance(value, Mapping) else value for key, value in asdict(self).items()}


def task_scale(scale: Mapping[str, Any], task: str) -> dict[str, Any]:
    """The settings of ``scale`` (:meth:`StudyScale.as_dict`) for one task: its own value of each per-task setting,
    and its own episodes per iteration (``hyperparams/genrl.yml``) where the scale leaves them to the task.

    :param scale: a scale as a dict
    :param task: a task name
    """
    resolved = dict(scale)
    for key in ("policy_episodes", "seeds"):
        value = scale[key]
        if isinstance(value, Mapping):
            if task not in value:
                raise ValueError(f"the scale gives {key} for {sorted(value)}, not for {task!r}")
            resolved[key] = value[task]
    if scale.get("batch_episodes") is None:
        resolved["batch_episodes"] = task_settings(task)[1]
    return resolved


SCALES: dict[str, StudyScale] = {
    # Seconds per generator: checks that every stage runs and every table and plot is written (one seed).
    "smoke": StudyScale(
        demo_episodes=160,
        generator_epochs=2,
        eval_every=1,
        pr_samples=100,
        dwpr_samples=40,
        policy_episodes=32,
        seeds=1,
        baseline_episodes=2,
        bc_eval_goals=2,
        prior_contexts=4,
        prior_draws=2,
    ),
    # A few hours of a 2-core CPU per task (docs/guide/study.md has the estimate from measured stage times): 600
    # epochs let the InfoGANs train (150 left most below precision 0.15); each task plays its own episodes per
    # iteration, and basketball's settings anneal the policy's spread over many more episodes than hockey's need,
    # so it runs 2 seeds of 12000 where hockey runs 3 of 1024.
    "small": StudyScale(
        demo_episodes=4000,
        generator_epochs=600,
        eval_every=25,
        pr_samples=2000,
        dwpr_samples=1000,
        policy_episodes={_HOCKEY: 1024, _BASKETBALL: 12000},
        seeds={_HOCKEY: 3, _BASKETBALL: 2},
        baseline_episodes=192,
    ),
    # The paper's sizes (sections 6.1.2-6.1.4) and each task's budget of hyperparams/genrl.yml: a GPU or a cluster.
    # The baselines run the budget of benchmarks/baselines.py (3000 episodes, 3 seeds; their settings are the
    # library's defaults there and here).
    "paper": StudyScale(
        demo_episodes=40000,
        generator_epochs=5000,
        eval_every=50,
        pr_samples=15000,
        dwpr_samples=10000,
        policy_episodes={_HOCKEY: 3000, _BASKETBALL: 20000},
        seeds=3,
        baseline_episodes=3000,
        prior_contexts=100,
        prior_draws=100,
    ),
}
