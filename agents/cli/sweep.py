"""Train a grid of runs (one figure panel per config file), locally or on a SLURM cluster, and evaluate it; the
same command as ``python scripts/sweep.py``.

    memgym-sweep CONFIG [CONFIG ...] [--launcher local|slurm] [--jobs N] [--root DIR] [--dry-run]
        [--evaluate] [--only KEY=VALUE[,KEY=VALUE...] ...] [--set KEY=VALUE ...]
        [--slurm-partition P --slurm-time T --slurm-gpus N --slurm-cpus N ...]

Every CONFIG's ``grid:`` block expands into runs named ``<panel>/<method>/<task>/seed<k>`` under ``--root`` (default
``runs/``); see agents/config/grids.py for the format and agents/experiments/planning.py for the layout. ``--dry-run``
prints the runs with their overrides and states, the environment steps and a disk estimate, and changes nothing.

Re-running the same command continues the sweep: finished runs are skipped, interrupted ones resume from their newest
checkpoint, and a run directory whose saved config differs from the grid's is an error (nothing is overwritten).

``--launcher local`` (default) trains ``--jobs`` runs at a time on this machine, each with its share of the cores as
torch threads (fixed when the run is created), its output in ``<run>/stdout.log``; a failed run is reported at the end
without stopping the others, and the exit status is 1 if any failed. ``--launcher slurm`` submits one job per run as
a job array through submitit (``pip install -e ".[slurm]"``), with the settings of the config's ``grid.slurm`` block
or the ``--slurm-*`` options; a pre-empted or timed-out job is requeued and resumes from its last checkpoint. Jobs run
in the background; with ``--evaluate`` this command waits for them.

``--evaluate`` evaluates every finished run's last checkpoint on the novel seeds and writes the panel's results to
``<root>/<panel>/results/`` (episodes.csv with the in-training and final evaluation records, training.csv,
summary.json, plots); with ``--no-train`` nothing is launched first (say, while SLURM jobs are queued: the local
launcher would otherwise train their runs here).

``--only KEY=VALUE[,KEY=VALUE...]`` picks runs (cells) of the grids by name, without restating a bundle: the keys are
the grids' axes (``method``, ``task``, dotted plain axes such as ``ppo.gamma``) and ``run.seed`` (or ``seed``); the
values are the bundles' names and the axes' values, and a key or value that no run has is an error listing the valid
ones. One ``--only`` keeps the runs that match all its pairs; repeated, it keeps the runs that match any of them
(``--only method=gru,seed=0 --only method=ppo`` is GRU's seed 0 and every PPO run). It applies to the dry run, the
local launcher and SLURM submission alike; ``--evaluate`` still writes each selected panel's results from all its
finished runs, so a selection never replaces a panel's table with a part of it.

``--set KEY=VALUE`` applies to every run, after the grid; ``--set grid.AXIS=VALUES`` replaces an axis (e.g.
``--set grid.run.seed=[0]``).

SIGTERM (or SLURM's warning signal, SIGUSR2) to this command stops the local launcher: every running run gets the
signal, finishes its update, writes a checkpoint and exits; no further run starts. Two sweeps on the same --root never
train one run at once (each run directory is locked while it trains; the other finds it busy and leaves it).
Exit status: 0 done, 1 some run failed, 2 bad config or arguments, 76 pre-empted (re-run to resume).
"""

from __future__ import annotations

import argparse
import json
import sys

from agents.config import NAMED_AXES, ConfigError
from agents.experiments.dry_run import describe
from agents.experiments.launchers import PREEMPTED, launch_local
from agents.experiments.panel import evaluate_panel
from agents.experiments.planning import SweepError, load_panel, select_runs
from agents.experiments.slurm import launch_slurm, wait_for_jobs
from agents.runtime.preemption import EXIT_PREEMPTED

# --slurm-* options -> grid.slurm keys, and whether the value is text (quoted so YAML keeps it a string)
SLURM_OPTIONS = {
    "partition": ("partition", True, "partition"),
    "time": ("time", True, "time limit per job, minutes or [D-]HH:MM:SS (default 24:00:00)"),
    "gpus": ("gpus_per_job", False, "GPUs per job"),
    "cpus": ("cpus_per_job", False, "CPU cores per job (new runs get as many torch threads)"),
    "mem-gb": ("mem_gb", False, "memory per job in GB"),
    "array-parallelism": ("array_parallelism", False, "array tasks running at once"),
    "account": ("account", True, "account to charge"),
    "qos": ("qos", True, "quality of service"),
    "constraint": ("constraint", True, "node features"),
    "max-requeues": ("max_requeues", False, "times a timed-out job is requeued (default 20)"),
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("configs", nargs="+", metavar="CONFIG", help="grid config files (one panel each)")
    parser.add_argument("--launcher", choices=("local", "slurm"), default="local")
    parser.add_argument("--jobs", type=int, default=1, help="local: runs trained at once (default 1)")
    parser.add_argument("--root", default="runs", help="where the runs and results go (default runs/)")
    parser.add_argument("--dry-run", action="store_true", help="print the runs, steps and disk estimate; train nothing")
    parser.add_argument("--evaluate", action="store_true", help="evaluate the finished runs into <panel>/results")
    parser.add_argument(
        "--no-train", action="store_true", help="launch nothing (e.g. --evaluate while SLURM jobs are still queued)"
    )
    parser.add_argument("--eval-device", default="cpu", help="torch device of the final evaluation (default cpu)")
    parser.add_argument(
        "--only",
        action="append",
        default=[],
        metavar="KEY=VALUE[,KEY=VALUE...]",
        help="train, submit, list or evaluate only the runs that match all these pairs (e.g. method=gru,task=mmact_grid"
        " or seed=0); repeat for more runs (any of them); keys: the grid's axes and run.seed (seed)",
    )
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override (repeatable)")
    slurm = parser.add_argument_group("SLURM (override the config's grid.slurm block)")
    for option, (_, _, help_text) in SLURM_OPTIONS.items():
        slurm.add_argument(f"--slurm-{option}", metavar="VALUE", help=help_text)
    slurm.add_argument(
        "--slurm-cluster",
        choices=("slurm", "local", "debug"),
        default=None,
        help="where submitit runs the jobs: slurm (default when sbatch exists), local (processes on this machine, to "
        "try a setup without a cluster), debug (in this process)",
    )
    slurm.add_argument("--slurm-poll", type=float, default=60.0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    overrides = list(args.set) + _slurm_overrides(args)
    try:
        panels = [load_panel(path, overrides, root=args.root) for path in args.configs]
        names = [panel.name for panel in panels]
        if len(set(names)) != len(names):
            raise ConfigError(f"two configs name the same panel ({', '.join(names)}): give one a grid.panel")
        selected = select_runs(panels, args.only)
        if args.dry_run:
            print(describe(selected), end="")
            return 0
        outcomes = [] if args.no_train else _train(selected, args)
        failed = [outcome for outcome in outcomes if outcome.result == "failed"]
        preempted = [outcome for outcome in outcomes if outcome.result == PREEMPTED]
        if args.evaluate:
            chosen = {panel.name for panel in selected}
            for panel in panels:  # the whole panel: its results gather every finished run, whatever --only picked
                if panel.name in chosen:
                    evaluate_panel(panel, device=args.eval_device)
    except (ConfigError, SweepError, FileNotFoundError) as err:
        print(f"error: {err}{_only_hint(args.set)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: re-run the same command to continue the sweep", file=sys.stderr)
        return 130
    if failed:
        print(f"{len(failed)} run(s) failed:", file=sys.stderr)
        for outcome in failed:
            print(f"  {outcome.run.name}: {outcome.detail}", file=sys.stderr)
        print("re-run the same command to retry them (finished runs are skipped)", file=sys.stderr)
        return 1
    if preempted:
        print(f"pre-empted: {len(preempted)} run(s) stopped at a checkpoint; re-run the same command to resume them")
        return EXIT_PREEMPTED
    return 0


def _train(panels: list, args: argparse.Namespace) -> list:
    """Launch the panels' unfinished runs; their outcomes."""
    if args.launcher == "local":
        runs = [run for panel in panels for run in panel.runs]
        outcomes = launch_local(runs, args.jobs)
        if not outcomes:
            print("nothing to train: every run is finished (or running elsewhere)")
    else:
        submitted = []
        for panel in panels:
            submitted += launch_slurm(panel, cluster=args.slurm_cluster)
        if not submitted:
            print("nothing to submit: every run is finished (or running)")
        if not args.evaluate or not submitted:
            return []
        print(f"waiting for {len(submitted)} job(s) (Ctrl-C stops waiting; the jobs go on)")
        outcomes = wait_for_jobs(submitted, poll_s=args.slurm_poll)
    return outcomes


def _only_hint(overrides: list[str]) -> str:
    """A named axis given as a list of its names (``--set grid.method=[gru]``) asks for what --only does: say so."""
    for item in overrides:
        key, _, value = (part.strip() for part in item.partition("="))
        axis = key.removeprefix("grid.")
        if key.startswith("grid.") and axis in NAMED_AXES and value.startswith("["):
            return f"\nto train some of the grid's {axis} bundles, select them by name: --only {axis}=NAME"
    return ""


def _slurm_overrides(args: argparse.Namespace) -> list[str]:
    overrides = []
    for option, (key, text, _) in SLURM_OPTIONS.items():
        value = getattr(args, "slurm_" + option.replace("-", "_"))
        if value is not None:
            overrides.append(f"grid.slurm.{key}={json.dumps(value) if text else value}")
    return overrides
