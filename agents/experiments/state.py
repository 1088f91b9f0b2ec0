"""Where the runs of a sweep stand, their directories and their locks.

States (:func:`run_status`): ``new`` (no config.yaml yet), ``partial`` (config.yaml, and a newest checkpoint before
the last update, or none yet), ``finished`` (the newest checkpoint is the last update), ``running`` (another process
holds the run's lock). A run directory whose saved config differs from the expanded one is an error naming the run
and the keys (:class:`~agents.experiments.planning.SweepError`); nothing is overwritten. ``run.torch_threads`` is the
one exception: left at 0 (automatic) by the config, the launcher fixes it when it creates the run (the cores' share
of a local job, the CPUs of a SLURM job), it is saved in config.yaml, and the run keeps it when it resumes; a
grid that sets it explicitly must match it, except for a finished run, which trains no more. The
settings no record depends on (progress bar, checkpoint interval and count, W&B:
:func:`agents.config.resume_may_change`, the rule of every resume) may differ too: a run that goes on takes the grid's
(:func:`prepare_run` writes them to its config.yaml).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import socket
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from agents.config import Config, ConfigError, config_to_dict, dump_config, resume_may_change, with_neutral_settings
from agents.experiments.planning import SweepError, SweepRun
from agents.policy.checkpoint import checkpoint_update, finished_update, latest_checkpoint, run_config
from agents.runtime.io import atomic_write_text, create_text_once

NEW, PARTIAL, FINISHED, RUNNING = "new", "partial", "finished", "running"
LOCK_FILE = ".lock"


@dataclass(frozen=True)
class RunStatus:
    """Where a run stands: its state and its newest checkpoint's update (0: none)."""

    run: SweepRun
    state: str
    update: int

    @property
    def num_updates(self) -> int:
        return self.run.config.num_updates


def run_status(run: SweepRun) -> RunStatus:
    """The state of one run; :class:`SweepError` when its directory holds a different config."""
    saved = _saved_config(run)
    latest = latest_checkpoint(run.run_dir) if run.run_dir.is_dir() else None
    update = checkpoint_update(latest) if latest is not None else 0
    if latest is None and saved is not None:  # a finished run whose checkpoints are gone (e.g. a committed copy)
        update = finished_update(run.run_dir) or 0
    if saved is not None:
        # A finished run trains no more: what changes only the rounding of training (the thread count) is no
        # difference for it, so a panel trained at different thread counts can be evaluated with an explicit one.
        differences = config_differences(saved, run.config, rounding=update >= run.config.num_updates)
        if differences:
            raise SweepError(
                f"{run.name}: {run.run_dir / 'config.yaml'} holds a different config than the grid makes now ("
                + "; ".join(differences)
                + "): restore the grid, or move that run directory away to train it anew"
            )
    if saved is None:
        if latest is not None:
            raise SweepError(f"{run.name}: {run.run_dir} holds checkpoints but no config.yaml; move it away")
        return RunStatus(run, NEW, 0)
    if _locked(run.run_dir):
        return RunStatus(run, RUNNING, update)
    return RunStatus(run, FINISHED if update >= run.config.num_updates else PARTIAL, update)


def statuses(runs: Sequence[SweepRun]) -> list[RunStatus]:
    """The state of every run; one :class:`SweepError` listing every run whose directory disagrees."""
    found, errors = [], []
    for run in runs:
        try:
            found.append(run_status(run))
        except SweepError as err:
            errors.append(str(err))
    if errors:
        raise SweepError(
            f"{len(errors)} run director{'y' if len(errors) == 1 else 'ies'} disagree with the grid:\n  "
            + "\n  ".join(errors)
        )
    return found


def config_differences(saved: Config, expanded: Config, rounding: bool = False) -> list[str]:
    """``key: saved X, now Y`` for every field that differs (``run.torch_threads`` only when the grid sets it), but
    the settings no record depends on, which a run that goes on takes from the grid (:func:`prepare_run`), and with
    ``rounding`` (a finished run) those that change only the rounding (:data:`agents.config.ROUNDING_ONLY`)."""
    old, new = _flatten(config_to_dict(saved)), _flatten(config_to_dict(expanded))
    if expanded.run.torch_threads == 0:
        old.pop("run.torch_threads", None)
        new.pop("run.torch_threads", None)
    missing = object()
    keys = sorted(set(old) | set(new))
    return [
        f"{key}: saved {_show(old.get(key, missing))}, now {_show(new.get(key, missing))}"
        for key in keys
        if old.get(key, missing) != new.get(key, missing)
        and not resume_may_change(key, lengthen=False, rounding=rounding)
    ]


def _flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(tree, dict) and tree and not prefix.endswith("options"):
        flat: dict[str, Any] = {}
        for key, value in tree.items():
            flat.update(_flatten(value, f"{prefix}.{key}" if prefix else str(key)))
        return flat
    return {prefix: tree}


def _show(value: Any) -> str:
    return "(none)" if not isinstance(value, int | float | str | bool | list | dict | type(None)) else repr(value)


def _saved_config(run: SweepRun) -> Config | None:
    if not (run.run_dir / "config.yaml").is_file():
        return None
    try:
        return run_config(run.run_dir)
    except (ConfigError, FileNotFoundError, yaml.YAMLError) as err:
        raise SweepError(f"{run.name}: cannot read {run.run_dir / 'config.yaml'}: {err}") from err


def _locked(run_dir: Path) -> bool:
    """Whether another process holds the run's lock (a probe: the lock is released at once)."""
    path = run_dir / LOCK_FILE
    if not path.exists():
        return False
    import fcntl

    with open(path, "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(handle, fcntl.LOCK_UN)
    return False


@contextlib.contextmanager
def run_lock(run_dir: Path) -> Iterator[bool]:
    """Hold ``<run>/.lock`` exclusively while training; yields False (holding nothing) when another process has it.
    The lock goes with the process, however it ends (a killed holder leaves no stale lock); while held, the file
    names its holder (host and process id) for :func:`lock_holder`."""
    import fcntl

    run_dir.mkdir(parents=True, exist_ok=True)
    with open(run_dir / LOCK_FILE, "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        handle.truncate(0)
        handle.write(f"{socket.gethostname()} pid {os.getpid()}\n")
        handle.flush()
        try:
            yield True
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def lock_holder(run_dir: Path) -> str:
    """Who holds (or last held) the run's lock, as its lock file says: ``host pid N``, or ``unknown``."""
    try:
        return (run_dir / LOCK_FILE).read_text().strip() or "unknown"
    except OSError:
        return "unknown"


def prepare_run(run: SweepRun, torch_threads: int = 0) -> Path:
    """Create the run directory and its config.yaml (unless it has one): the expanded config, with
    ``run.torch_threads`` fixed to ``torch_threads`` when the config leaves it at 0. Returns the directory."""
    run.run_dir.mkdir(parents=True, exist_ok=True)
    path = run.run_dir / "config.yaml"
    if not path.exists():
        config = run.config
        if config.run.torch_threads == 0 and torch_threads > 0:
            config = dataclasses.replace(config, run=dataclasses.replace(config.run, torch_threads=torch_threads))
        # created once: two launchers with different thread counts must not replace the config a run trains with
        create_text_once(path, dump_config(config))
    else:  # a run that goes on takes the grid's settings that no record depends on (W&B, progress bar, ...)
        saved = run_config(run.run_dir)
        updated = with_neutral_settings(saved, run.config)
        if updated is not saved:
            atomic_write_text(path, dump_config(updated))
    return run.run_dir
