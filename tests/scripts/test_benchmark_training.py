"""The training benchmark runs on any Dict-observation env id and writes its JSON record."""

from __future__ import annotations

import json
from pathlib import Path

from scripts import benchmark_training


def test_benchmark_writes_a_complete_record(tmp_path: Path, dict_env: str) -> None:
    out = tmp_path / "training.json"
    args = [
        "--env",
        dict_env,
        "--workers",
        "2",
        "--worker-steps",
        "16",
        "--epochs",
        "1",
        "--minibatches",
        "2",
        "--updates",
        "1",
        "--repeats",
        "1",
        "--precision",
        "fp32",
        "--sb3",
        "no",
        "--out",
        str(out),
    ]
    assert benchmark_training.main(args) == 0
    record = json.loads(out.read_text())
    summary = record["summary"]
    for how in ("median", "best"):
        end, bound = summary[f"{how}_end_to_end_steps_per_s"], summary[f"{how}_bound_steps_per_s"]
        assert end > 0 and bound > 0 and summary[f"{how}_end_to_end_over_bound"] == end / bound
        assert summary[f"{how}_sb3_recurrent_ppo_steps_per_s"] is None
    assert record["setting"]["batch"] == 32 and record["setting"]["env"] == dict_env
    assert set(record["versions"]) >= {"python", "torch", "numpy", "gymnasium"}
    assert record["git"]["revision"] and record["machine"]["cpu_count"]
    assert not list(tmp_path.glob(".*tmp*"))  # the atomic write left no temporary file
