"""Sweeps: a grid config (one figure panel) expanded into named runs, trained on this machine or on a SLURM
cluster (the launcher in :mod:`agents.slurm`), resumed after a crash or a pre-emption, and evaluated into one results
directory.

Layout under the root (``scripts/sweep.py --root``, default ``runs/``)::

    <root>/<panel>/<method>/<task>/seed<k>/   one run directory per grid point, as scripts/train.py writes it:
        config.yaml, run_info.json, checkpoints/, training.csv, eval/episodes.csv, TensorBoard events,
        stdout.log (the local launcher's log of every attempt), evaluation/ (the final evaluation)
    <root>/<panel>/results/                   the panel's results: episodes.csv, training.csv, summary.json, plots
    <root>/<panel>/slurm/                     submitit's job files and logs (the SLURM launcher, agents/slurm.py)

Names. The panel is ``grid.panel`` or the config file's stem; method and task are the names of the bundles of the
``method`` / ``task`` axes (without such an axis: ``Config.method`` / ``Config.task``); k is ``run.seed``. A plain
axis other than ``run.seed`` adds a ``<key>=<value>`` component before ``seed<k>``. Two points with the same name
are an error (name them with a bundle axis).

States (:func:`run_status`): ``new`` (no config.yaml yet), ``partial`` (config.yaml, and a newest checkpoint before
the last update, or none yet), ``finished`` (the newest checkpoint is the last update), ``running`` (another process
holds the run's lock). A run directory whose saved config differs from the expanded one is an error naming the run
and the keys (:class:`SweepError`); nothing is overwritten. ``run.torch_threads`` is the one exception: left at 0
(automatic) by the config, the launcher fixes it when it creates the run (the cores' share of a local job, the CPUs
of a SLURM job), it is saved in config.yaml, and the run keeps it when it resumes. The settings no record depends on
(progress bar, checkpoint interval and count, W&B: :func:`agents.config.resume_may_change`, the rule of every resume)
may differ too: a run that goes on takes the grid's (:func:`prepare_run` writes them to its config.yaml).

Training a run (:func:`train_run`, the same for both launchers) holds an exclusive lock on ``<run>/.lock`` (a second
process finds the run busy and leaves it), starts from scratch when there is no checkpoint (clearing what a killed
first attempt left), and otherwise continues exactly from the newest checkpoint (``Trainer.resume``, the semantics of
``scripts/train.py --resume``). Re-running a sweep therefore finishes it without redoing work: finished runs are not
touched, interrupted ones lose at most ``run.checkpoint_interval`` updates. Disk use stays bounded by
``run.keep_checkpoints`` (the paper configs keep 1); learning curves come from the in-training evaluation records.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from agents.config import (
    GRID_SETTINGS,
    NAMED_AXES,
    Config,
    ConfigError,
    GridPoint,
    SlurmConfig,
    check_name,
    config_from_dict,
    config_to_dict,
    dump_config,
    expand_grid,
    grid_panel,
    grid_slurm,
    read_config_file,
    resume_may_change,
    with_neutral_settings,
)
from agents.policy.checkpoint import (
    DamagedCheckpoint,
    checkpoint_damage,
    checkpoint_update,
    finished_update,
    ground_truth_size,
    latest_checkpoint,
    run_config,
)
from agents.runtime.faults import FaultSpecError, active_faults
from agents.runtime.io import atomic_write_text, create_text_once, now, provenance, write_json_atomic
from agents.runtime.preemption import EXIT_PREEMPTED, StopRequests, signal_name

NEW, PARTIAL, FINISHED, RUNNING = "new", "partial", "finished", "running"
PREEMPTED = "preempted"  # an outcome: the run stopped at a checkpoint on a signal (resumable, not failed)
EXIT_BUSY = 75  # the worker's exit status when another process trains the run (EX_TEMPFAIL)
LOCK_FILE = ".lock"
LOG_FILE = "stdout.log"
FINAL_EVALUATION = "evaluation"  # <run>/evaluation: the final evaluation, as scripts/evaluate.py writes it
REPO_ROOT = Path(__file__).resolve().parent.parent
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
Echo = Callable[[str], None]


class SweepError(RuntimeError):
    """A sweep cannot go on as asked: a run directory disagrees with the grid, submitit is missing, ..."""


# ----------------------------------------------------------------------------------------------- expansion
@dataclass(frozen=True)
class SweepRun:
    """One run of a panel: its name (``<panel>/<method>/<task>/seed<k>``), directory and grid point."""

    name: str
    run_dir: Path
    point: GridPoint

    @property
    def config(self) -> Config:
        return self.point.config

    @property
    def steps(self) -> int:
        """Agent steps (decisions) of the whole run: whole updates only, as the trainer runs them."""
        return self.config.num_updates * self.config.batch_size

    @property
    def frames(self) -> int:
        """Environment frames of the whole run (steps x ``env.frame_skip``)."""
        return self.steps * self.config.env.frame_skip

    def grid_overrides(self) -> list[tuple[str, Any]]:
        """What the grid sets for this run, in order, without the ``run.method`` / ``run.task`` that the bundles'
        names set (they are in the run's name)."""
        implicit = [(f"run.{axis}", label) for axis, label in self.point.choices if axis in NAMED_AXES]
        return [(key, value) for key, value, _ in self.point.overrides if (key, value) not in implicit]


@dataclass(frozen=True)
class Panel:
    """The runs of one grid config under ``root/name``, with the cluster settings of its ``grid.slurm``; after
    :func:`select_runs`, only the selected runs."""

    name: str
    root: Path
    runs: tuple[SweepRun, ...]
    slurm: SlurmConfig
    source: Path | None = None
    overrides: tuple[str, ...] = ()
    grid: dict[str, Any] = dataclasses.field(default_factory=dict)
    selection: tuple[str, ...] = ()  # the --only items that cut ``runs`` down (:func:`select_runs`)

    @property
    def directory(self) -> Path:
        return self.root / self.name

    @property
    def results_dir(self) -> Path:
        return self.directory / "results"

    @property
    def slurm_dir(self) -> Path:
        return self.directory / "slurm"


def load_panel(path: str | Path, overrides: Sequence[str] = (), root: str | Path = "runs") -> Panel:
    """The panel of a grid config file: the base validated, every point expanded and named."""
    path = Path(path)
    raw = read_config_file(path)
    try:
        return panel_from_dict(raw, overrides, root=root, name=None, source=path)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from err


def panel_from_dict(
    raw: dict[str, Any],
    overrides: Sequence[str] = (),
    *,
    root: str | Path = "runs",
    name: str | None = None,
    source: Path | None = None,
) -> Panel:
    """The panel of a config given as nested dicts. Its name: ``name``, else ``grid.panel``, else the stem of
    ``source``."""
    base = config_from_dict(raw, overrides)  # validates the base and every point
    panel = name or grid_panel(base.grid) or (source.stem if source is not None else None)
    if panel is None:
        raise ConfigError("the panel has no name: give grid.panel (or load it from a file)")
    check_name("panel", panel)
    root = Path(root)
    runs, seen = [], {}
    for point in map(separate_cells, expand_grid(raw, overrides)):
        run_name = _run_name(panel, point)
        if run_name in seen:
            raise ConfigError(
                f"grid points ({_choices(seen[run_name])}) and ({_choices(point)}) both make the run {run_name}: "
                "name what differs with a method or task bundle"
            )
        seen[run_name] = point
        runs.append(SweepRun(run_name, root.joinpath(*run_name.split("/")), point))
    return Panel(panel, root, tuple(runs), grid_slurm(base.grid), source, tuple(overrides), dict(base.grid))


def _run_name(panel: str, point: GridPoint) -> str:
    config = point.config
    check_name("the method's name", config.method)
    check_name("the task's name", config.task)
    return "/".join([panel, config.method, config.task, f"seed{config.run.seed}"])


def separate_cells(point: GridPoint) -> GridPoint:
    """The point with its plain axes other than ``run.seed`` written into its cell's names, so that the runs of one
    (method, task) cell differ by their seed only, as the panel's results demand (different experiments are never
    pooled): ``env.*`` axes extend the task (``pom+env.options.delay=8``), the others the method
    (``gru+ppo.gamma=0.9``). A point without such axes is returned as it is."""
    config = point.config
    extra = [(axis, label) for axis, label in point.choices if "." in axis and axis != "run.seed"]
    if not extra:
        return point

    def extended(name: str, axes: list[tuple[str, str]]) -> str:
        return name + "".join(f"+{axis}={_path_safe(label)}" for axis, label in axes)

    method = extended(point.choice("method") or config.method, [a for a in extra if not a[0].startswith("env.")])
    task = extended(point.choice("task") or config.task, [a for a in extra if a[0].startswith("env.")])
    run = dataclasses.replace(config.run, method=method, task=task)
    return dataclasses.replace(point, config=dataclasses.replace(config, run=run))


def _path_safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.+=-]+", "_", text).strip("_") or "_"


def _choices(point: GridPoint) -> str:
    return ", ".join(f"{axis}={label}" for axis, label in point.choices)


# ------------------------------------------------------------------------------------------------ selection
SELECTION_ALIASES = {"seed": "run.seed", "run.method": "method", "run.task": "task"}  # --only's short keys
_PAIR_START = re.compile(r",\s*(?=[A-Za-z_][\w.]*\s*=)")  # a comma that starts the next key=value pair


def run_coordinates(run: SweepRun) -> dict[str, str]:
    """What ``--only`` selects a run by: the method, task and ``run.seed`` of its name (every run has them) and its
    label on every axis of the grid (a bundle's name, a plain axis' value as one line of YAML)."""
    _, method, task, *_ = run.name.split("/")
    return {"method": method, "task": task, "run.seed": str(run.config.run.seed), **dict(run.point.choices)}


def parse_selection(text: str) -> dict[str, str]:
    """One ``--only`` value: ``key=value`` pairs joined by commas, e.g. ``method=gru,task=mm_grid_1,seed=0``. A comma
    starts a new pair only where a key and ``=`` follow, so a value such as ``[0, 1]`` stays whole."""
    selection: dict[str, str] = {}
    for pair in _PAIR_START.split(text.strip()):
        key, equals, value = (part.strip() for part in pair.partition("="))
        if not (key and equals and value):
            raise SweepError(f"--only {text}: expected key=value pairs joined by commas, e.g. method=gru,seed=0")
        key = SELECTION_ALIASES.get(key, key)
        if key in selection:  # a run has one value per key: the pair could never match
            raise SweepError(
                f"--only {text} names {key} twice; one --only selects the runs that match all its pairs, "
                "repeat --only to add the runs of another value"
            )
        selection[key] = value
    return selection


def select_runs(panels: Sequence[Panel], only: Sequence[str]) -> list[Panel]:
    """The panels cut down to the runs ``only`` selects (``scripts/sweep.py --only``): a run is kept when it matches
    every pair of at least one item (within an item AND, across items OR). Keys are the axes of the grids plus
    ``method``, ``task`` and ``run.seed`` (``seed``); a key or a value that no run has is an error naming the valid
    ones, and so is a selection that keeps no run. Panels left without a run are dropped. Without ``only``: the
    panels as they are."""
    if not only:
        return list(panels)
    selections = [parse_selection(text) for text in only]
    coordinates = {run.name: run_coordinates(run) for panel in panels for run in panel.runs}
    valid: dict[str, list[str]] = {}
    for found in coordinates.values():
        for key, value in found.items():
            if value not in valid.setdefault(key, []):
                valid[key].append(value)
    where = ", ".join(panel.name for panel in panels)
    for text, selection in zip(only, selections, strict=True):
        for key, value in selection.items():
            if key not in valid:
                keys = ", ".join(f"{k} (seed)" if k == "run.seed" else k for k in valid)
                raise SweepError(f"--only {text}: {key!r} is not an axis of {where}; valid keys: {keys}")
            if _label(value, valid[key]) is None:
                raise SweepError(
                    f"--only {text}: no run of {where} has {key}={value}; valid values: {', '.join(valid[key])}"
                )
    wanted = [{key: _label(value, valid[key]) for key, value in selection.items()} for selection in selections]

    def selected(run: SweepRun) -> bool:
        found = coordinates[run.name]
        return any(all(found.get(key) == value for key, value in selection.items()) for selection in wanted)

    kept = [
        dataclasses.replace(panel, runs=tuple(filter(selected, panel.runs)), selection=tuple(only)) for panel in panels
    ]
    kept = [panel for panel in kept if panel.runs]
    if not kept:
        raise SweepError(f"--only {' '.join(only)}: no run of {where} matches all the pairs of one --only")
    return kept


def _label(value: str, labels: Sequence[str]) -> str | None:
    """The label ``value`` names: itself, or the same value written as the grid writes it (``0.90`` -> ``0.9``)."""
    if value in labels:
        return value
    try:
        parsed = _short(yaml.safe_load(value), 10_000)
    except yaml.YAMLError:
        return None
    return parsed if parsed in labels else None


# ------------------------------------------------------------------------------------------------ states
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
    if saved is not None:
        differences = config_differences(saved, run.config)
        if differences:
            raise SweepError(
                f"{run.name}: {run.run_dir / 'config.yaml'} holds a different config than the grid makes now ("
                + "; ".join(differences)
                + "): restore the grid, or move that run directory away to train it anew"
            )
    latest = latest_checkpoint(run.run_dir) if run.run_dir.is_dir() else None
    update = checkpoint_update(latest) if latest is not None else 0
    if latest is None and saved is not None:  # a finished run whose checkpoints are gone (e.g. a committed copy)
        update = finished_update(run.run_dir) or 0
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


def config_differences(saved: Config, expanded: Config) -> list[str]:
    """``key: saved X, now Y`` for every field that differs (``run.torch_threads`` only when the grid sets it), but
    the settings no record depends on, which a run that goes on takes from the grid (:func:`prepare_run`)."""
    old, new = _flatten(config_to_dict(saved)), _flatten(config_to_dict(expanded))
    if expanded.run.torch_threads == 0:
        old.pop("run.torch_threads", None)
        new.pop("run.torch_threads", None)
    missing = object()
    keys = sorted(set(old) | set(new))
    return [
        f"{key}: saved {_show(old.get(key, missing))}, now {_show(new.get(key, missing))}"
        for key in keys
        if old.get(key, missing) != new.get(key, missing) and not resume_may_change(key, lengthen=False, rounding=False)
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


# ---------------------------------------------------------------------------------------- creating, training
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


def train_run(run_dir: str | Path, echo: Echo = print) -> str:
    """Train a prepared run directory to its end: from scratch without a checkpoint, else from the newest one.
    Returns ``finished`` (nothing was left to do), ``trained`` or ``busy`` (another process holds the run)."""
    from agents.training.trainer import Trainer

    run_dir = Path(run_dir)
    with run_lock(run_dir) as held:
        if not held:
            echo(f"{run_dir}: another process ({lock_holder(run_dir)}) is training this run; leaving it")
            return "busy"
        config = run_config(run_dir)
        latest = latest_checkpoint(run_dir)
        done = checkpoint_update(latest) if latest is not None else 0
        damage = checkpoint_damage(latest) if latest is not None and done >= config.num_updates else None
        if done >= config.num_updates and damage is None:
            echo(f"{run_dir}: finished already ({done} of {config.num_updates} updates)")
            return FINISHED
        if damage is not None:
            echo(f"warning: {damage}; the run resumes from an intact checkpoint")
        if latest is None:
            _clear_first_attempt(run_dir)
            echo(f"{now()} {run_dir}: training {config.num_updates} updates from scratch")
            trainer = Trainer(config, run_dir)
        else:
            echo(f"{now()} {run_dir}: resuming from update {done} of {config.num_updates} ({latest.name})")
            trainer = Trainer.resume(run_dir)
            for note in trainer.resume_notes:  # damaged checkpoints passed over
                echo(f"warning: {note}")
        history = trainer.train()
        last = history[-1] if history else {}
        scores = ", ".join(f"{k}={v:.4g}" for k, v in last.items() if k.startswith(("charts/episodic", "eval/")))
        echo(f"{now()} {run_dir}: finished, update {trainer.update} of {config.num_updates}; {scores}")
    return "trained"


def _clear_first_attempt(run_dir: Path) -> None:
    """What an attempt killed before its first checkpoint left (its logs would duplicate the new attempt's)."""
    for path in run_dir.glob("events.out.tfevents.*"):
        path.unlink()
    for name in ("training.csv", "run_info.json"):
        (run_dir / name).unlink(missing_ok=True)
    for name in ("eval", "checkpoints"):
        shutil.rmtree(run_dir / name, ignore_errors=True)


def worker_command(run_dir: Path) -> list[str]:
    """The command that trains one prepared run in its own process (``python -m agents.sweep RUN_DIR``)."""
    return [sys.executable, "-m", "agents.sweep", str(run_dir)]


def worker_environment(threads: int = 0) -> dict[str, str]:
    """This process's environment, with the repository importable and (when ``threads``) the native thread pools of
    numpy's BLAS and OpenMP limited to the run's share, unless the user set them."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO_ROOT), *filter(None, [env.get("PYTHONPATH")])])
    if threads:
        for name in THREAD_VARIABLES:
            env.setdefault(name, str(threads))
    return env


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity, which SLURM and containers restrict)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# --------------------------------------------------------------------------------------------- local launcher
@dataclass(frozen=True)
class Outcome:
    """How one launched run ended: ``ok``, ``failed`` (with the exit status or the error) or ``busy``."""

    run: SweepRun
    result: str
    detail: str = ""
    seconds: float = 0.0


def launch_local(
    runs: Sequence[SweepRun],
    jobs: int = 1,
    *,
    cores: int | None = None,
    echo: Echo = print,
    poll_s: float = 0.2,
) -> list[Outcome]:
    """Train every new or partial run, ``jobs`` processes at a time, each with ``cores // jobs`` torch threads (fixed
    when the run is created). Each run's output goes to ``<run>/stdout.log`` (appended, attempt after attempt). A
    failed run does not stop the others; the outcomes say which failed. Interrupted (Ctrl-C), the runs in progress
    are stopped and resume on the next call. Pre-empted (SIGTERM or SLURM's warning signal,
    :mod:`agents.runtime.preemption`), it passes the signal on to the running runs, which checkpoint and exit (outcome
    ``preempted``), and starts no other."""
    try:
        active_faults()  # the workers inherit MEMGYM_FAULT: a malformed one is refused once, here
    except FaultSpecError as err:
        raise SweepError(str(err)) from None
    pending = [s for s in statuses(runs) if s.state in (NEW, PARTIAL)]
    if not pending:
        return []
    jobs = max(1, min(jobs, len(pending)))
    threads = max(1, (cores or available_cores()) // jobs)
    env = worker_environment(threads)
    queue = list(pending)
    running: dict[subprocess.Popen, tuple[RunStatus, Any, float]] = {}
    outcomes: list[Outcome] = []
    with StopRequests() as stops:
        try:
            _run_queue(queue, running, outcomes, jobs, threads, env, stops, echo, poll_s)
        finally:
            _stop(running)
    return outcomes


def _run_queue(
    queue: list[RunStatus],
    running: dict[subprocess.Popen, tuple[RunStatus, Any, float]],
    outcomes: list[Outcome],
    jobs: int,
    threads: int,
    env: dict[str, str],
    stops: StopRequests,
    echo: Echo,
    poll_s: float,
) -> None:
    """:func:`launch_local`'s loop: start runs while there is room, collect the ended ones. After a pre-emption
    signal the running runs get it too (they checkpoint and exit) and no new one starts."""
    total, started, forwarded = len(queue), 0, False
    while queue or running:
        if stops.received is not None and not forwarded:
            forwarded = True
            echo(f"{signal_name(stops.received)}: stopping {len(running)} run(s) at their next checkpoint")
            for process in running:
                process.send_signal(stops.received)
            if queue:
                echo(f"{len(queue)} run(s) not started: re-run the same command to continue the sweep")
            queue.clear()
        while queue and len(running) < jobs:
            status = queue.pop(0)
            started += 1
            prepare_run(status.run, threads)
            log = open(status.run.run_dir / LOG_FILE, "ab")  # noqa: SIM115 (closed when the process ends)
            log.write(f"==== {now()} sweep: {status.state} run, update {status.update}\n".encode())
            log.flush()
            process = subprocess.Popen(
                worker_command(status.run.run_dir), stdout=log, stderr=subprocess.STDOUT, env=env
            )
            running[process] = (status, log, time.monotonic())
            what = "start" if status.update == 0 else f"resume at update {status.update}"
            echo(f"[{started}/{total}] {what}: {status.run.name}  (log: {status.run.run_dir / LOG_FILE})")
        time.sleep(poll_s)
        for process in [p for p in running if p.poll() is not None]:
            status, log, since = running.pop(process)
            log.close()
            outcome = _outcome(status.run, process.returncode, time.monotonic() - since)
            if forwarded and process.returncode == -stops.received_first:  # stopped before its trainer began
                outcome = dataclasses.replace(outcome, result=PREEMPTED, detail="stopped before its first update")
            outcomes.append(outcome)
            echo(f"{outcome.result}: {status.run.name} ({_duration(outcome.seconds)}){_suffix(outcome.detail)}")


def _outcome(run: SweepRun, returncode: int, seconds: float) -> Outcome:
    if returncode == 0:
        return Outcome(run, "ok", seconds=seconds)
    if returncode == EXIT_BUSY:
        return Outcome(run, "busy", "another process is training it", seconds)
    if returncode == EXIT_PREEMPTED:
        return Outcome(run, PREEMPTED, "stopped by a signal after a checkpoint; re-run to resume it", seconds)
    return Outcome(run, "failed", f"exit status {returncode}; {_last_error(run.run_dir / LOG_FILE)}", seconds)


def _stop(running: dict[subprocess.Popen, tuple[RunStatus, Any, float]]) -> None:
    """Stop the processes this launcher started (on an interrupt): terminate, then kill after a grace period."""
    for process in running:
        if process.poll() is None:
            process.terminate()
    deadline = time.monotonic() + 10
    for process, (_, log, _) in running.items():
        try:
            process.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        log.close()


def _last_error(log: Path) -> str:
    """The last non-empty line of a log (usually the exception), to report a failure in one line."""
    try:
        lines = [line.strip() for line in log.read_text(errors="replace").splitlines() if line.strip()]
    except OSError:
        return "no log"
    return lines[-1] if lines else "empty log"


def _duration(seconds: float) -> str:
    minutes, secs = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m" if hours else f"{minutes}m{secs:02d}s"


def _suffix(detail: str) -> str:
    return f": {detail}" if detail else ""


# ------------------------------------------------------------------------------------------------- evaluation
def final_evaluation(run: SweepRun, device: str = "cpu") -> list[dict[str, Any]]:
    """The records of the run's last checkpoint on its novel seeds (the run's ``eval`` block: seeds, repetitions,
    sampling seed), kept in ``<run>/evaluation/`` as ``scripts/evaluate.py`` writes them and reused when they are of
    that checkpoint."""
    from agents.evaluation.records import read_records, seed_list
    from agents.evaluation.runs import evaluate_runs

    latest = latest_checkpoint(run.run_dir)
    update = checkpoint_update(latest) if latest is not None else finished_update(run.run_dir)
    if update is None:
        raise SweepError(f"{run.name}: no checkpoint to evaluate")
    step = update * run.config.batch_size
    out = run.run_dir / FINAL_EVALUATION
    path = out / "episodes.csv"
    # The directory may also hold a user's own evaluations (scripts/evaluate.py writes here by default, perhaps with
    # other seeds or checkpoints): those rows are kept, and only the protocol's records of this checkpoint count.
    seeds = set(seed_list(run.config.eval_seeds))
    repetitions = run.config.eval.repetitions

    def protocol_records() -> list[dict[str, Any]]:
        return [
            record
            for record in (read_records(path) if path.is_file() else [])
            if record["step"] == step and record["seed"] in seeds and record["repetition"] < repetitions
        ]

    records = protocol_records()
    if len(records) == len(seeds) * repetitions:
        return records
    if latest is None:
        raise SweepError(f"{run.name}: finished, but neither its checkpoint nor its final evaluation is here")
    evaluate_runs([run.run_dir], out, device=device, force=True)
    return protocol_records()


def evaluate_panel(panel: Panel, *, device: str = "cpu", plots: bool = True, echo: Echo = print) -> Path:
    """Evaluate every finished run's last checkpoint on the novel seeds and write the panel's results directory
    (``<root>/<panel>/results``):

    * ``episodes.csv``: every run's in-training evaluation records (``<run>/eval/episodes.csv``) up to its last step,
      then the final evaluation of its last checkpoint, which takes the place of the in-training records of that
      step (same seeds, repetitions and sampling seed); the ``run`` column holds the run's name;
    * ``training.csv``: the runs' ``training.csv`` one after the other, ``run`` as above;
    * ``summary.json``: :func:`agents.analysis.scores.summarize` of those records (per run and step the means; per
      method and task, at every step the runs share, the IQM across runs with its 95% stratified-bootstrap interval),
      the runs not finished yet, the protocol and provenance;
    * ``plots/``: the curves and final-performance figures of :func:`agents.analysis.plots.plot_results`.

    Runs not finished are left out (and listed). Returns the results directory."""
    from agents.analysis.results import TRAINING_COLUMNS, read_episodes
    from agents.analysis.scores import summarize
    from agents.evaluation.records import read_records, write_records

    found = statuses(panel.runs)
    finished = [s.run for s in found if s.state == FINISHED]
    unfinished = [s.run.name for s in found if s.state != FINISHED]
    if not finished:
        raise SweepError(f"{panel.name}: no finished run to evaluate ({len(unfinished)} not finished)")
    records: list[dict[str, Any]] = []
    rows: list[dict[str, Any]] = []
    for index, run in enumerate(finished, 1):
        echo(f"[{index}/{len(finished)}] final evaluation: {run.name}")
        final = [{**record, "run": run.name} for record in final_evaluation(run, device)]
        last = max(record["step"] for record in final)
        in_training = run.run_dir / "eval" / "episodes.csv"
        if in_training.is_file():
            records += [{**r, "run": run.name} for r in read_records(in_training) if r["step"] < last]
        records += final
        rows += [{**row, "run": run.name} for row in _read_csv(run.run_dir / "training.csv")]
    out = panel.results_dir
    write_records(out / "episodes.csv", records)
    atomic_write_text(out / "training.csv", _csv_text(TRAINING_COLUMNS, rows))
    first = finished[0].config
    summary = {
        "panel": panel.name,
        "config": str(panel.source) if panel.source else None,
        "overrides": list(panel.overrides),
        "unfinished": unfinished,
        **summarize(read_episodes(out)),
        "evaluation": {
            "seeds": first.eval_seeds,
            "repetitions": first.eval.repetitions,
            "greedy": first.eval.greedy,
            "checkpoints": "last",
            "in_training_interval": first.eval.interval,
            **provenance(),
        },
    }
    write_json_atomic(out / "summary.json", summary, sort_keys=False)
    if plots:
        _plot(out, echo)
    if unfinished:
        echo(f"{panel.name}: {len(unfinished)} run(s) not finished and left out: {', '.join(unfinished)}")
    echo(f"{panel.name}: results in {out}")
    return out


def _plot(results_dir: Path, echo: Echo) -> None:
    """The panel's curves and final-performance charts (``agents.analysis.plots``) into ``results/plots``. A failure is
    reported, not raised: the records are written, and ``scripts/plot.py`` can draw them again."""
    try:
        from agents.analysis import plots
    except ImportError as err:
        echo(f"plots: skipped ({err}); the records are in {results_dir}")
        return
    try:
        paths = plots.plot_results([results_dir], results_dir / "plots")
    except Exception as err:  # noqa: BLE001 (whatever goes wrong in a figure must not hide the results)
        echo(f"plots: failed ({type(err).__name__}: {err}); retry: python scripts/plot.py {results_dir}")
        return
    echo("plots: " + ", ".join(str(path) for path in paths))


def _read_csv(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def _csv_text(columns: Sequence[str], rows: Sequence[dict[str, Any]]) -> str:
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    return text.getvalue()


# ---------------------------------------------------------------------------------------- estimates, report
CHECKPOINT_EXTRA_BYTES = 100_000  # config, RNG states, the slots' episodes, recent returns (measured: ~40 KB)
TRAINING_ROW_BYTES = 80  # one row of training.csv
RECORD_BYTES = 200  # one evaluation record (episodes.csv), with the environment's metrics
EVENT_BYTES_PER_UPDATE = 1_100  # TensorBoard scalars of one update (measured: ~1 KB, evaluations included)
ASSUMED_LM_WIDTH = 1024  # HELM features of a language model named by the hub (Pythia-410m, TrXL: 1024)


@dataclass(frozen=True)
class DiskEstimate:
    """What one run leaves on disk: its checkpoints (weights + AdamW's two moments, 12 bytes per parameter, plus
    the state that resuming needs) and its records (training.csv, evaluation records, TensorBoard events)."""

    parameters: int
    checkpoint_bytes: int
    kept: int
    record_bytes: int

    @property
    def run_bytes(self) -> int:
        return self.checkpoint_bytes * self.kept + self.record_bytes

    @property
    def peak_bytes(self) -> int:
        """While a checkpoint is written the oldest kept one still exists."""
        return self.run_bytes + self.checkpoint_bytes


_PARAMETERS: dict[str, int] = {}


def parameter_count(config: Config) -> int:
    """Trainable parameters of the run's model (the frozen HELM branch is not checkpointed)."""
    reconstruction = config.ppo.reconstruction_coef > 0  # the decoder is trained, so it counts
    env = config.env  # what decides the spaces
    settings = [env.id, env.options, env.make_kwargs, env.wrappers, env.image_layout, config_to_dict(config.model)]
    settings += [reconstruction, config.ppo.ground_truth_coef > 0]
    key = json.dumps(settings, sort_keys=True, default=str)
    if key not in _PARAMETERS:
        import torch

        from agents.policy.models import ActorCritic

        core = config.env.make_core(1)
        ground_truth = ground_truth_size(config, core)  # the estimator is trained, so it counts
        helm = _helm_width(config) if config.model.helm.enabled else 0
        with torch.device("meta"):  # shapes only: no memory, no initialisation cost
            spaces = core.single_observation_space, core.single_action_space
            model = ActorCritic(*spaces, config.model, helm, reconstruction, ground_truth)
        _PARAMETERS[key] = sum(p.numel() for p in model.parameters() if p.requires_grad)
    return _PARAMETERS[key]


def _helm_width(config: Config) -> int:
    helm = config.model.helm
    if helm.lm == "random":
        return helm.random_width
    local = Path(helm.lm) / "config.json"
    if local.is_file():
        settings = json.loads(local.read_text())
        for name in ("hidden_size", "d_model", "n_embd"):
            if isinstance(settings.get(name), int):
                return settings[name]
    return ASSUMED_LM_WIDTH


def disk_estimate(config: Config) -> DiskEstimate:
    """The disk use of one run of ``config`` at its end."""
    parameters = parameter_count(config)
    checkpoint = 12 * parameters + CHECKPOINT_EXTRA_BYTES
    updates = config.num_updates
    interval = config.run.checkpoint_interval
    written = (updates // interval if interval else 0) + (0 if interval and updates % interval == 0 else 1)
    kept = min(config.run.keep_checkpoints, written) if config.run.keep_checkpoints else written
    episodes = (config.eval_seeds[1] - config.eval_seeds[0] + 1) * config.eval.repetitions
    evaluations = 0
    if config.eval.interval:
        evaluations = updates // config.eval.interval + (0 if updates % config.eval.interval == 0 else 1)
    records = (
        updates * (TRAINING_ROW_BYTES + EVENT_BYTES_PER_UPDATE)
        + (evaluations + 1) * episodes * RECORD_BYTES  # + 1: the final evaluation
    )
    return DiskEstimate(parameters, checkpoint, kept, records)


def describe(panels: Sequence[Panel], *, width: int = 40) -> str:
    """The dry run: per panel its axes, every run with its state and overrides, the steps, the disk estimate and
    how many runs are finished, partial, new or running. Reads run directories; writes nothing."""
    lines: list[str] = []
    total_steps = total_bytes = 0
    for panel in panels:
        found = statuses(panel.runs)
        source = f"{panel.source} -> " if panel.source else ""
        chosen = " selected by " + " ".join(f"--only {item}" for item in panel.selection) if panel.selection else ""
        count = f"{len(panel.runs)} run{'' if len(panel.runs) == 1 else 's'}"
        lines.append(f"panel {panel.name}: {count}{chosen} ({source}{panel.directory})")
        lines += _axes_lines(panel)
        name_width = max(len(s.run.name) for s in found)
        lines.append(f"  {'run':<{name_width}}  {'state':<9} {'updates':>13}  overrides (grid)")
        for status in found:
            done = f"{status.update}/{status.num_updates}"
            overrides = " ".join(f"{key}={_short(value, width)}" for key, value in status.run.grid_overrides())
            lines.append(f"  {status.run.name:<{name_width}}  {status.state:<9} {done:>13}  {overrides}")
        steps = sum(run.steps for run in panel.runs)
        frames = sum(run.frames for run in panel.runs)
        skip = f" ({frames:,} frames with the frame skip)" if frames != steps else ""
        lines.append(f"  steps: {steps:,} agent steps in {len(panel.runs)} runs{skip}")
        estimates = [disk_estimate(run.config) for run in panel.runs]
        disk = sum(e.run_bytes for e in estimates)
        for kind, estimate in _distinct(panel.runs, estimates):
            lines.append(
                f"  disk per {kind} run: checkpoint {_bytes(estimate.checkpoint_bytes)} ({estimate.parameters:,} "
                f"parameters + AdamW state) x {estimate.kept} kept + records and logs {_bytes(estimate.record_bytes)}"
                f" = {_bytes(estimate.run_bytes)}"
            )
        lines.append(
            f"  disk for the panel: {_bytes(disk)} at the end (a run holds one more checkpoint while it writes one)"
        )
        if any(run.config.run.keep_checkpoints == 0 for run in panel.runs):
            lines.append("  warning: run.keep_checkpoints 0 keeps every checkpoint (disk grows with the run)")
        counts = {state: sum(s.state == state for s in found) for state in (FINISHED, PARTIAL, NEW, RUNNING)}
        lines.append("  runs: " + ", ".join(f"{count} {state}" for state, count in counts.items()))
        lines.append("")
        total_steps += steps
        total_bytes += disk
    if len(panels) > 1:
        runs = sum(len(panel.runs) for panel in panels)
        lines.append(f"all panels: {runs} runs, {total_steps:,} agent steps, disk {_bytes(total_bytes)}")
    return "\n".join(lines).rstrip() + "\n"


def _axes_lines(panel: Panel) -> list[str]:
    lines = []
    for axis, values in panel.grid.items():
        if axis in GRID_SETTINGS:
            continue
        if isinstance(values, dict):
            for index, (name, bundle) in enumerate(values.items()):
                sets = ", ".join(f"{key}={_short(value, 10_000)}" for key, value in (bundle or {}).items())
                lines.append(f"  {axis if index == 0 else '':<8} {name}: {sets or '(nothing)'}")
        else:
            lines.append(f"  {axis}: {', '.join(_short(value, 10_000) for value in values)}")
    if panel.overrides:
        lines.append(f"  --set (applied last): {' '.join(panel.overrides)}")
    default = SlurmConfig()
    settings = [
        f"{field.name}={_short(getattr(panel.slurm, field.name), 10_000)}"
        for field in dataclasses.fields(SlurmConfig)
        if getattr(panel.slurm, field.name) != getattr(default, field.name)
    ]
    lines.append(
        f"  slurm (--launcher slurm): {', '.join(settings) or 'defaults'}; {panel.slurm.timeout_min} min per job"
    )
    return lines


def _distinct(runs: Sequence[SweepRun], estimates: Sequence[DiskEstimate]) -> list[tuple[str, DiskEstimate]]:
    """One estimate per method (the model decides the size), in the panel's order."""
    seen: dict[str, DiskEstimate] = {}
    for run, estimate in zip(runs, estimates, strict=True):
        seen.setdefault(run.config.method, estimate)
    return list(seen.items())


def _short(value: Any, width: int) -> str:
    """A value as one line of YAML; a longer mapping as ``{N keys}`` (the axes list it in full)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10_000, sort_keys=False).strip()
    text = text.removesuffix("...").strip()
    if len(text) <= width:
        return text
    return f"{{{len(value)} keys}}" if isinstance(value, dict) else text[: width - 3] + "..."


def _bytes(count: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if count < 1000 or unit == "TB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.1f} {unit}"
        count /= 1000
    raise AssertionError  # unreachable


# -------------------------------------------------------------------------------------------------- worker
def main(argv: Sequence[str] | None = None) -> int:
    """``python -m agents.sweep RUN_DIR``: train one prepared run directory (what the local launcher runs)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        print("usage: python -m agents.sweep RUN_DIR", file=sys.stderr)
        return 2
    from agents.runtime.preemption import Preempted
    from agents.training.trainer import TrainingDiverged, WriteFailed

    try:
        result = train_run(args[0], echo=lambda text: print(text, flush=True))
    except Preempted as err:
        print(f"pre-empted: {err}", flush=True)
        return EXIT_PREEMPTED
    except (TrainingDiverged, WriteFailed, DamagedCheckpoint) as err:
        print(f"error: {err}", flush=True)
        return 1
    return EXIT_BUSY if result == "busy" else 0


if __name__ == "__main__":
    sys.exit(main())
