"""Tests of sb3_genrl.utils: atomic output files."""

from __future__ import annotations

import errno
import json
from pathlib import Path

import pytest

from sb3_genrl.utils import (
    atomic_path,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    read_checkpoint,
    write_checkpoint,
)


def test_atomic_writes_create_parents_and_replace_whole_files(tmp_path: Path) -> None:
    path = tmp_path / "a" / "b" / "out.json"
    atomic_write_json(path, {"x": [1, 2]})
    assert json.loads(path.read_text()) == {"x": [1, 2]} and path.read_text().endswith("\n")
    atomic_write_text(path, "second")
    assert path.read_text() == "second"
    atomic_write_bytes(path, b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in path.parent.iterdir()) == ["out.json"]


def test_interrupted_write_keeps_the_previous_file_and_leaves_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "model.pt"
    path.write_bytes(b"previous")
    with pytest.raises(KeyboardInterrupt), atomic_path(path) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".pt" and tmp.name.startswith(".")
        tmp.write_bytes(b"half a fi")
        raise KeyboardInterrupt
    assert path.read_bytes() == b"previous" and list(tmp_path.iterdir()) == [path]


def test_a_block_that_writes_nothing_or_a_directory_target_is_refused(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nothing was written"), atomic_path(tmp_path / "empty.txt"):
        pass
    with pytest.raises(IsADirectoryError, match="directory"), atomic_path(tmp_path):
        pass
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_names_the_file_being_written(tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / "results.json"
    path.write_text("previous")

    def disk_full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", disk_full)
    with pytest.raises(OSError, match="No space left on device") as error:
        atomic_write_bytes(path, b"new")
    assert error.value.errno == errno.ENOSPC and error.value.filename == str(path) and str(path) in str(error.value)
    # torch's zip writer says only where in its archive it failed
    with pytest.raises(OSError, match="torch could not write the file, is the disk full") as error, atomic_path(path):
        raise RuntimeError("[enforce fail at inline_container.cc:664] . unexpected pos 64 vs 0")
    assert error.value.filename == str(path)
    # an error that names its file already, and one that is no failed write, pass as they are
    with pytest.raises(PermissionError) as error, atomic_path(path):
        raise PermissionError(errno.EACCES, "Permission denied", "/elsewhere")
    assert error.value.filename == "/elsewhere"
    with pytest.raises(RuntimeError, match="other"), atomic_path(path):
        raise RuntimeError("other")
    assert path.read_text() == "previous" and list(tmp_path.iterdir()) == [path]


def test_a_truncated_checkpoint_file_is_refused_naming_it(tmp_path: Path) -> None:
    record = write_checkpoint(
        tmp_path,
        {
            "model": ("model.zip", lambda p: p.write_bytes(b"m" * 100)),
            "memories": ("memories.pt", lambda p: p.write_bytes(b"x" * 50)),
        },
        {"episodes": 4},
    )
    assert record["sizes"] == {"model": 100, "memories": 50} and read_checkpoint(tmp_path)["episodes"] == 4
    memories = tmp_path / record["files"]["memories"]
    memories.write_bytes(b"x" * 49)
    with pytest.raises(ValueError, match="is truncated or corrupt") as error:
        read_checkpoint(tmp_path)
    assert str(memories) in str(error.value) and f"delete {tmp_path}" in str(error.value)
