"""What a run writes beside its checkpoints, and what a resume checks of it: ``training.csv`` (one row per update,
cut back to the checkpoint a run resumes from), ``run_info.json`` (seed, size, provenance, resumes and extensions),
the TensorBoard scalars and the progress bar, and the records every checkpoint vouches for (:func:`run_records`).
"""

from __future__ import annotations

import csv
import datetime
import io
import json
import math
import os
import sys
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.analysis.results import TRAINING_COLUMNS
from agents.config import LENGTH_KEY, Config, ConfigError, config_from_dict, config_to_dict, dump_config
from agents.evaluation.records import read_records, records_csv_text
from agents.policy.checkpoint import DamagedCheckpoint
from agents.runtime.io import atomic_write_text, content_record, now, provenance, write_json_atomic


def extend_run(run_dir: Path, config: Config, total_steps: int, update: int) -> tuple[Config, dict[str, Any]]:
    """Lengthen the run in ``run_dir`` (saved config ``config``, newest checkpoint at ``update``) to ``total_steps``,
    which must add at least one update. Writes the new ``config.yaml`` and records the extension in ``run_info.json``
    (``extended``: when, at which update and step, old and new length; its ``finished`` entry goes, since the run is
    not any more). Returns the new config and that record."""
    new = config_from_dict(config_to_dict(config), [f"{LENGTH_KEY}={total_steps}"])
    batch, old_updates, new_updates = config.batch_size, config.num_updates, new.num_updates
    if new_updates <= old_updates:
        raise ConfigError(
            f"run.total_steps={new.run.total_steps} does not lengthen the run: it is {old_updates} updates of {batch} "
            f"steps ({old_updates * batch} steps) long; give at least {(old_updates + 1) * batch} to add an update"
        )
    record = {
        "time": now(),
        "update": update,
        "step": update * batch,
        "total_steps": [config.run.total_steps, new.run.total_steps],
        "num_updates": [old_updates, new_updates],
        "command": sys.argv,
    }
    # config.yaml first: from then on a resume sees the longer run (its checkpoints hold the shorter one), and the
    # schedules follow from that difference; the run_info record below is the history for readers
    atomic_write_text(run_dir / "config.yaml", dump_config(new))
    info_path = run_dir / "run_info.json"
    info = json.loads(info_path.read_text()) if info_path.is_file() else run_info(config)
    info.pop("finished", None)
    info["num_updates"] = new_updates
    info.setdefault("extended", []).append(record)
    write_json_atomic(info_path, info, sort_keys=False)
    return new, record


class TrainingLog:
    """``training.csv``, one row appended and flushed per update, so a running (or killed) run's log is current.

    Opened at ``step`` (0 for a new run, the checkpoint's step on resume), it first rewrites the file atomically with
    the header and the rows up to ``step`` only: rows a killed run appended after its last checkpoint, and a last line
    torn by the kill, are dropped, so that after a resume the file holds what an uninterrupted run's holds (the
    TensorBoard events are truncated the same way, by ``purge_step``)."""

    def __init__(self, path: Path, step: int, columns: tuple[str, ...] = TRAINING_COLUMNS) -> None:
        self.path = path
        atomic_write_text(path, training_log_text(path, step, columns))
        self._handle = open(path, "a", newline="")  # noqa: SIM115 (held open across updates, closed by close())
        self._writer = csv.DictWriter(self._handle, fieldnames=list(columns), lineterminator="\n")

    def append(self, row: dict[str, Any]) -> None:
        self._writer.writerow(row)
        self._handle.flush()  # a reader (or a kill) sees every finished update

    def sync(self) -> None:
        """Force the rows to disk (at a checkpoint: the log then survives whatever the checkpoint survives)."""
        os.fsync(self._handle.fileno())

    def close(self) -> None:
        self._handle.close()


def records_past(run_dir: Path, step: int) -> dict[str, int]:
    """How many rows of ``training.csv`` (a last line cut short by a kill counts as one) and records of
    ``eval/episodes.csv`` the run holds past ``step``: what resuming from the checkpoint at ``step`` drops."""
    path = run_dir / "training.csv"
    text = path.read_text() if path.is_file() else ""
    torn = int(bool(text) and not text.endswith("\n"))
    rows = sum(int(row["step"]) > step for row in _complete_rows(path)) + torn
    records = run_dir / "eval" / "episodes.csv"
    found = read_records(records, skip_malformed=True) if records.is_file() else []
    return {"training.csv": rows, "eval/episodes.csv": sum(record["step"] > step for record in found)}


def training_log_text(path: Path, step: int, columns: tuple[str, ...] = TRAINING_COLUMNS) -> str:
    """``training.csv`` as it is up to ``step``: the header and the complete rows of steps up to ``step``."""
    kept = [row for row in _complete_rows(path) if int(row["step"]) <= step] if step > 0 else []
    text = io.StringIO()
    rewrite = csv.DictWriter(text, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
    rewrite.writeheader()
    rewrite.writerows(kept)
    return text.getvalue()


RECORDED_FILES = ("training.csv", "eval/episodes.csv")  # what a checkpoint records of its run's files


def evaluation_records(path: Path, step: int) -> list[dict[str, Any]]:
    """The in-training evaluation records up to ``step`` (none without the file); a row cut short is left out."""
    if not path.is_file():
        return []
    return [record for record in read_records(path, skip_malformed=True) if record["step"] <= step]


def _records_text(path: Path, step: int) -> str:
    if path.name == "training.csv":
        return training_log_text(path, step)
    return records_csv_text(evaluation_records(path, step))


def run_records(run_dir: Path, step: int) -> dict[str, dict[str, Any]]:
    """Size and SHA-256 of what the run's records (:data:`RECORDED_FILES`) hold up to ``step`` as they are read back
    (what a killed run wrote later does not count; a missing file holds nothing): stored in every checkpoint."""
    return {name: content_record(_records_text(run_dir / name, step).encode()) for name in RECORDED_FILES}


def check_run_records(run_dir: Path, path: Path, state: dict[str, Any]) -> None:
    """:class:`DamagedCheckpoint` unless the run's records still hold what the checkpoint ``state`` (at ``path``)
    recorded of them: a truncated or corrupted training.csv or eval/episodes.csv is never continued."""
    step = state["global_step"]
    for name, recorded in state.get("records", {}).items():
        file = run_dir / name
        try:
            found = content_record(_records_text(file, step).encode())
        except (OSError, ValueError, KeyError, TypeError, csv.Error):  # a row garbled beyond parsing
            found = None
        if found != recorded:
            what = "is missing" if not file.is_file() else "does not hold what it recorded of it"
            raise DamagedCheckpoint(
                f"{file} {what} (the rows up to step {step}: {recorded['bytes']} bytes, SHA-256 "
                f"{recorded['sha256'][:12]}...), so {path} cannot be continued: the file was truncated or corrupted"
            )


def _complete_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of a CSV file, without a last line that a kill cut short (no newline at its end)."""
    if not path.is_file():
        return []
    text = path.read_text()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return list(csv.DictReader(io.StringIO(text)))


def log_scalars(writer: Any, metrics: dict[str, float], step: int) -> None:
    for name, value in metrics.items():
        if "/" in name and math.isfinite(value):
            writer.add_scalar(name, value, step)


def show_progress(progress: Any, metrics: dict[str, float], recent_returns: deque, batch_size: int) -> None:
    if progress is None:
        return
    progress.update(batch_size)
    recent = f"{np.mean(recent_returns):.3f}" if recent_returns else "-"
    progress.set_postfix(SPS=f"{metrics['charts/SPS']:.0f}", recent_return=recent, refresh=False)


def progress_bar(config: Config, initial: int) -> Any:
    if not config.run.progress_bar:
        return None
    from tqdm import tqdm

    total = config.num_updates * config.batch_size
    return tqdm(total=total, initial=initial, unit="step", unit_scale=True, dynamic_ncols=True)


def summary_writer(run_dir: Path, step: int) -> Any:
    from torch.utils.tensorboard import SummaryWriter

    # purge_step drops the events that a killed run logged after its last checkpoint (steps > step), so curves stay
    # single-valued; the checkpoint's own step was logged before the checkpoint and stays.
    return SummaryWriter(log_dir=str(run_dir), purge_step=step + 1 if step > 0 else None)


def run_info(config: Config) -> dict[str, Any]:
    """Seed, run size and provenance (versions, git revision, machine) of a run (``run_info.json``)."""
    return {"seed": config.run.seed, "num_updates": config.num_updates, "batch_size": config.batch_size, **provenance()}


def default_run_dir(config_path: str | Path, seed: int, root: str | Path = "runs", cell: Sequence[str] = ()) -> Path:
    """``runs/<config name>/<timestamp>-seed<seed>``; the name is the path below ``configs/`` without suffix. One run
    of a grid config (``train.py --only``) goes under its ``cell`` (method and task) in between:
    ``runs/<config name>/<method>/<task>/<timestamp>-seed<seed>``."""
    path = Path(config_path).resolve()
    parts = path.with_suffix("").parts
    name = "/".join(parts[parts.index("configs") + 1 :]) if "configs" in parts[:-1] else path.stem
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path(root).joinpath(name, *cell, f"{stamp}-seed{seed}")
