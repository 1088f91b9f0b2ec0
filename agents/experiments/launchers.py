"""Training the runs of a sweep: one run (:func:`train_run`, the same for the local and the SLURM launcher), and
the local launcher (:func:`launch_local`): every new or partial run trained in a process of its own
(``python -m agents.experiments.worker RUN_DIR``), ``--jobs`` at a time, each with its share of the cores. The SLURM
launcher is :mod:`agents.experiments.slurm`.

Training a run holds an exclusive lock on ``<run>/.lock`` (a second process finds the run busy and leaves it),
starts from scratch when there is no checkpoint (clearing what a killed first attempt left), and otherwise continues
exactly from the newest checkpoint (``Trainer.resume``, the semantics of ``scripts/train.py --resume``). Re-running a
sweep therefore finishes it without redoing work: finished runs are not touched, interrupted ones lose at most
``run.checkpoint_interval`` updates. Disk use stays bounded by ``run.keep_checkpoints`` (the paper configs keep 1);
learning curves come from the in-training evaluation records. Pre-empted or interrupted, the runs stop at a
checkpoint and resume on the next call.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.experiments.planning import Echo, SweepError, SweepRun
from agents.experiments.state import FINISHED, NEW, PARTIAL, RunStatus, lock_holder, prepare_run, run_lock, statuses
from agents.policy.checkpoint import checkpoint_damage, checkpoint_update, latest_checkpoint, run_config
from agents.runtime.faults import FaultSpecError, active_faults
from agents.runtime.io import now
from agents.runtime.preemption import EXIT_PREEMPTED, StopRequests, signal_name

PREEMPTED = "preempted"  # an outcome: the run stopped at a checkpoint on a signal (resumable, not failed)
EXIT_BUSY = 75  # the worker's exit status when another process trains the run (EX_TEMPFAIL)
LOG_FILE = "stdout.log"
REPO_ROOT = Path(__file__).resolve().parents[2]
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


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
    """The command that trains one prepared run in its own process (``python -m agents.experiments.worker RUN_DIR``)."""
    return [sys.executable, "-m", "agents.experiments.worker", str(run_dir)]


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
