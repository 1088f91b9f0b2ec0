"""The experiments room: sweeps, a grid config (one figure panel) expanded into named runs, trained on this machine
or on a SLURM cluster, resumed after a crash or a pre-emption, and evaluated into one results directory.

* :mod:`agents.experiments.planning`: the panel's runs, their names, and the runs ``--only`` selects;
* :mod:`agents.experiments.state`: where each run stands (new, partial, finished, running), its lock, its creation;
* :mod:`agents.experiments.dry_run`: the dry run's table and the disk estimate;
* :mod:`agents.experiments.launchers`: training one run, and the local launcher (processes on this machine);
* :mod:`agents.experiments.worker`: one run trained in its own process (``python -m agents.experiments.worker DIR``;
  not imported here, so that ``python -m`` runs it fresh);
* :mod:`agents.experiments.slurm`: the SLURM launcher (job arrays through submitit);
* :mod:`agents.experiments.panel`: the final evaluation and the panel's results directory.

The top floor of the package: it trains through :mod:`agents.training` and evaluates through
:mod:`agents.evaluation`; only the command lines (:mod:`agents.cli`, ``scripts/``) stand above it.
"""

from __future__ import annotations

from agents.experiments.dry_run import DiskEstimate, describe, disk_estimate, parameter_count
from agents.experiments.launchers import PREEMPTED, Outcome, launch_local, train_run, worker_command
from agents.experiments.panel import evaluate_panel, final_evaluation
from agents.experiments.planning import (
    Panel,
    SweepError,
    SweepRun,
    load_panel,
    panel_from_dict,
    parse_selection,
    run_coordinates,
    select_runs,
)
from agents.experiments.slurm import launch_slurm, wait_for_jobs
from agents.experiments.state import FINISHED, NEW, PARTIAL, RUNNING, RunStatus, prepare_run, run_status, statuses

__all__ = [
    "FINISHED",
    "NEW",
    "PARTIAL",
    "PREEMPTED",
    "RUNNING",
    "DiskEstimate",
    "Outcome",
    "Panel",
    "RunStatus",
    "SweepError",
    "SweepRun",
    "describe",
    "disk_estimate",
    "evaluate_panel",
    "final_evaluation",
    "launch_local",
    "launch_slurm",
    "load_panel",
    "panel_from_dict",
    "parameter_count",
    "parse_selection",
    "prepare_run",
    "run_coordinates",
    "run_status",
    "select_runs",
    "statuses",
    "train_run",
    "wait_for_jobs",
    "worker_command",
]
