"""A training run's folder (``genrl train-policy``, ``genrl baseline``): one run at a time, and never two runs mixed.

Before it writes anything else, a run records what it is (its task, budget, seed, settings and inputs) in
``run_record.json``, and it writes ``summary.json`` last, when it has finished. A rerun into the same folder, under
the folder's lock (:func:`~sb3_genrl.utils.folder_lock`), then does one of these (:func:`open_run`):

- **another run** (another record, or a run's files without a record) is refused before anything is changed, naming
  what differs;
- **the same run, finished**: nothing is done, and the finished run's summary is returned;
- **the same run, unfinished**: it resumes from its checkpoint when it has one, else starts again from its first
  episode, the unfinished run's files removed first;
- ``overwrite=True`` (``--overwrite``) removes the files a run writes (and only those) and starts afresh.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sb3_genrl.curves import LOG_DIR, MONITOR_FILE
from sb3_genrl.utils import CHECKPOINT_STATE, atomic_write_json, atomic_write_text

RUN_RECORD = "run_record.json"
SUMMARY = "summary.json"
CHECKPOINT_DIR = "checkpoint"


class RunFolderError(ValueError):
    """A run folder holds another run than the one asked for (see :func:`open_run`)."""


def open_run(
    out: str | os.PathLike[str], identity: Mapping[str, Any], outputs: Sequence[str], *, overwrite: bool = False
) -> dict[str, Any] | None:
    """Make ``out`` ready for the run ``identity`` (see the module doc); call it holding the folder's lock.

    :param out: the run folder
    :param identity: what the run is (JSON values): compared with the record of a run already in ``out``
    :param outputs: the names of the files and folders the run writes in ``out`` (besides ``summary.json``,
        ``checkpoint/`` and the record), or glob patterns of them (``logs/events.out.tfevents.*``): a folder the
        run shares with other files is named by the patterns of its own files in it, so that only those are removed
    :param overwrite: remove a run already in ``out`` (its files only) instead of refusing or resuming it
    :return: the summary of the same run finished in ``out`` (then nothing is to be done), else ``None``: ``out``
        holds at most this run's checkpoint, to resume from
    """
    out, identity = Path(out), _normal(identity)
    present = sorted(
        {
            path.relative_to(out).as_posix()
            for name in (*outputs, SUMMARY, CHECKPOINT_DIR, RUN_RECORD)
            for path in out.glob(name)
        }
    )
    recorded = _read_record(out)
    if not overwrite and present:
        if recorded is None:
            raise RunFolderError(
                f"{out} holds a run's files ({', '.join(present)}) but no {RUN_RECORD} saying what run "
                "made them. Nothing was changed: choose another output folder (--out), or pass --overwrite "
                "(overwrite=True) to replace those files"
            )
        if recorded != identity:
            raise RunFolderError(
                f"{out} holds another run (it differs in {', '.join(differing(recorded, identity))}). "
                f"Nothing was changed: {_WAYS_OUT}"
            )
        if (out / SUMMARY).is_file():
            return json.loads((out / SUMMARY).read_text())
    if overwrite or not (out / CHECKPOINT_DIR / CHECKPOINT_STATE).is_file():
        _remove(out, present)
    atomic_write_json(out / RUN_RECORD, identity)
    return None


def differing(recorded: Mapping[str, Any], identity: Mapping[str, Any]) -> list[str]:
    """The keys whose values differ between two runs' records (a key missing from one counts), sorted."""
    return sorted(key for key in set(recorded) | set(identity) if recorded.get(key) != identity.get(key))


_WAYS_OUT = (
    "rerun with that run's settings, choose another output folder (--out), or pass --overwrite (overwrite=True) to replace it"
)


def _read_record(out: Path) -> dict[str, Any] | None:
    path = out / RUN_RECORD
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise RunFolderError(f"cannot read {path} ({error}); pass --overwrite to replace the run") from None
    return record if isinstance(record, dict) else {}


def _remove(out: Path, names: Sequence[str]) -> None:
    """Remove the run's files and folders ``names`` in ``out``, then the folders they were in that are left empty."""
    parents = set()
    for name in names:
        path = out / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)
        parents.update(parent for parent in path.parents if out in parent.parents)
    for parent in sorted(parents, key=lambda folder: len(folder.parts), reverse=True):
        if parent.is_dir() and not any(parent.iterdir()):
            parent.rmdir()


def _normal(value: Mapping[str, Any]) -> dict[str, Any]:
    return json.loads(json.dumps(dict(value)))  # as the record reads back: tuples as lists, keys as strings


def keep_episodes(out: str | os.PathLike[str], episodes: int) -> None:
    """Before a run resumes from its checkpoint at ``episodes``: keep the Monitor file's rows up to it (the later ones
    are played again) and set the training log aside as ``logs/progress.until_episode_<episodes>.csv`` (SB3's logger
    starts a new one). A second resume from the same checkpoint keeps the log the first set aside (the one since
    then is of episodes played again).

    :param out: the run folder
    :param episodes: the episodes the checkpoint had played
    """
    out = Path(out)
    monitor_file = out / MONITOR_FILE
    lines = monitor_file.read_text().splitlines(keepends=True)
    kept = 2 + int(episodes)  # the JSON header, the column names, one row per episode
    if len(lines) < kept:
        raise ValueError(
            f"{monitor_file} holds {len(lines) - 2} episodes, fewer than its checkpoint's {episodes}; "
            "pass --overwrite to start the run afresh"
        )
    atomic_write_text(monitor_file, "".join(lines[:kept]), newline="")
    progress = out / LOG_DIR / "progress.csv"
    earlier = progress.with_name(f"progress.until_episode_{episodes}.csv")
    if earlier.is_file():
        progress.unlink(missing_ok=True)
    elif progress.is_file():
        os.replace(progress, earlier)


def remove_checkpoint(out: str | os.PathLike[str]) -> None:
    """Remove the run's checkpoint (a finished run)."""
    shutil.rmtree(Path(out) / CHECKPOINT_DIR, ignore_errors=True)
