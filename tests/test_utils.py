"""Tests of sb3_genrl.utils: atomic output files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sb3_genrl.utils import atomic_path, atomic_write_bytes, atomic_write_json, atomic_write_text


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
