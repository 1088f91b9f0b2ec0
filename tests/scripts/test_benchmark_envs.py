"""Smoke test of scripts/benchmark_envs.py: a tiny run without the reference writes a well-formed report."""

from __future__ import annotations

import json
from pathlib import Path

from scripts import benchmark_envs
from scripts.reference import REFERENCE_IDS


def test_quick_benchmark_writes_report(tmp_path: Path, capsys) -> None:
    ids = list(REFERENCE_IDS[:2])
    out = tmp_path / "benchmarks" / "envs.json"
    report = benchmark_envs.main(
        ["--ids", *ids, "--episodes", "2", "--batched-steps", "256", "--no-reference", "--out", str(out)]
    )
    assert json.loads(out.read_text()) == json.loads(json.dumps(report))
    assert list(out.parent.iterdir()) == [out], "written atomically, no temporary file left behind"
    assert set(report["results"]) == set(ids)
    for row in report["results"].values():
        assert row["single"]["episodes"] == 2 and row["single"]["steps"] > 0 and row["single"]["steps_per_s"] > 0
        for slots in ("b16", "b64"):
            assert row[slots]["steps"] >= 256 and row[slots]["steps_per_s"] > 0
        assert row["reference_single_steps_per_s"] is None
    machine = report["machine"]
    assert report["git"]["revision"] and report["versions"]["numpy"] and machine["cpu_count"]
    printed = capsys.readouterr().out
    assert all(env_id in printed for env_id in ids)
