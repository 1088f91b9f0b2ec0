"""scripts/probe_table.py: one row per probe run with its novel-seed curve, beside a random policy's metric."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from scripts import probe_table


def _run(panel: Path, method: str, task: str, values: dict[int, list[float]], finished: bool) -> None:
    run = panel / method / task / "seed0"
    (run / "eval").mkdir(parents=True)
    config = {"env": {"id": "ProofOfMemory-v0", "options": {"delay": 2}}}
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    rows = ["run,step,metric"] + [f"seed0,{step},{v}" for step, vs in values.items() for v in vs]
    (run / "eval" / "episodes.csv").write_text("\n".join(rows) + "\n")
    (run / "training.csv").write_text("run,step\nseed0,2048\nseed0,4096\n")
    info = {"time": "2026-11-29T00:00:00+00:00"}
    if finished:
        info["finished"] = {"time": "2026-11-29T00:30:00+00:00", "update": 2, "step": 4096}
    (run / "run_info.json").write_text(json.dumps(info))


def test_the_table_holds_every_probe_with_its_curve_and_the_random_floor(tmp_path: Path, capsys) -> None:
    _run(tmp_path, "lru", "cue", {2048: [1.0, 0.0], 4096: [1.0, 1.0]}, finished=True)
    _run(tmp_path, "ppo", "cue", {2048: [0.0, 1.0]}, finished=False)
    assert probe_table.main([str(tmp_path), "--random-episodes", "40", "--out", str(tmp_path / "t.md")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("| task | env id and options | method |") and len(lines) == 4
    lru, ppo = lines[2].split(" | "), lines[3].split(" | ")
    assert lru[2:5] == ["lru", "4k", "success 2: 0.500, 4: 1.000"] and lru[-1].strip(" |") == "30"
    assert ppo[3] == "4k (stopped)" and 0.3 < float(lru[5]) < 0.7  # a random choice of two sides: about 0.5
    assert (tmp_path / "t.md").read_text().splitlines() == lines
    assert probe_table.main([str(tmp_path / "none")]) == 2
