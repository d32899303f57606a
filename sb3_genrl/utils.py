"""Atomic output files: every file sb3-genrl writes appears whole or not at all.

A file is written under a temporary name in its own folder (same file system), flushed to disk and renamed onto
its final name with :func:`os.replace`, which is atomic. An interrupted write (an exception, ``kill -9``, a full
disk) leaves the previous file, or no file, at the final path, never a truncated one; a stage that resumes by
checking whether its output exists therefore never mistakes a partial file for a finished one.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any


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
    was. A block that writes nothing to the temporary path raises ``FileNotFoundError``.

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
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


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
