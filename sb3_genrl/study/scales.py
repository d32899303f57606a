"""Scale presets of the study (paper section 6 at three sizes)."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class StudyScale:
    """How big each stage of the study is.

    :param demo_episodes: demonstrations per task (paper: 40000)
    :param generator_epochs: training epochs of each generator (paper: 5000)
    :param eval_every: epochs between model-selection evaluations
    :param pr_samples: samples per set for precision/recall (paper: 15000)
    :param dwpr_samples: samples per intervention for DwPR (paper: 10000, 5 interventions)
    :param policy_episodes: GenRL episodes per run
    :param batch_episodes: GenRL episodes per EM iteration
    :param seeds: GenRL seeds per generator (paper: 3)
    :param baseline_episodes: episodes of the baseline comparison runs (0: no comparison)
    :param bc_eval_goals: held-out goals on which the behaviour-cloned policy is evaluated before PPO
    """

    demo_episodes: int
    generator_epochs: int
    eval_every: int
    pr_samples: int
    dwpr_samples: int
    policy_episodes: int
    batch_episodes: int
    seeds: int = 3
    baseline_episodes: int = 0
    bc_eval_goals: int = 100

    def as_dict(self) -> dict:
        return asdict(self)


SCALES: dict[str, StudyScale] = {
    # Seconds per generator: checks that every stage runs and every table and plot is written (one seed).
    "smoke": StudyScale(demo_episodes=160, generator_epochs=2, eval_every=1, pr_samples=100, dwpr_samples=40,
                        policy_episodes=32, batch_episodes=16, seeds=1, baseline_episodes=2, bc_eval_goals=2),
    # A 2-core CPU in well under an hour per task.
    "small": StudyScale(demo_episodes=4000, generator_epochs=150, eval_every=10, pr_samples=2000, dwpr_samples=1000,
                        policy_episodes=960, batch_episodes=64, seeds=3, baseline_episodes=192),
    # The paper's sizes (sections 6.1.2-6.1.4): a GPU or a cluster. The baselines run the budget of
    # benchmarks/baselines.py (3000 episodes, 3 seeds; their settings are the library's defaults there and here).
    "paper": StudyScale(demo_episodes=40000, generator_epochs=5000, eval_every=50, pr_samples=15000, dwpr_samples=10000,
                        policy_episodes=10000, batch_episodes=64, seeds=3, baseline_episodes=3000),
}
