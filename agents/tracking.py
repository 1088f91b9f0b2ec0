"""Optional experiment tracking with Weights & Biases (``run.wandb``; ``pip install -e ".[wandb]"``).

:func:`scalar_writer` hands the trainer one writer for its scalars: TensorBoard's, and when ``run.wandb.project`` is
set also a W&B run that receives the same scalars at the same environment steps. The W&B run gets the resolved config
and the run's provenance (git revision, versions, machine) as its config, the run directory's name, and the group of
``run.wandb.group``; its files go under ``<run>/wandb``. Its id is kept in ``<run>/wandb.json``, so a resumed run
continues the same W&B run (``resume="allow"``). W&B keeps the points it has: after a kill, the steps that the killed
run logged past its last checkpoint stay, and the resumed run's points for those steps are dropped by W&B (TensorBoard's
event files, in contrast, are cut back to the checkpoint).
"""

from __future__ import annotations

import json
import uuid
from pathlib import Path
from typing import Any, Protocol

from agents.config import Config, config_to_dict
from agents.io import provenance, write_json_atomic

WANDB_FILE = "wandb.json"  # the run directory's W&B run id


class ScalarWriter(Protocol):
    def add_scalar(self, tag: str, value: float, step: int) -> None: ...

    def close(self) -> None: ...


class WandbWriter:
    """The scalars of one run directory into one W&B run (created on first use, or continued on resume)."""

    def __init__(self, config: Config, run_dir: Path) -> None:
        try:
            import wandb
        except ImportError as err:
            raise ImportError(
                "run.wandb.project is set but wandb is not installed: pip install -e '.[wandb]' (or leave "
                "run.wandb.project empty)"
            ) from err
        settings = config.run.wandb
        id_path = run_dir / WANDB_FILE
        run_id = json.loads(id_path.read_text())["id"] if id_path.is_file() else uuid.uuid4().hex[:16]
        if not id_path.is_file():
            write_json_atomic(id_path, {"id": run_id, "project": settings.project})
        (run_dir / "wandb").mkdir(parents=True, exist_ok=True)
        self.run = wandb.init(
            project=settings.project,
            entity=settings.entity or None,
            group=settings.group or None,
            mode=settings.mode,
            name=run_dir.name,
            id=run_id,
            resume="allow",
            dir=str(run_dir),
            config={**config_to_dict(config), "provenance": provenance()},
        )

    def add_scalar(self, tag: str, value: float, step: int) -> None:
        self.run.log({tag: value}, step=step)  # the scalars of one step merge into one W&B row

    def close(self) -> None:
        self.run.finish()


class _Writers:
    def __init__(self, writers: list[Any]) -> None:
        self.writers = writers

    def add_scalar(self, tag: str, value: float, step: int) -> None:
        for writer in self.writers:
            writer.add_scalar(tag, value, step)

    def close(self) -> None:
        for writer in self.writers:
            writer.close()


def scalar_writer(tensorboard: Any, config: Config, run_dir: str | Path) -> ScalarWriter:
    """``tensorboard`` alone, or together with a W&B run when ``run.wandb.project`` is set (see the module
    docstring)."""
    if not config.run.wandb.project:
        return tensorboard
    try:
        wandb_writer = WandbWriter(config, Path(run_dir))
    except BaseException:
        tensorboard.close()
        raise
    return _Writers([tensorboard, wandb_writer])
