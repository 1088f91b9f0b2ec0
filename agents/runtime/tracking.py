"""Optional experiment tracking with Weights & Biases (``run.wandb``; ``pip install -e ".[wandb]"``).

:func:`start_wandb` starts the W&B run of a run directory when ``run.wandb.project`` is set. The trainer calls it
before it writes anything of the run, so a start that fails (no API key, no network, a wrong entity) raises
:class:`TrackingError`, one line that says why, and leaves no file behind: a new run directory is not created, a
resumed one stays resumable. :func:`scalar_writer` then hands the trainer one writer for its scalars: TensorBoard's,
and the W&B run's, which receives the same scalars at the same environment steps. The W&B run gets the resolved
config and the run's provenance (git revision, versions, machine) as its config, the run directory's name, and the
group of ``run.wandb.group``; its files go under ``<run>/wandb``. Its id is kept in ``<run>/wandb.json``, so a resumed
run continues the same W&B run (``resume="allow"``). W&B keeps the points it has: after a kill, the steps that the
killed run logged past its last checkpoint stay, and the resumed run's points for those steps are dropped by W&B
(TensorBoard's event files, in contrast, are cut back to the checkpoint).

Settings. ``run.wandb.project`` switches the logging on (``WANDB_PROJECT`` alone does not). A setting the config
leaves unset (``entity`` and ``group`` empty, ``mode`` null) is left to W&B, which reads its own environment variable
(:data:`ENVIRONMENT`: ``WANDB_MODE``, ``WANDB_ENTITY``, ``WANDB_RUN_GROUP``) or takes its default; ``WANDB_DIR``, when
set, takes the place of ``<run>`` for W&B's files. A value the config sets wins over the variable. ``wandb.json``
records, for every start, the mode, entity, group and directory that applied and where each came from.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from pathlib import Path
from typing import Any, Protocol

from agents.config import Config, config_to_dict
from agents.runtime.io import now, provenance, write_json_atomic

WANDB_FILE = "wandb.json"  # the run directory's W&B run id, and what every start resolved
# W&B's environment variable of each setting the config also has (the directory: no config field, <run> by default)
ENVIRONMENT = {"mode": "WANDB_MODE", "entity": "WANDB_ENTITY", "group": "WANDB_RUN_GROUP", "dir": "WANDB_DIR"}
W_AND_B_DEFAULT = "W&B's default"


class ScalarWriter(Protocol):
    def add_scalar(self, tag: str, value: float, step: int) -> None: ...

    def close(self) -> None: ...


class TrackingError(RuntimeError):
    """The W&B run could not start; the message says why in one line and what would let it start."""


class WandbNotInstalled(ImportError, TrackingError):
    """``run.wandb.project`` is set but wandb is not installed."""


class WandbWriter:
    """The scalars of one run directory into one W&B run (created on first use, or continued on resume).

    A failed start raises :class:`TrackingError` after removing what this call created (``wandb.json``, the
    ``wandb`` folder, the run directory itself when it did not exist)."""

    def __init__(self, config: Config, run_dir: Path) -> None:
        try:
            import wandb
        except ImportError as err:
            raise WandbNotInstalled(
                "run.wandb.project is set but wandb is not installed: pip install -e '.[wandb]' (or leave "
                "run.wandb.project empty)"
            ) from err
        settings = config.run.wandb
        files_dir = None if os.environ.get(ENVIRONMENT["dir"]) else run_dir  # None: W&B reads WANDB_DIR
        given = {"mode": settings.mode, "entity": settings.entity or None, "group": settings.group or None}
        id_path = run_dir / WANDB_FILE
        new_record = not id_path.is_file()
        record = (
            {"id": uuid.uuid4().hex[:16], "project": settings.project}
            if new_record
            else json.loads(id_path.read_text())
        )
        created = _missing_folders(run_dir / "wandb" if files_dir is not None else run_dir)
        try:
            if new_record:  # written before the start: a run killed during it keeps its W&B id
                write_json_atomic(id_path, record, sort_keys=False)
            if files_dir is not None:
                (run_dir / "wandb").mkdir(parents=True, exist_ok=True)
            self.run = wandb.init(
                project=settings.project,
                **given,
                name=run_dir.name,
                id=record["id"],
                resume="allow",
                dir=None if files_dir is None else str(files_dir),
                config={**config_to_dict(config), "provenance": provenance()},
            )
        except Exception as err:  # noqa: BLE001 (wandb raises its own errors, and OS and network ones)
            if new_record:
                id_path.unlink(missing_ok=True)
            if created:  # everything below the top-most folder this call created is this call's
                shutil.rmtree(created[-1], ignore_errors=True)
            raise TrackingError(_start_failure(err, resolved_settings(given, files_dir))) from err
        started = resolved_settings(given, files_dir, getattr(getattr(self.run, "settings", None), "mode", None))
        record.setdefault("starts", []).append({"time": now(), **started})
        write_json_atomic(id_path, record, sort_keys=False)

    def add_scalar(self, tag: str, value: float, step: int) -> None:
        self.run.log({tag: value}, step=step)  # the scalars of one step merge into one W&B row

    def close(self) -> None:
        self.run.finish()


def resolved_settings(given: dict[str, str | None], files_dir: Path | None, started_mode: Any = None) -> dict[str, Any]:
    """The mode, entity, group and directory that apply to a W&B start, each from the config (``given``, None where
    unset), else its environment variable (:data:`ENVIRONMENT`), else W&B's default; ``from`` says which for each.
    ``started_mode``: the mode the started run reports, when it reports one (W&B also reads settings files)."""
    values: dict[str, Any] = {}
    sources: dict[str, str] = {}
    for key, default in (("mode", "online"), ("entity", ""), ("group", "")):
        variable = ENVIRONMENT[key]
        if given[key] is not None:
            values[key], sources[key] = given[key], "config"
        elif os.environ.get(variable):
            values[key], sources[key] = os.environ[variable], variable
        else:
            values[key], sources[key] = default, W_AND_B_DEFAULT
    if isinstance(started_mode, str) and started_mode:
        values["mode"] = started_mode
    if files_dir is None:
        values["dir"], sources["dir"] = os.environ[ENVIRONMENT["dir"]], ENVIRONMENT["dir"]
    else:
        values["dir"], sources["dir"] = str(files_dir), "the run directory"
    return {**values, "from": sources}


def _start_failure(err: Exception, settings: dict[str, Any]) -> str:
    """One line: why W&B did not start, with which mode (and from where), and what lets it start."""
    lines = str(err).strip().splitlines()
    reason = f"{type(err).__name__}: {lines[0]}" if lines else type(err).__name__
    mode, source = settings["mode"], settings["from"]["mode"]
    hint = (
        "log in (wandb login, or WANDB_API_KEY) and check the network, run.wandb.entity and run.wandb.project, or "
        "log without the service: WANDB_MODE=offline (or run.wandb.mode=offline; disabled: no W&B)"
    )
    return f"W&B could not start ({reason}) in mode {mode} ({source}): {hint}"


def _missing_folders(path: Path) -> list[Path]:
    """``path`` and its ancestors that do not exist yet, deepest first (what creating ``path`` creates)."""
    missing = []
    while not path.exists() and path != path.parent:
        missing.append(path)
        path = path.parent
    return missing


class _Writers:
    def __init__(self, writers: list[Any]) -> None:
        self.writers = writers

    def add_scalar(self, tag: str, value: float, step: int) -> None:
        for writer in self.writers:
            writer.add_scalar(tag, value, step)

    def close(self) -> None:
        for writer in self.writers:
            writer.close()


def start_wandb(config: Config, run_dir: str | Path) -> WandbWriter | None:
    """The W&B run of ``run_dir`` when ``run.wandb.project`` is set (None otherwise); :class:`TrackingError` when it
    cannot start (see the module docstring)."""
    if not config.run.wandb.project:
        return None
    return WandbWriter(config, Path(run_dir))


def scalar_writer(tensorboard: Any, wandb_writer: WandbWriter | None) -> ScalarWriter:
    """``tensorboard`` alone, or together with the started W&B run."""
    return tensorboard if wandb_writer is None else _Writers([tensorboard, wandb_writer])
