"""The regression check trains the two methods of a panel, evaluates them and judges the separation of their IQMs."""

from __future__ import annotations

from pathlib import Path

import pytest

from scripts import check_memory_dependence

PANEL = Path(__file__).resolve().parents[2] / "configs" / "examples" / "proof_of_memory.yaml"
SHORT = ["--set", "run.total_steps=12288", "--set", "eval.interval=6", "--set", "eval.repetitions=2"]


@pytest.mark.slow
def test_passes_when_memory_wins_and_fails_when_asked_the_other_way(tmp_path: Path, capsys) -> None:
    args = ["--config", str(PANEL), "--seeds", "1", "2", "--root", str(tmp_path), "--jobs", "2", *SHORT]
    assert check_memory_dependence.main(args) == 0
    out = capsys.readouterr().out
    assert "delay6 at step 12288: gru IQM" in out and "over 2 and 2 runs: separated" in out
    # the same runs, reused: memory-less PPO does not beat GRU-PPO
    assert check_memory_dependence.main([*args, "--better", "ppo", "--worse", "gru"]) == 1
    assert "NOT separated" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        check_memory_dependence.main([*args, "--better", "lstm"])


def test_refuses_a_single_seed(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit):
        check_memory_dependence.main(["--config", str(PANEL), "--seeds", "3", "3", "--root", str(tmp_path)])
    assert "at least 2 distinct seeds" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # refused before training anything
