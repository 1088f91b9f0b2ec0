"""Interrupting a trainer in-process, as a killed process would be (the resume tests' helper)."""

from __future__ import annotations

from agents.training.trainer import Trainer


def kill_after(trainer: Trainer, updates: int) -> None:
    """Make ``trainer.train()`` die like a killed process once ``updates`` updates are done."""
    run_update = trainer.train_update

    def maybe_die() -> dict[str, float]:
        if trainer.update == updates:
            raise KeyboardInterrupt
        return run_update()

    trainer.train_update = maybe_die  # type: ignore[method-assign]
