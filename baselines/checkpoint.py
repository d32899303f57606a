"""What the checkpoints of the off-policy baselines (SAC, SAC without prefill, SAC + HER) add to the run layer's
(:mod:`sb3_genrl.run.checkpoint`, the mechanism GenRL's checkpoints use too), so that a stopped run resumes.

A run of 3000 episodes takes about an hour of one core (one gradient step per environment step). Every
``checkpoint_every`` episodes, at the end of an episode and after its last gradient step, :class:`ReplayBufferCheckpoint`
writes into ``OUT/checkpoint/`` the model (SB3's zip: weights, optimisers, entropy coefficient, step counters), its
replay buffer (SB3's ``save_replay_buffer``) and ``state.json``: the run's identity, the episodes and steps done, the
Monitor file's clock and CPU seconds at that point, the seconds trained so far, and the names of this checkpoint's own
model and buffer files, as one unit.

Training the same run into the same folder again resumes from it (:func:`~sb3_genrl.run.checkpoint.resume_state`,
:func:`~sb3_genrl.run.folder.keep_episodes`, :func:`resume_off_policy`): the Monitor file keeps its first rows up to
the checkpoint (later ones are played again), the model and buffer are loaded, and training goes on for the steps left.
A resumed run is not bitwise the uninterrupted one (the random streams restart), and its ``logs/progress.csv`` starts
at the checkpoint (the earlier one is kept as ``progress.until_episode_K.csv``). A finished run removes its checkpoint.
A checkpoint of another run (other settings) is refused, naming what differs.
"""

from __future__ import annotations

import os
import pathlib
import time
from collections.abc import Callable
from typing import Any

from stable_baselines3 import SAC
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

from sb3_genrl.run.checkpoint import EpisodeCheckpoint, continue_clocks

MODEL, BUFFER = "model.zip", "replay_buffer.pkl"


class ReplayBufferCheckpoint(EpisodeCheckpoint):
    """An off-policy run's checkpoint: every ``every`` episodes, the model and its replay buffer (see the module doc).

    :param out: the run folder (the checkpoint goes into ``out/checkpoint``)
    :param every: episodes between checkpoints
    :param identity: what the run is (algorithm, task, budget, seed, settings), checked on resume
    :param start: the state the run was resumed from (its ``"episodes"`` and ``"learn_seconds"``; ``None``: a new run)
    :param extra: further entries of ``state.json`` (e.g. the setup's timings and records for the summary)
    """

    def __init__(
        self,
        out: str | os.PathLike[str],
        every: int,
        identity: dict[str, Any],
        start: dict[str, Any] | None,
        extra: dict[str, Any],
    ) -> None:
        super().__init__(out, every, identity, start)
        self.extra = extra
        self.start_seconds = 0.0 if start is None else float(start["learn_seconds"])
        self._began = time.perf_counter()

    def _files(self) -> dict[str, tuple[str, Callable[[pathlib.Path], None]]]:
        return {"model": (MODEL, self.model.save), "buffer": (BUFFER, self.model.save_replay_buffer)}

    def _state(self) -> dict[str, Any]:
        return {
            "steps": int(self.model.num_timesteps),
            "learn_seconds": self.start_seconds + time.perf_counter() - self._began,
            **self.extra,
        }

    def _cpu_seconds(self) -> float:
        """The one env's CPU seconds, a number (as these checkpoints have always recorded them)."""
        (seconds,) = super()._cpu_seconds()
        return seconds


def resume_off_policy(
    state: dict[str, Any], env: Monitor, *, device: str, algorithm: type[OffPolicyAlgorithm] = SAC
) -> OffPolicyAlgorithm:
    """The model as the checkpoint ``state`` left it, with its replay buffer, on ``env`` (a new Monitor of the run,
    which starts with a reset), the Monitor's clocks going on from the checkpoint's.

    :param state: the checkpoint's state (:func:`~sb3_genrl.run.checkpoint.resume_state`)
    :param env: the resumed run's Monitor (over :func:`sb3_genrl.curves.episode_info`'s wrapper)
    :param device: the torch device to load the model on
    :param algorithm: the model's SB3 class
    """
    continue_clocks(env, state)
    model = algorithm.load(state["paths"]["model"], env=env, device=device)
    model.load_replay_buffer(state["paths"]["buffer"])
    return model
