"""Train one config: ``memgym-train --config FILE [--set key=value ...] [--run-dir DIR]`` (the same command as
``python scripts/train.py``).

``--resume DIR`` continues a run from its newest checkpoint with the config saved in DIR (it says which checkpoint,
and how many rows of training.csv and eval/episodes.csv logged past it are dropped); a finished run is left as it is
(exit 0). ``--resume DIR --set run.total_steps=N`` lengthens a run, finished or not, to N steps; the schedules that
decay over the whole run go on from their current values to their final values at the new end. Besides that, a
resume takes only the settings no record depends on (``--set run.progress_bar=false``, run.checkpoint_interval,
run.keep_checkpoints, run.wandb.*, env.check_seeding: agents.config.RESULT_NEUTRAL) and run.torch_threads (with a
note: the rounding changes from there on), which config.yaml keeps from then on; any other key is refused, by name.

Exit status: 0 done (or finished already), 1 the run stopped on a non-finite loss or parameter or a failed write (the
message names the update or file; the newest checkpoint is intact), 2 bad arguments, config or run directory (a
damaged checkpoint with no intact one to fall back to is named), or a W&B run (run.wandb) that could not start (before
anything of the run was written: the same command works once it can), 76 pre-empted: SIGTERM or SLURM's warning signal
(SIGUSR2) stopped the run after its current update, which was checkpointed (resume it). Faults can be injected for
tests through the MEMGYM_FAULT environment variable (agents/runtime/faults.py).

The run directory (default ``runs/<config name>/<timestamp>-seed<seed>``) receives the resolved config, run_info.json
(seed, versions, git revision, resumes and extensions), training.csv, TensorBoard events and checkpoints.

A grid config (a ``grid:`` block, which scripts/sweep.py expands into runs) trains one of its runs, the one that
``--only KEY=VALUE[,KEY=VALUE...]`` selects: scripts/sweep.py's selection (keys: method, task, seed and the grid's
axes; values: the bundles' names and the axes' values), which must select exactly one run. It goes to
``runs/<config name>/<method>/<task>/<timestamp>-seed<seed>`` and is the run the sweep would train, names and all.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import yaml

from agents.config import (
    ROUNDING_ONLY,
    Config,
    ConfigError,
    load_config,
    resume_config,
    rounding_notice,
    sets_length,
)
from agents.experiments.planning import SweepError, SweepRun, load_panel, run_coordinates, select_runs
from agents.policy.checkpoint import checkpoint_damage, checkpoint_update, latest_checkpoint, run_config
from agents.runtime.preemption import EXIT_PREEMPTED, Preempted
from agents.runtime.tracking import TrackingError
from agents.training.logs import default_run_dir
from agents.training.trainer import Trainer, TrainingDiverged, WriteFailed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", help="YAML config file")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override (repeatable); with --resume only run.total_steps=N, to lengthen the run, and the settings "
        "no record depends on (e.g. run.progress_bar, run.wandb.*)",
    )
    parser.add_argument("--run-dir", help="run directory (default: runs/<config name>/<timestamp>-seed<seed>)")
    parser.add_argument("--resume", metavar="DIR", help="continue the run in DIR from its newest checkpoint")
    parser.add_argument(
        "--only",
        action="append",
        default=[],
        metavar="KEY=VALUE[,KEY=VALUE...]",
        help="with a grid config: the one run to train, selected as scripts/sweep.py --only selects runs (e.g. "
        "method=gru,seed=1); keys: method, task, seed and the grid's axes",
    )
    args = parser.parse_args(argv)
    if args.resume and (args.config or args.run_dir or args.only):
        parser.error("--resume DIR takes the config saved in DIR; it cannot be combined with --config/--run-dir/--only")
    if not args.resume and not args.config:
        parser.error("give --config FILE (or --resume DIR)")
    try:
        if args.resume:
            if done := _finished(Path(args.resume), args.set):
                print(done)
                return 0
            trainer = Trainer.resume(args.resume, args.set)
        else:
            config = load_config(args.config, args.set)
            cell: tuple[str, ...] = ()
            if config.grid or args.only:
                run = _grid_run(args.config, args.set, args.only, config)
                config, cell = run.config, (run.config.method, run.config.task)
                print(f"training one run of the grid: {run.name}", flush=True)
            run_dir = Path(args.run_dir) if args.run_dir else default_run_dir(args.config, config.run.seed, cell=cell)
            if (run_dir / "config.yaml").exists():
                parser.error(f"{run_dir} already holds a run; use --resume {run_dir} or another --run-dir")
            trainer = Trainer(config, run_dir)
    except (ConfigError, SweepError, FileNotFoundError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for note in trainer.resume_notes:  # damaged checkpoints passed over
        print(f"warning: {note}", file=sys.stderr, flush=True)
    if trainer.resumed_from is not None:
        print(_resume_message(trainer), flush=True)
    if trainer.settings_changed:
        changes = ", ".join(
            f"{key}: {_yaml(old)} -> {_yaml(new)}" for key, (old, new) in trainer.settings_changed.items()
        )
        print(f"settings changed on resume (no record depends on them): {changes}", flush=True)
    for key in sorted(set(trainer.settings_changed) & set(ROUNDING_ONLY)):
        print(f"note: {key}: {ROUNDING_ONLY[key]}", flush=True)
    if trainer.extension is not None:
        print(_extension_message(trainer.extension), flush=True)
    notice = rounding_notice(trainer.config)
    if notice and (not args.resume or trainer.extension is not None):
        print(f"note: {notice}", flush=True)
    print(f"run directory: {trainer.run_dir}", flush=True)
    try:
        history = trainer.train()
    except TrackingError as err:  # W&B could not start: nothing was written (a resumed run is as it was)
        print(f"error: {err}", file=sys.stderr)
        return 2
    except (TrainingDiverged, WriteFailed) as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    except Preempted as err:
        print(f"pre-empted: {err}", file=sys.stderr)
        return EXIT_PREEMPTED
    if history:
        last = history[-1]
        summary = {k: v for k, v in last.items() if k.startswith(("charts/episodic", "env/"))}
        print("last update: " + ", ".join(f"{k}={v:.4g}" for k, v in summary.items()))
    return 0


def _grid_run(config_path: str, overrides: list[str], only: list[str], config: Config) -> SweepRun:
    """The run of the grid config at ``config_path`` (``config``: as loaded) that ``only`` selects, as
    scripts/sweep.py expands and selects it (:func:`agents.experiments.planning.select_runs`); a ConfigError that says
    what can be selected when ``only`` is missing or selects several runs, a SweepError when it selects none."""
    if not config.grid:
        raise ConfigError(
            f"--only selects a run of a grid config, and {config_path} has no grid: block (train it without --only)"
        )
    panel = load_panel(config_path, overrides)
    if not only:
        raise ConfigError(
            f"{config_path} has a grid: block ({len(panel.runs)} runs): train one of them with --only "
            f"KEY=VALUE[,KEY=VALUE...] (e.g. --only {_example(panel.runs)}; {_choices(panel.runs)}), or all of them "
            f"with python scripts/sweep.py {config_path}"
        )
    runs = [run for selected in select_runs([panel], only) for run in selected.runs]
    if len(runs) > 1:
        raise ConfigError(
            f"--only {' '.join(only)} selects {len(runs)} runs of {config_path}, expected one: "
            f"{', '.join(run.name for run in runs)}; add pairs that tell them apart ({_choices(runs, varying=True)})"
        )
    return runs[0]


def _values(runs: list[SweepRun]) -> dict[str, list[str]]:
    """Per key --only takes (:func:`agents.experiments.planning.run_coordinates`), the values ``runs`` have, in
    order."""
    values: dict[str, list[str]] = {}
    for run in runs:
        for key, value in run_coordinates(run).items():
            if value not in values.setdefault(key, []):
                values[key].append(value)
    return values


def _choices(runs: list[SweepRun], varying: bool = False) -> str:
    """``method: gru, ppo; task: ...; seed: 1, 2`` (``varying``: only the keys whose values differ)."""
    found = _values(runs).items()
    return "; ".join(f"{_key(key)}: {', '.join(values)}" for key, values in found if not varying or len(values) > 1)


def _example(runs: list[SweepRun]) -> str:
    """An --only value that selects the first run: its value of every key the runs differ in."""
    first = run_coordinates(runs[0])
    keys = [key for key, values in _values(runs).items() if len(values) > 1] or ["run.seed"]
    return ",".join(f"{_key(key)}={first[key]}" for key in keys)


def _key(key: str) -> str:
    return "seed" if key == "run.seed" else key


def _finished(run_dir: Path, overrides: list[str]) -> str | None:
    """What to say when the run in ``run_dir`` has done all its updates and ``overrides`` do not lengthen it (None
    otherwise): read from the config and the newest checkpoint's name, before anything is built or written. Overrides
    a resume refuses are refused here too (ConfigError)."""
    config, latest = run_config(run_dir), latest_checkpoint(run_dir)
    resume_config(config, overrides, run_dir / "config.yaml")  # what a resume refuses is refused for a finished run too
    if sets_length(overrides):
        return None  # Trainer.resume lengthens the run (or says why the value does not lengthen it)
    if latest is None or checkpoint_update(latest) < config.num_updates or checkpoint_damage(latest):
        return None  # a damaged last checkpoint: Trainer.resume falls back to an intact one (or names the damage)
    steps, total = checkpoint_update(latest) * config.batch_size, config.num_updates * config.batch_size
    return (
        f"{run_dir}: already finished ({steps} steps of {total}); nothing changed. "
        f"To train it further: --resume {run_dir} --set run.total_steps=N (N >= {total + config.batch_size})"
    )


def _resume_message(trainer: Trainer) -> str:
    dropped = trainer.dropped
    rows, records = dropped.get("training.csv", 0), dropped.get("eval/episodes.csv", 0)
    return (
        f"resuming from {trainer.resumed_from} (update {trainer.update} of {trainer.num_updates}, step "
        f"{trainer.global_step}); dropped what the run logged after it: {rows} row{'' if rows == 1 else 's'} of "
        f"training.csv, {records} record{'' if records == 1 else 's'} of eval/episodes.csv (and their TensorBoard "
        "points)"
    )


def _yaml(value: Any) -> str:
    """A setting's value as YAML writes it in config.yaml (true, null, 3, offline)."""
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()


def _extension_message(record: dict[str, Any]) -> str:
    (old_steps, new_steps), (old_updates, new_updates) = record["total_steps"], record["num_updates"]
    return (
        f"lengthening the run from run.total_steps={old_steps} ({old_updates} updates) to {new_steps} "
        f"({new_updates} updates), from update {record['update']} (step {record['step']}) on: the schedules that "
        f"decay over the whole run go on from their values there to their final values at update {new_updates} "
        "(recorded in run_info.json, 'extended')"
    )
