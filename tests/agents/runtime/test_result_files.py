"""Where a result table may be written (``agents.runtime.io.ResultFile``): committed files only where --out names them,
a partial run never over a full table, whoever named it, and a table refused at write time kept, not lost."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agents.runtime.io import ROOT, SCRATCH, OutputRefused, ResultFile, json_table


def _partial_of(record: dict) -> str:
    return "" if record["rows"] == 3 else f"{record['rows']} of 3 rows"


def _target(tmp_path: Path, path: Path, explicit: bool) -> ResultFile:
    return ResultFile(path, explicit, json_table(_partial_of), tmp_path / "results", tmp_path / "runs")


def _write(path: Path, record: object) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record))
    return path


def test_a_committed_file_is_replaced_only_where_out_names_it(tmp_path: Path) -> None:
    committed = _write(tmp_path / "results" / "table.json", {"rows": 3})
    with pytest.raises(OutputRefused, match="is a committed result: it is replaced only where --out names it"):
        _target(tmp_path, committed, explicit=False).check("")
    _target(tmp_path, committed, explicit=True).write_bytes(b'{"rows": 3}', "")  # named: a full run replaces it
    _target(tmp_path, tmp_path / "results" / "new.json", explicit=False).check("")  # nothing there yet
    _target(tmp_path, _write(tmp_path / "runs" / "t.json", {"rows": 3}), explicit=False).check("")  # scratch


def test_a_partial_run_never_replaces_a_full_table(tmp_path: Path) -> None:
    for full in (tmp_path / "results" / "table.json", tmp_path / "elsewhere" / "table.json"):
        _write(full, {"rows": 3})
        before = full.read_bytes()
        with pytest.raises(OutputRefused) as err:
            _target(tmp_path, full, explicit=True).check("1 of 3 rows")
        assert str(err.value) == (
            f"{full} holds a full table and this run is partial (1 of 3 rows): a partial run never replaces a full "
            "table; write it elsewhere with --out PATH"
        )
        assert full.read_bytes() == before
    partial = _write(tmp_path / "runs" / "partial.json", {"rows": 1})
    _target(tmp_path, partial, explicit=False).write_bytes(b'{"rows": 2}', "2 of 3 rows")  # partial over partial
    assert json.loads(partial.read_text()) == {"rows": 2}
    for other in ("not json", "[1, 2]", '{"columns": 3}'):  # files that hold no table of this kind
        path = tmp_path / "runs" / "other.json"
        path.write_text(other)
        _target(tmp_path, path, explicit=True).check("1 of 3 rows")


def test_a_table_refused_when_written_is_kept_in_the_scratch_folder(tmp_path: Path) -> None:
    target = _target(tmp_path, tmp_path / "out" / "table.json", explicit=True)
    target.check("1 of 3 rows")  # nothing there when the run starts ...
    _write(target.path, {"rows": 3})  # ... a full table when it ends
    with pytest.raises(OutputRefused, match="this run's output is kept in ") as err:
        target.write_bytes(b'{"rows": 1}', "1 of 3 rows")
    (kept,) = (tmp_path / "runs" / "refused").iterdir()
    assert kept.name.endswith("-table.json") and str(kept) in str(err.value)
    assert json.loads(kept.read_text()) == {"rows": 1} and json.loads(target.path.read_text()) == {"rows": 3}


def test_defaults_are_git_ignored_and_the_committed_folder_is_results() -> None:
    chosen = ResultFile.choose(None, SCRATCH / "benchmarks" / "x.json", json_table(_partial_of))
    assert not chosen.explicit and chosen.committed == ROOT / "results"
    assert ResultFile.choose("results/x.json", chosen.path, chosen.holds_full).explicit
    assert "runs/" in (ROOT / ".gitignore").read_text().splitlines() and SCRATCH == ROOT / "runs"
