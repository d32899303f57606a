"""The run layer: a training run's folder, lock, settings record, checkpoints and summary, and the workflow that
trains a GenRL policy for a task (:func:`train_policy`), as ``genrl train-policy`` runs it."""

from sb3_genrl.run.train import evaluate_on_goals, train_policy, training_env

__all__ = ["evaluate_on_goals", "train_policy", "training_env"]
