"""The dry run of a sweep (``scripts/sweep.py --dry-run``): per panel its axes, every run with its state and
overrides, the steps, and an estimate of the disk its runs will use. Reads run directories; writes nothing.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from agents.config import GRID_SETTINGS, Config, SlurmConfig, config_to_dict
from agents.experiments.planning import Panel, SweepRun, short_yaml
from agents.experiments.state import FINISHED, NEW, PARTIAL, RUNNING, statuses
from agents.policy.checkpoint import ground_truth_size

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
            overrides = " ".join(f"{key}={short_yaml(value, width)}" for key, value in status.run.grid_overrides())
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
                sets = ", ".join(f"{key}={short_yaml(value, 10_000)}" for key, value in (bundle or {}).items())
                lines.append(f"  {axis if index == 0 else '':<8} {name}: {sets or '(nothing)'}")
        else:
            lines.append(f"  {axis}: {', '.join(short_yaml(value, 10_000) for value in values)}")
    if panel.overrides:
        lines.append(f"  --set (applied last): {' '.join(panel.overrides)}")
    default = SlurmConfig()
    settings = [
        f"{field.name}={short_yaml(getattr(panel.slurm, field.name), 10_000)}"
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


def _bytes(count: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if count < 1000 or unit == "TB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.1f} {unit}"
        count /= 1000
    raise AssertionError  # unreachable
