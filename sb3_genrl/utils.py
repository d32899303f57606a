"""Atomic output files (every file sb3-genrl writes appears whole or not at all) and folder locks.

A file is written under a temporary name in its own folder (same file system), flushed to disk and renamed onto
its final name with :func:`os.replace`, which is atomic. An interrupted write (an exception, ``kill -9``, a full
disk) leaves the previous file, or no file, at the final path, never a truncated one; a stage that resumes by
checking whether its output exists therefore never mistakes a partial file for a finished one.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import secrets
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

LOCK_FILE = ".lock"


class FolderInUseError(ValueError):
    """Another process holds the lock of the folder (see :func:`folder_lock`)."""


def temporary_sibling(path: str | os.PathLike[str]) -> Path:
    """A fresh hidden name in ``path``'s folder that keeps ``path``'s suffix (writers that pick their format from
    the suffix, such as ``savefig`` or SB3's ``save``, then write the same format).

    :param path: the final path
    :return: ``folder/.<stem>-partial-<pid>-<random><suffix>``
    """
    path = Path(path)
    return path.with_name(f".{path.stem}-partial-{os.getpid()}-{secrets.token_hex(4)}{path.suffix}")


def _fsync(path: Path) -> None:
    with open(path, "rb") as file:
        os.fsync(file.fileno())


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path to write ``path``'s content to; on success it is renamed onto ``path``.

    For writers that take a file name (``torch.save``, ``figure.savefig``, SB3's ``model.save``)::

        with atomic_path("out/vae.pt") as tmp:
            torch.save(payload, tmp)

    The parent folder is created. If the block raises, the temporary file is removed and ``path`` is left as it
    was. A block that writes nothing to the temporary path raises ``FileNotFoundError``. A failed write that names no
    file (a full disk: ``OSError`` without a file name, or torch's ``RuntimeError`` from its zip writer) is raised as
    an ``OSError`` naming ``path``.

    :param path: the final path
    """
    final = Path(path)
    if final.is_dir():
        raise IsADirectoryError(f"cannot write the file {str(final)!r}: it is a directory")
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_sibling(final)
    try:
        yield tmp
        if not tmp.is_file():
            raise FileNotFoundError(f"nothing was written for {str(final)!r}")
        _fsync(tmp)
        os.replace(tmp, final)
    except BaseException as error:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        named = _naming_the_file(error, final)
        if named is None:
            raise
        raise named from error


def _naming_the_file(error: BaseException, final: Path) -> OSError | None:
    """The failed write ``error`` as an ``OSError`` naming ``final`` (``None``: it names a file already, or is no
    failed write)."""
    if isinstance(error, OSError) and error.filename is None and error.errno is not None:
        return OSError(error.errno, error.strerror or str(error), str(final))
    if isinstance(error, RuntimeError) and ("PytorchStreamWriter" in str(error) or "unexpected pos" in str(error)):
        first_line = str(error).strip().splitlines()[0]
        return OSError(errno.EIO, f"torch could not write the file, is the disk full? ({first_line})", str(final))
    return None


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`).

    :param path: the final path
    :param data: the file's content
    :return: ``path``
    """
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike[str], text: str, *, newline: str | None = None) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`atomic_path`).

    :param path: the final path
    :param text: the file's content
    :param newline: as for :func:`open` (``""`` for CSV written with the :mod:`csv` module)
    :return: ``path``
    """
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline=newline) as file:
        file.write(text)
    return Path(path)


def atomic_write_json(path: str | os.PathLike[str], value: Any, *, indent: int | None = 2, **kwargs: Any) -> Path:
    """Write ``value`` as JSON (with a final newline) to ``path`` atomically (see :func:`atomic_path`).

    :param path: the final path
    :param value: a JSON-serialisable value
    :param indent: JSON indentation
    :param kwargs: further :func:`json.dumps` arguments (e.g. ``default=``)
    :return: ``path``
    """
    return atomic_write_text(path, json.dumps(value, indent=indent, **kwargs) + "\n")


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike, lock_file: str | os.PathLike | None = None) -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` for the ``with`` block, or raise :class:`FolderInUseError` at once.

    The lock is an OS file lock (``flock``; ``msvcrt.locking`` on Windows) on ``folder/.lock``, which holds the
    holder's PID while it runs and is removed at the end. The OS drops the lock when the holder exits, however it
    exits (``kill -9`` included), so a lock file left by a killed process does not block the next run.

    :param folder: the folder to lock (created)
    :param lock_file: the lock file (default ``folder/.lock``), e.g. a sibling for a folder that must stay empty
    :return: the lock file's path
    """
    folder = Path(folder)
    path = Path(lock_file) if lock_file is not None else folder / LOCK_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        if not _try_lock(fd):
            holder = os.read(fd, 32).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise FolderInUseError(
                f"{folder} is in use by another process (PID {holder}, lock file {path}): wait "
                "for it to finish, or stop it, then rerun"
            )
        if _same_file(fd, path):
            break
        os.close(fd)  # the holder before removed this file as we opened it: lock the current one
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield path
    finally:
        if os.name != "nt":
            path.unlink(missing_ok=True)  # still locked: a process that opened it will see it is gone
        os.close(fd)  # releases the lock


def _same_file(fd: int, path: Path) -> bool:
    try:
        on_disk = os.stat(path)
    except FileNotFoundError:
        return False
    held = os.fstat(fd)
    return (held.st_dev, held.st_ino) == (on_disk.st_dev, on_disk.st_ino)


def _try_lock(fd: int) -> bool:
    try:
        import fcntl
    except ImportError:  # Windows
        import msvcrt

        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        except OSError:
            return False
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


CHECKPOINT_STATE = "state.json"


def write_checkpoint(
    folder: str | os.PathLike[str], files: Mapping[str, tuple[str, Callable[[Path], None]]], state: Mapping[str, Any]
) -> dict[str, Any]:
    """Write a checkpoint of several files as one unit into ``folder``.

    Each file is written (atomically) under a name of its own, ``<stem>-<random><suffix>``; then ``state.json``,
    holding ``state``, ``"files"`` (each entry's file name) and ``"sizes"`` (each file's size in bytes, checked by
    :func:`read_checkpoint`), replaces the previous one atomically; then the files of the previous checkpoint are
    removed. A run killed at any moment (or a full disk) leaves ``state.json``
    naming a whole checkpoint, the new one or the one before, never a mix of them.

    :param folder: the checkpoint folder (created)
    :param files: entry -> (file name, a writer that writes the file at the path it is given)
    :param state: the rest of ``state.json`` (JSON values)
    :return: what ``state.json`` holds
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    token = secrets.token_hex(4)
    names = {entry: f"{Path(name).stem}-{token}{Path(name).suffix}" for entry, (name, _) in files.items()}
    record = {**state, "files": names, "sizes": {}}
    try:
        for entry, (_, write) in files.items():
            with atomic_path(folder / names[entry]) as tmp:
                write(tmp)
            record["sizes"][entry] = (folder / names[entry]).stat().st_size
        atomic_write_json(folder / CHECKPOINT_STATE, record)
    except BaseException:  # the previous checkpoint stays; this one's files go
        for name in names.values():
            (folder / name).unlink(missing_ok=True)
        raise
    for stale in folder.iterdir():  # the previous checkpoint's files (and any left by a killed write)
        if stale.name != CHECKPOINT_STATE and stale.name not in names.values():
            stale.unlink(missing_ok=True)
    return record


def read_checkpoint(folder: str | os.PathLike[str]) -> dict[str, Any] | None:
    """What ``folder/state.json`` holds (see :func:`write_checkpoint`), with ``"paths"``: each entry's file; ``None``
    when there is no checkpoint. A file that is missing, or not of the size it was written with (truncated), is
    refused with a ``ValueError`` naming it.

    :param folder: the checkpoint folder
    """
    folder = Path(folder)
    path = folder / CHECKPOINT_STATE
    if not path.is_file():
        return None
    try:
        state = json.loads(path.read_text())
        paths = {entry: folder / name for entry, name in state["files"].items()}
        sizes = {entry: int(size) for entry, size in state.get("sizes", {}).items()}  # none: an earlier version's
    except (json.JSONDecodeError, KeyError, TypeError, AttributeError, ValueError) as error:
        raise ValueError(f"{path} is not a checkpoint state ({error}); delete {folder} to start afresh") from None
    missing = [str(p) for p in paths.values() if not p.is_file()]
    if missing:
        raise ValueError(f"{path} names files that do not exist: {missing}; delete {folder} to start afresh")
    for entry, size in sizes.items():
        if entry in paths and paths[entry].stat().st_size != size:
            raise ValueError(
                f"the checkpoint file {paths[entry]} is truncated or corrupt ({paths[entry].stat().st_size} bytes, "
                f"{size} when it was written); delete {folder} to start afresh"
            )
    return state | {"paths": paths}


def same_observation(first: Any, second: Any) -> bool:
    """Whether two observations (arrays, or dicts and tuples of them) are equal, element for element."""
    if isinstance(first, dict):
        return (
            isinstance(second, dict)
            and first.keys() == second.keys()
            and all(same_observation(first[k], second[k]) for k in first)
        )
    if isinstance(first, tuple | list):
        return isinstance(second, tuple | list) and len(first) == len(second) and all(map(same_observation, first, second))
    return np.array_equal(np.asarray(first), np.asarray(second))


@contextlib.contextmanager
def one_torch_thread() -> Iterator[None]:
    """Torch on one CPU thread for the block; the caller's thread count is restored after.

    GenRL and the baselines' runs build and train their networks under it. Torch's default (one thread per core) would
    make a result depend on the machine: the work of an operation is split by thread (SB3's orthogonal initialisation,
    sums), so the last bits, and from them the policy, differ. The networks are small, so more threads gain little,
    and their idle workers spin on the cores that the simulation needs next.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
