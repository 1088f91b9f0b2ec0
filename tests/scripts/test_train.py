"""scripts/train.py: what the command line says and does around the trainer (notices, errors, resuming)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from scripts import train as train_script

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory": "gru", "memory_size": 8, "hidden_size": 8, "vector_encoder_size": 8},
    "ppo": {"epochs": 1, "minibatches": 2, "learning_rate": {"initial": 1.0e-3, "final": 1.0e-4}},
    "run": {
        "total_steps": 4 * 16 * 2,
        "workers": 4,
        "worker_steps": 16,
        "seed": 1,
        "progress_bar": False,
        "torch_threads": 1,
        "checkpoint_interval": 0,
    },
}


@pytest.fixture
def config_file(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(TINY))
    return path


def test_rounding_down_to_whole_updates_is_announced(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    run_dir = tmp_path / "run"
    args = ["--config", str(config_file), "--run-dir", str(run_dir), "--set", "run.total_steps=1.5e2"]
    assert train_script.main(args) == 0
    out = capsys.readouterr().out
    assert (
        "note: run.total_steps=150 is not a whole number of updates of 64 steps (run.workers x run.worker_steps = "
        "4 x 16): training 2 updates, 128 steps"
    ) in out
    assert train_script.main(["--config", str(config_file), "--run-dir", str(tmp_path / "exact")]) == 0
    assert "note:" not in capsys.readouterr().out


def test_a_yaml_syntax_error_exits_2_naming_file_line_and_column(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("run:\n  seed: 1\nppo: {gamma: 0.99\n")
    assert train_script.main(["--config", str(path), "--run-dir", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {path}: line 4, column 1: invalid YAML:") and "Traceback" not in err
    assert not (tmp_path / "run").exists()


def test_a_fractional_integer_override_exits_2_naming_the_key(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    args = ["--config", str(config_file), "--run-dir", str(tmp_path / "run"), "--set", "ppo.epochs=1.5e0"]
    assert train_script.main(args) == 2
    assert "ppo.epochs='1.5e0' is invalid: expected an int in [1, inf]; 1.5 is not a whole number" in (
        capsys.readouterr().err
    )
