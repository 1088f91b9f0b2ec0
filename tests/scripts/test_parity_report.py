"""scripts/parity_report.py: a report of some ids goes to runs/ by default and never replaces a report of all ids."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from agents.runtime.io import ROOT, SCRATCH
from scripts import parity_report


def test_a_report_of_some_ids_goes_to_runs_and_never_replaces_the_full_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    assert parity_report.DEFAULT_OUT == SCRATCH / "parity.json"  # git-ignored, not results/
    default = tmp_path / "runs" / "parity.json"
    monkeypatch.setattr(parity_report, "DEFAULT_OUT", default)
    report = parity_report.main(["--ids", "MortarMayhemB-Grid-v0"])
    assert json.loads(default.read_text()) == report and list(report) == ["MortarMayhemB-Grid-v0"]
    assert report["MortarMayhemB-Grid-v0"]["single"]["percent"] == 100.0
    assert f"wrote {default}" in capsys.readouterr().out

    full = tmp_path / "parity.json"  # the committed report, copied: every id
    shutil.copy(ROOT / "results" / "parity.json", full)
    before = full.read_bytes()
    with pytest.raises(SystemExit) as exit_:  # refused before anything is replayed
        parity_report.main(["--ids", "MortarMayhemB-Grid-v0", "--out", str(full)])
    assert exit_.value.code == 2
    assert f"{full} holds a full table and this run is partial (1 of 10 ids)" in capsys.readouterr().err
    assert full.read_bytes() == before
