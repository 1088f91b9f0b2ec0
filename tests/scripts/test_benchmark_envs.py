"""scripts/benchmark_envs.py: a tiny run without the reference writes a well-formed report, by default under runs/;
a partial run never replaces a full table; the help is whole."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from agents.runtime.io import ROOT, SCRATCH
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


def test_the_default_report_goes_to_runs_and_a_partial_run_never_replaces_a_full_table(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    assert benchmark_envs.DEFAULT_OUT == SCRATCH / "benchmarks" / "envs.json"  # git-ignored, not results/
    default = tmp_path / "runs" / "benchmarks" / "envs.json"
    monkeypatch.setattr(benchmark_envs, "DEFAULT_OUT", default)
    tiny = ["--ids", REFERENCE_IDS[0], "--episodes", "1", "--batched-steps", "128", "--repeats", "1", "--no-reference"]
    benchmark_envs.main(tiny)
    assert set(json.loads(default.read_text())["results"]) == {REFERENCE_IDS[0]}
    assert f"wrote {default}" in capsys.readouterr().out

    full = tmp_path / "envs.json"  # the committed table, copied: it is full
    shutil.copy(ROOT / "results" / "benchmarks" / "envs.json", full)
    before = full.read_bytes()
    for partial in (["--quick"], ["--ids", *REFERENCE_IDS[:2]], ["--no-reference"]):
        with pytest.raises(SystemExit) as exit_:
            benchmark_envs.main([*partial, "--out", str(full)])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert f"{full} holds a full table and this run is partial" in err and "--out PATH" in err
        assert "2 of 10 ids" in err if "--ids" in partial else partial[0] in err
    assert full.read_bytes() == before and sorted(tmp_path.iterdir()) == [full, tmp_path / "runs"]


def test_help_says_everything(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        benchmark_envs.main(["--help"])
    text = capsys.readouterr().out
    assert "ours and (when available) the\nreference memory-gym==1.0.2, side by side in one run." in text
    assert "--out results/benchmarks/envs.json   # the committed table" in text
    assert "a file under results/ only when named here" in " ".join(text.split())
