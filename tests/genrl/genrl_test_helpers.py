"""Helpers shared by the tests of sb3_genrl.genrl: goals of the toy bandit, a toy whose pulls can be relabelled, and
callbacks and GenRL subclasses that record what training saw."""

from __future__ import annotations

import itertools

import numpy as np
import torch as th
from conftest import FastReachEnv
from stable_baselines3.common.callbacks import BaseCallback

from sb3_genrl import GenRL

GOALS = np.array([[0.5, -0.3], [-0.6, 0.4], [0.0, 0.6], [0.3, 0.3]], dtype=np.float32)
TOY_ID = "GenRLTest/FastReach-v0"


class HindsightReachEnv(FastReachEnv):
    """FastReachEnv whose pulls are relabelled with the point they reached (reward 0 there, the maximum)."""

    def hindsight(self, info):
        return np.asarray(info["reached"], dtype=np.float32), 0.0


class SuccessReachEnv(HindsightReachEnv):
    """HindsightReachEnv that reports ``info["is_success"]``: the reached point within 0.5 of the goal."""

    def play_trajectories(self, trajectories, goals, *, n_threads=1):
        rewards, infos = super().play_trajectories(trajectories, goals, n_threads=n_threads)
        for reward, info in zip(rewards, infos, strict=True):
            info["is_success"] = bool(reward > -0.25)
        return rewards, infos


class SuccessOnlyReachEnv(FastReachEnv):
    """FastReachEnv that reports ``info["is_success"]`` (the reached point within 0.5 of the goal) and no
    relabelling: no ``hindsight(info)``, as a task from outside the package (Meta-World)."""

    def play_trajectories(self, trajectories, goals, *, n_threads=1):
        rewards, infos = super().play_trajectories(trajectories, goals, n_threads=n_threads)
        for reward, info in zip(rewards, infos, strict=True):
            info["is_success"] = bool(reward > -0.25)
        return rewards, infos


class EStepBatchRecorder(GenRL):
    """GenRL that keeps its first E-step batch, with V and the policy's log-probabilities then."""

    def _e_step(self, q, batch):
        if not hasattr(self, "recorded"):
            observations = batch[0]
            with th.no_grad():
                values = self.policy.predict_values(observations).flatten()
                log_prob = self.policy.get_distribution(observations).log_prob(batch[1])
            self.recorded = ([t.clone() for t in batch], values, log_prob, self.rollout_buffer.advantages.copy())
        return super()._e_step(q, batch)


class Recorder(BaseCallback):
    """A callback that records with ``_record`` at the start of every rollout and at the end of training."""

    def _record(self) -> None:
        raise NotImplementedError

    def _on_rollout_start(self) -> None:
        self._record()

    def _on_training_end(self) -> None:
        self._record()

    def _on_step(self) -> bool:
        return True


def box_corners(dim: int) -> th.Tensor:
    """The 2^dim corners of [-1, 1]^dim."""
    return th.tensor(list(itertools.product((-1.0, 1.0), repeat=dim)))
