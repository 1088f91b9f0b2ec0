"""scripts/check_run.py: a committed run re-trained from scratch gives its records byte for byte; a changed byte is
named; a selection of several runs, or of a run not committed whole, is refused."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from scripts import check_run, sweep

GRID = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 2}, "train_seeds": [0, 999]},
    "model": {"memory": "gru", "memory_size": 8, "hidden_size": 8},
    "ppo": {"epochs": 1, "minibatches": 2},
    "run": {"total_steps": 128, "workers": 4, "worker_steps": 16, "progress_bar": False, "checkpoint_interval": 1},
    "eval": {"interval": 1, "seeds": [1000, 1002], "repetitions": 2},
    "grid": {"panel": "tiny", "method": {"gru": {"model.memory": "gru"}}, "run.seed": [0, 1]},
}


@pytest.mark.slow
def test_a_committed_run_regenerates_and_a_changed_byte_is_named(tmp_path: Path, capsys) -> None:
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(GRID))
    root = tmp_path / "committed"
    assert sweep.main([str(config), "--root", str(root), "--jobs", "1", "--evaluate", "--only", "seed=0"]) == 0
    only = ["--root", str(root), "--only", "method=gru,seed=0", "--scratch", str(tmp_path / "again")]
    assert check_run.main([str(config), *only]) == 0
    assert "is the same as" in capsys.readouterr().out
    run = next((root / "tiny").glob("gru/*/seed0"))
    saved = yaml.safe_load((run / "config.yaml").read_text())  # as an older version wrote it: a key added since
    del saved["ppo"]["ground_truth_coef"]  # missing, and W&B's mode (no record depends on it) another
    saved["run"]["wandb"]["mode"] = "online"
    (run / "config.yaml").write_text(yaml.safe_dump(saved))
    assert check_run.main([str(config), *only[:4], "--scratch", str(tmp_path / "older")]) == 0
    saved["ppo"]["gamma"] = 0.5
    (run / "config.yaml").write_text(yaml.safe_dump(saved))
    assert check_run.main([str(config), *only[:4], "--scratch", str(tmp_path / "other")]) == 1
    assert "ppo.gamma: saved 0.5, now 0.99" in capsys.readouterr().out
    del saved["ppo"]["gamma"]
    (run / "config.yaml").write_text(yaml.safe_dump(saved))
    log = run / "training.csv"
    log.write_text(log.read_text().replace(",", ";", 1))
    assert check_run.main([str(config), *only[:4], "--scratch", str(tmp_path / "third")]) == 1
    out = capsys.readouterr().out
    assert "training.csv: line 1 differs" in out and "eval/episodes.csv" not in out
    assert check_run.main([str(config), "--root", str(root), "--only", "method=gru"]) == 2
    assert "selects 2 runs" in capsys.readouterr().err
    assert check_run.main([str(config), "--root", str(root), "--only", "seed=1"]) == 2
    assert "not a finished, committed run" in capsys.readouterr().err
