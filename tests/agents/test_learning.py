"""Learning tests: GRU-PPO solves ProofOfMemory-v0 within its config budget; memory-less PPO stays at chance.

Both runs are deterministic given the config's seed (CPU, same thread count). Success is the mean over the episodes
of the last updates (each update ends ~200 episodes).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from agents.config import load_config
from agents.trainer import Trainer

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "proof_of_memory"


def _success(history: list[dict[str, float]], last: int) -> float:
    episodes = np.array([m["charts/episodes"] for m in history[-last:]])
    success = np.array([m["env/success"] for m in history[-last:]])
    return float((episodes * success).sum() / episodes.sum())


@pytest.mark.slow
def test_gru_ppo_learns_proof_of_memory(tmp_path: Path) -> None:
    config = load_config(CONFIGS / "gru.yaml", ["run.progress_bar=false"])
    history = Trainer(config, tmp_path).train()
    assert len(history) == config.num_updates
    assert _success(history, last=4) >= 0.95
    assert _success(history[:2], last=2) < 0.7  # it did not know the task at the start


@pytest.mark.slow
def test_memoryless_ppo_stays_at_chance_on_proof_of_memory(tmp_path: Path) -> None:
    config = load_config(CONFIGS / "ppo.yaml", ["run.progress_bar=false"])
    assert config.model.memory == "none" and not config.model.previous_action  # no memory, not even via actions
    history = Trainer(config, tmp_path).train()
    assert 0.35 <= _success(history, last=8) <= 0.65
