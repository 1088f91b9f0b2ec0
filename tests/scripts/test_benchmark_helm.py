"""The HELM benchmark times the branch and its parts and writes its JSON record."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agents.runtime.io import SCRATCH
from scripts import benchmark_helm


def test_benchmark_writes_a_complete_record(tmp_path: Path) -> None:
    out = tmp_path / "helm.json"
    benchmark_helm.main(["--sizes", "tiny", "--batch", "2", "--steps", "2", "--repeats", "1", "--out", str(out)])
    record = json.loads(out.read_text())
    tiny = record["results"]["tiny"]
    assert (tiny["layers"], tiny["width"], tiny["vocab"]) == (2, 128, 4096)
    best = tiny["best_ms"]
    assert best["step"] > 0 and best["projection"] > 0 and best["retrieval"] > 0
    assert best["transformer"] == best["step"] - best["projection"] - best["retrieval"]
    assert record["setting"]["batch"] == 2 and record["git"]["revision"]


def test_a_partial_run_never_replaces_a_full_table(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert benchmark_helm.DEFAULT_OUT == SCRATCH / "benchmarks" / "helm.json"  # git-ignored, not results/
    full = tmp_path / "helm.json"
    full.write_text(json.dumps({"results": {size: {} for size in benchmark_helm.DEFAULT_SIZES}}))
    before = full.read_bytes()
    with pytest.raises(SystemExit) as exit_:  # refused before anything is measured
        benchmark_helm.main(["--sizes", "tiny", "small", "--out", str(full)])
    assert exit_.value.code == 2
    assert "holds a full table and this run is partial (1 of the 3 default sizes)" in capsys.readouterr().err
    assert full.read_bytes() == before
