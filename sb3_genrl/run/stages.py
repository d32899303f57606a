"""What makes a stage's folder (a study's, a quickstart's, a cached generator's) safe to resume: recorded settings,
fingerprints, a lock, worker exit.

- **Recorded settings.** Each resumable stage writes the settings that produce it (``stage.json`` next to its
  output) before it starts, and a rerun compares them with its own before it does any work
  (:func:`settings_conflicts`, :func:`refuse_conflicts`). A stage whose output exists without a record (an older
  version wrote it) counts as a conflict too, so no result of unknown settings is reused or reported.
- **Fingerprints** (:func:`~sb3_genrl.data.fingerprints.dataset_fingerprint`,
  :func:`~sb3_genrl.data.fingerprints.file_fingerprint`) tie a stage to the exact inputs it used: a generator to its
  demonstrations, a policy to its generator.
- **A lock** (:func:`~sb3_genrl.utils.folder_lock`, shared with ``genrl train-policy`` and ``genrl baseline``)
  keeps a second process out of a folder while one works in it; the operating system releases it when the holder
  exits, however it exits.
- **Worker exit** (:func:`exit_with_parent`): worker processes end when the process that started them dies.

"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sb3_genrl.utils import atomic_write_json

STAGE_FILE = "stage.json"


class SettingsConflictError(ValueError):
    """A rerun asks for other settings than those recorded in a folder it would resume."""


def read_settings(record: str | os.PathLike) -> dict[str, Any] | None:
    """The settings recorded in ``record`` (a ``stage.json``), or None when there is none.

    :param record: the record file
    """
    record = Path(record)
    if not record.is_file():
        return None
    try:
        value = json.loads(record.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise ValueError(
            f"cannot read the recorded settings {str(record)!r}: {error}; delete the stage folder to redo it"
        ) from None
    if not isinstance(value, dict):
        raise ValueError(f"{str(record)!r} holds no settings (a JSON object was expected); delete the stage folder to redo it")
    return value


def settings_conflicts(
    where: str | os.PathLike, recorded: Mapping[str, Any] | None, wanted: Mapping[str, Any], *, output_exists: bool = True
) -> list[str]:
    """The differences between a stage's recorded settings and a run's, one line each (empty when they agree).

    Only the keys of ``wanted`` are compared, so a check can leave out what is not known yet (a fingerprint of an
    input still to be made). A stage with output but no record conflicts: its settings are unknown.

    :param where: the stage's folder or output, named in the lines
    :param recorded: the recorded settings (None: no record)
    :param wanted: the settings of this run
    :param output_exists: whether the stage has written anything (only then does a missing record conflict)
    :return: lines such as ``"FOLDER: epochs 2 (recorded) vs 150 (this run)"``
    """
    if recorded is None:
        return [f"{where}: no recorded settings (written by an older version of sb3-genrl)"] if output_exists else []
    differing = [
        f"{key} {_show(recorded[key]) if key in recorded else 'unset'} (recorded) vs {_show(value)} (this run)"
        for key, value in wanted.items()
        if key not in recorded or _normal(recorded[key]) != _normal(value)
    ]
    return [f"{where}: {', '.join(differing)}"] if differing else []


def _normal(value: Any) -> Any:
    return json.loads(json.dumps(value))  # tuples and lists, ints and floats as JSON has them


def _show(value: Any) -> str:
    return json.dumps(value) if isinstance(value, str | list | tuple | dict) else str(value)


def refuse_conflicts(folder: str | os.PathLike, conflicts: list[str]) -> None:
    """Raise :class:`SettingsConflictError` listing ``conflicts`` (nothing when the list is empty).

    :param folder: the output folder of the run (named in the message)
    :param conflicts: lines from :func:`settings_conflicts`
    """
    if conflicts:
        lines = "\n  ".join(conflicts)
        raise SettingsConflictError(
            f"{folder} holds results made with other settings than this run's:\n  {lines}\nNothing was changed. "
            "Rerun with the recorded settings, choose another output folder (--out), or delete the folders named "
            "above (and the stages made from them) to redo them with the new settings."
        )


def check_and_record(
    record: str | os.PathLike, wanted: Mapping[str, Any], *, output_exists: bool, folder: str | os.PathLike
) -> None:
    """Refuse when ``record`` holds other settings than ``wanted``; otherwise write ``wanted`` to it.

    :param record: the stage's ``stage.json``
    :param wanted: the settings of this run
    :param output_exists: whether the stage has output already
    :param folder: the run's output folder (named in the message)
    """
    record = Path(record)
    recorded = read_settings(record)
    refuse_conflicts(
        folder,
        settings_conflicts(
            record.parent if record.name == STAGE_FILE else record, recorded, wanted, output_exists=output_exists
        ),
    )
    if recorded is None:
        atomic_write_json(record, dict(wanted))


def exit_with_parent(parent_pid: int, poll_s: float = 1.0) -> None:
    """Make this process exit as soon as ``parent_pid`` (the process that started it) dies.

    A process pool's ``initializer``: on Linux the kernel sends SIGKILL when the parent dies
    (``prctl(PR_SET_PDEATHSIG)``); everywhere a daemon thread also polls ``os.getppid()`` every ``poll_s``
    seconds and exits when the parent has changed. So workers do not outlive a killed study, finish stale jobs
    and race a rerun on the same files.

    :param parent_pid: the parent's PID, as the parent saw it (``os.getpid()`` there)
    :param poll_s: seconds between two checks of the parent
    """
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            pr_set_pdeathsig = 1
            ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent_pid:  # the parent died before the above took effect
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(poll_s)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()
