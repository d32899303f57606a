"""Checkpoints of the off-policy baselines (SAC, SAC without prefill, SAC + HER), so that a stopped run resumes.

A run of 3000 episodes takes about an hour of one core (one gradient step per environment step). Every
``checkpoint_every`` episodes, at the end of an episode and after its last gradient step, :class:`EpisodeCheckpoint`
writes into ``OUT/checkpoint/`` the model (SB3's zip: weights, optimisers, entropy coefficient, step counters), its
replay buffer (SB3's ``save_replay_buffer``) and ``state.json``: the run's identity, the episodes and steps done, the
Monitor file's clock and CPU seconds at that point, and the names of this checkpoint's own model and buffer files.
The checkpoint is one unit (:func:`sb3_genrl.utils.write_checkpoint`): its files are written under new names and
``state.json`` replaces the previous one last, so a run killed at any moment (or a full disk) leaves the previous
checkpoint whole, never a new model beside an old buffer and state.

Training the same run into the same folder again resumes from it (:func:`resume_state`): the Monitor file keeps its
first rows up to the checkpoint (later ones are played again), the model and buffer are loaded, and training goes on
for the steps left. A resumed run is not bitwise the uninterrupted one (the random streams restart), and its
``logs/progress.csv`` starts at the checkpoint (the earlier one is kept as ``progress.until_episode_K.csv``). A
finished run removes its checkpoint. A checkpoint of another run (other settings) is refused, naming what differs.
"""

from __future__ import annotations

import pathlib
import time
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor

from sb3_genrl.curves import _EpisodeInfo
from sb3_genrl.run.folder import CHECKPOINT_DIR, differing, keep_episodes, remove_checkpoint  # noqa: F401 (re-exported)
from sb3_genrl.utils import read_checkpoint, write_checkpoint

MODEL, BUFFER = "model.zip", "replay_buffer.pkl"


class EpisodeCheckpoint(BaseCallback):
    """Write a checkpoint every ``every`` episodes (see the module doc).

    :param folder: the checkpoint folder (``OUT/checkpoint``)
    :param every: episodes between checkpoints
    :param identity: what the run is (algorithm, task, budget, seed, settings), checked on resume
    :param start: the state the run started from (``episodes``, ``steps``, ``learn_seconds``; zeros for a new run)
    :param extra: further entries of ``state.json`` (e.g. the setup's timings and records for the summary)
    """

    def __init__(
        self, folder: pathlib.Path, every: int, identity: dict[str, Any], start: dict[str, Any], extra: dict[str, Any]
    ) -> None:
        super().__init__()
        self.folder, self.every, self.identity, self.start, self.extra = folder, int(every), identity, start, extra
        self._seen = 0  # episodes this process has seen end
        self._last = int(start["episodes"])
        self._began = time.perf_counter()

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:
        # Called before each step is collected, after the previous step's gradient step (train_freq = 1 step).
        monitor = _monitor(self.model)
        ended = len(monitor.get_episode_lengths())
        if ended == self._seen:  # no episode ended on the last step: not at an episode's end
            return
        self._seen = ended
        episodes = int(self.start["episodes"]) + ended
        if episodes - self._last >= self.every:
            self.save(episodes)
            self._last = episodes

    def save(self, episodes: int) -> None:
        """Write the model, its replay buffer and then the state naming them, as one unit (see the module doc)."""
        monitor = _monitor(self.model)
        write_checkpoint(
            self.folder,
            {"model": (MODEL, self.model.save), "buffer": (BUFFER, self.model.save_replay_buffer)},
            {
                "identity": self.identity,
                "episodes": episodes,
                "steps": int(self.model.num_timesteps),
                "monitor_seconds": time.time() - monitor.t_start,
                "cpu_seconds": _episode_info(monitor).cpu_seconds(),
                "learn_seconds": float(self.start["learn_seconds"]) + time.perf_counter() - self._began,
                **self.extra,
            },
        )


def resume_state(out: pathlib.Path, identity: dict[str, Any]) -> dict[str, Any] | None:
    """The checkpoint's state if ``out`` holds one of this run, else ``None``; raises ``ValueError`` for another run's.
    Its ``"paths"`` entry names the checkpoint's ``"model"`` and ``"buffer"`` files."""
    state = read_checkpoint(out / CHECKPOINT_DIR)
    if state is None:
        return None
    recorded = state["identity"]
    if recorded != identity:
        raise ValueError(
            f"{out} holds a checkpoint of another run (it differs in "
            f"{', '.join(differing(recorded, identity))}); use another "
            f"out_dir, or delete {out / CHECKPOINT_DIR} to start this run afresh"
        )
    return state


def prepare_resume(out: pathlib.Path, state: dict[str, Any]) -> None:
    """Keep the Monitor file's rows up to the checkpoint and set the earlier training log aside (once per checkpoint: a
    second resume from the same checkpoint keeps the log set aside by the first; see
    :func:`sb3_genrl.run.folder.keep_episodes`)."""
    keep_episodes(out, int(state["episodes"]))


def continue_clocks(monitor: Monitor, state: dict[str, Any]) -> None:
    """Make the resumed Monitor's ``t`` and ``cpu_seconds`` columns go on from the checkpoint's."""
    monitor.t_start = time.time() - float(state["monitor_seconds"])
    _episode_info(monitor).continue_from(float(state["cpu_seconds"]))


def _monitor(model: Any) -> Monitor:
    env = model.get_env().envs[0]
    if not isinstance(env, Monitor):
        raise TypeError(f"the checkpointed run's env must be a Monitor, got {type(env).__name__}")
    return env


def _episode_info(monitor: Monitor) -> Any:
    if not isinstance(monitor.env, _EpisodeInfo):
        raise TypeError("the checkpointed run's Monitor must wrap sb3_genrl.curves.episode_info's wrapper")
    return monitor.env
