"""``write_json_atomic``: the file is replaced whole, and a failed write leaves the old file and no debris."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from agents.runtime.io import write_json_atomic


def test_write_json_atomic_replaces_and_creates_folders(tmp_path: Path) -> None:
    target = tmp_path / "deep" / "report.json"
    write_json_atomic(target, {"b": 1, "a": [1, 2]})
    write_json_atomic(str(target), {"c": 3})
    assert json.loads(target.read_text()) == {"c": 3}
    assert target.read_text().endswith("\n")
    assert [p.name for p in target.parent.iterdir()] == ["report.json"]


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "report.json"
    write_json_atomic(target, {"old": True})
    with pytest.raises(TypeError):
        write_json_atomic(target, {"new": object()})  # not JSON-serialisable, fails halfway through
    assert json.loads(target.read_text()) == {"old": True}
    assert [p.name for p in tmp_path.iterdir()] == ["report.json"]


def test_written_files_get_the_usual_permissions(tmp_path: Path) -> None:
    target = tmp_path / "report.json"
    write_json_atomic(target, {"a": 1})
    mask = os.umask(0)
    os.umask(mask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~mask
