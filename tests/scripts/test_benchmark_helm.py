"""The HELM benchmark times the branch and its parts and writes its JSON record."""

from __future__ import annotations

import json
from pathlib import Path

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
