"""The SLURM launcher of sweeps: every new or partial run of a panel submitted as one job of a job array through
submitit, requeued when it is pre-empted or reaches its time limit, and resumed from its newest checkpoint.

A job runs :func:`agents.experiments.launchers.train_run` on one prepared run directory, exactly as the local launcher's
worker does; the panel's ``grid.slurm`` block (:class:`agents.config.SlurmConfig`) holds the cluster settings.
submitit's job files and the jobs' logs go to ``<root>/<panel>/slurm/``, with ``submissions.jsonl`` saying which job
trained which run. The plan, run states and the local launcher are in :mod:`agents.experiments`.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from agents.experiments.launchers import Outcome, train_run, worker_environment
from agents.experiments.planning import Echo, Panel, SweepError, SweepRun
from agents.experiments.state import NEW, PARTIAL, prepare_run, statuses
from agents.runtime.io import now


class RunJob:
    """What a SLURM job runs: :func:`train_run` on one run directory. submitit calls :meth:`checkpoint` when the
    job is pre-empted or about to time out; the job is then requeued with a fresh ``RunJob`` of the same directory,
    which resumes from the run's newest checkpoint (at most ``run.checkpoint_interval`` updates are redone)."""

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = str(run_dir)

    def __call__(self) -> str:
        return train_run(self.run_dir)

    def checkpoint(self, *args: Any, **kwargs: Any) -> Any:
        from submitit.helpers import DelayedSubmission

        return DelayedSubmission(RunJob(self.run_dir))

    def __repr__(self) -> str:
        return f"RunJob({self.run_dir!r})"


def slurm_executor(panel: Panel, cluster: str | None = None) -> Any:
    """A submitit executor for the panel's jobs (logs in ``<panel>/slurm``) with its ``grid.slurm`` settings;
    ``cluster``: submitit's name for where the jobs run (None: detect SLURM; ``local``: processes on this machine)."""
    try:
        import submitit
    except ImportError as err:
        raise SweepError('the SLURM launcher needs submitit: pip install -e ".[slurm]"') from err
    if cluster in (None, "slurm") and shutil.which("sbatch") is None:
        raise SweepError("no SLURM here (sbatch not found); --slurm-cluster local runs the jobs on this machine")
    slurm = panel.slurm
    executor = submitit.AutoExecutor(
        folder=panel.slurm_dir,
        cluster=cluster,
        slurm_max_num_timeout=slurm.max_requeues,
        local_max_num_timeout=slurm.max_requeues,
    )
    parameters: dict[str, Any] = {"name": f"sweep-{panel.name}", "timeout_min": slurm.timeout_min, "nodes": 1}
    parameters["tasks_per_node"] = 1
    if slurm.gpus_per_job:
        parameters["gpus_per_node"] = slurm.gpus_per_job
    if slurm.cpus_per_job:
        parameters["cpus_per_task"] = slurm.cpus_per_job
    if slurm.mem_gb:
        parameters["mem_gb"] = slurm.mem_gb
    for key in ("partition", "account", "qos", "constraint"):
        if getattr(slurm, key):
            parameters[f"slurm_{key}"] = getattr(slurm, key)
    if slurm.array_parallelism:
        parameters["slurm_array_parallelism"] = slurm.array_parallelism
    if slurm.setup:
        parameters["slurm_setup"] = list(slurm.setup)
    if slurm.additional:
        parameters["slurm_additional_parameters"] = dict(slurm.additional)
    executor.update_parameters(**parameters)
    return executor


def launch_slurm(panel: Panel, *, cluster: str | None = None, echo: Echo = print) -> list[tuple[SweepRun, Any]]:
    """Submit every new or partial run of the panel as one job of a job array; returns ``(run, job)`` pairs.
    New runs get ``grid.slurm.cpus_per_job`` torch threads. Runs held by a running job are left alone; a job that
    starts while another trains its run exits at once."""
    pending = [s for s in statuses(panel.runs) if s.state in (NEW, PARTIAL)]
    if not pending:
        return []
    slurm = panel.slurm
    if slurm.gpus_per_job and all(s.run.config.run.device == "cpu" for s in pending):
        echo(
            f"warning: {panel.name}: the jobs ask for GPUs but the runs train on run.device=cpu "
            "(add --set run.device=cuda)"
        )
    if not slurm.cpus_per_job and any(s.run.config.run.torch_threads == 0 for s in pending):
        echo(
            f"warning: {panel.name}: no grid.slurm.cpus_per_job (--slurm-cpus): torch will start one thread per "
            "core it can see"
        )
    executor = slurm_executor(panel, cluster)
    for status in pending:
        prepare_run(status.run, slurm.cpus_per_job)
    jobs = []
    with _importable_repository(), executor.batch():  # one job array; the jobs get their ids when it closes
        for status in pending:
            jobs.append(executor.submit(RunJob(status.run.run_dir)))
    submitted = [(status.run, job) for status, job in zip(pending, jobs, strict=True)]
    lines = [
        json.dumps({"time": now(), "run": run.name, "job": str(job.job_id), "run_dir": str(run.run_dir)})
        for run, job in submitted
    ]
    panel.slurm_dir.mkdir(parents=True, exist_ok=True)  # submitit's debug executor makes no folder
    with open(panel.slurm_dir / "submissions.jsonl", "a") as handle:  # which job trained which run (sacct)
        handle.write("".join(line + "\n" for line in lines))
    for (run, job), status in zip(submitted, pending, strict=True):
        what = "new" if status.update == 0 else f"resume at update {status.update}"
        echo(f"submitted job {job.job_id}: {run.name} ({what})")
    return submitted


@contextlib.contextmanager
def _importable_repository() -> Iterator[None]:
    """Jobs inherit the submitting environment: make this checkout importable there while submitting."""
    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = worker_environment()["PYTHONPATH"]
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = old


def wait_for_jobs(submitted: Sequence[tuple[SweepRun, Any]], echo: Echo = print, poll_s: float = 30.0) -> list[Outcome]:
    """Wait until every submitted job is done (requeued jobs included); the outcome of each run."""
    outcomes, waiting = [], list(submitted)
    while waiting:
        for run, job in [pair for pair in waiting if pair[1].done()]:
            waiting.remove((run, job))
            try:
                result = job.result()
            except Exception as err:  # noqa: BLE001 (submitit re-raises the job's exception, whatever it is)
                outcome = Outcome(run, "failed", f"job {job.job_id}: {_one_line(err)}")
            else:
                outcome = Outcome(run, "busy" if result == "busy" else "ok", f"job {job.job_id}")
            outcomes.append(outcome)
            echo(f"{outcome.result}: {run.name}: {outcome.detail}")  # the detail names the job
        if waiting:
            time.sleep(poll_s)
    return outcomes


def _one_line(err: BaseException) -> str:
    """The first line of an error (submitit's own errors follow it with the job's log tail)."""
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    return f"{type(err).__name__}: {lines[0]}" if lines else type(err).__name__
