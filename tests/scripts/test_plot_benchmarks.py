"""scripts/plot_benchmarks.py: the chart says whether its benchmark was full, goes to runs/ by default, and the chart
of a partial benchmark never replaces the chart of a full one (the committed chart has no marker: it counts as full)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from PIL import Image

from agents.runtime.io import ROOT, SCRATCH
from scripts import plot_benchmarks

COMMITTED = ROOT / "results" / "benchmarks"


def _marker(path: Path) -> str:
    with Image.open(path) as image:
        return image.info[plot_benchmarks.MARKER]


def test_charts_are_marked_and_a_partial_one_never_replaces_a_full_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    assert plot_benchmarks.DEFAULT_OUT == SCRATCH / "benchmarks" / "envs.png"  # git-ignored, not results/
    assert plot_benchmarks.DEFAULT_JSON == SCRATCH / "benchmarks" / "envs.json"
    full_json = COMMITTED / "envs.json"
    report = json.loads(full_json.read_text())
    partial_json = tmp_path / "quick.json"
    row = next(iter(report["results"]))
    partial_json.write_text(json.dumps({**report, "results": {row: report["results"][row]}}))
    default = tmp_path / "runs" / "envs.png"
    monkeypatch.setattr(plot_benchmarks, "DEFAULT_OUT", default)

    assert plot_benchmarks.main(["--json", str(partial_json)]) == default
    assert _marker(default) == "partial: 1 of 10 ids"
    full_png = tmp_path / "full.png"
    plot_benchmarks.main(["--json", str(full_json), "--out", str(full_png)])
    assert _marker(full_png) == "full"
    committed_png = tmp_path / "committed.png"  # drawn before the marker existed: counts as full
    shutil.copy(COMMITTED / "envs.png", committed_png)
    capsys.readouterr()
    for target in (full_png, committed_png):
        before = target.read_bytes()
        with pytest.raises(SystemExit) as exit_:
            plot_benchmarks.main(["--json", str(partial_json), "--out", str(target)])
        assert exit_.value.code == 2
        assert f"{target} holds a full table and this run is partial (1 of 10 ids)" in capsys.readouterr().err
        assert target.read_bytes() == before
    plot_benchmarks.main(["--json", str(full_json), "--out", str(default)])  # a full chart replaces a partial one
    assert _marker(default) == "full"


def test_a_missing_benchmark_says_how_to_make_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    monkeypatch.setattr(plot_benchmarks, "DEFAULT_JSON", tmp_path / "none.json")
    with pytest.raises(SystemExit) as exit_:
        plot_benchmarks.main([])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "none.json: no such file; run scripts/benchmark_envs.py first" in err
    assert "--json results/benchmarks/envs.json" in err
