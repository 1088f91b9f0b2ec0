"""Synthetic results directories (``episodes.csv`` and ``training.csv``) in the evaluation's format, for the tests of
agents.analysis.results, agents.analysis.plots, scripts/plot.py and the notebook."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agents.analysis.results import EPISODE_COLUMNS, TRAINING_COLUMNS

TASKS = {  # task -> env id (two tasks may share an id with different options)
    "ProofOfMemory-v0": "ProofOfMemory-v0",
    "MortarMayhem-Grid-v0": "MortarMayhem-Grid-v0",
}
SKILL = {"ppo": 0.3, "gru": 0.9, "stack4": 0.5, "helm": 0.7}


def episode_rows(
    methods: Sequence[str] = ("ppo", "gru"),
    tasks: dict[str, str] | None = None,
    runs: int = 3,
    steps: Sequence[int] = (8192, 16384, 24576),
    seeds: int = 4,
    repetitions: int = 2,
    seed: int = 0,
) -> list[dict]:
    """One record per episode: successes (ProofOfMemory) or fractions of commands (Mortar Mayhem) that grow with the
    step and the method's skill; ``success`` is left empty for runs whose id starts with ``Endless``."""
    rng = np.random.default_rng(seed)
    rows = []
    for method in methods:
        for task, env_id in (tasks or TASKS).items():
            for run in range(runs):
                name = f"{method}-{task}-{run}"
                for k, step in enumerate(steps):
                    p = SKILL.get(method, 0.5) * (k + 1) / len(steps)
                    for s in range(seeds):
                        for repetition in range(repetitions):
                            if env_id.startswith("Mortar"):
                                metric = rng.integers(0, 11) / 10 * p
                                success = float(metric == 1.0)
                            else:
                                metric = float(rng.random() < p)
                                success = metric
                            rows.append(
                                {
                                    "run": name,
                                    "method": method,
                                    "task": task,
                                    "env_id": env_id,
                                    "step": step,
                                    "seed": 100_000 + s,
                                    "repetition": repetition,
                                    "return": metric + 0.1 * rng.random(),
                                    "length": int(rng.integers(10, 100)),
                                    "metric": metric,
                                    "metric_reference": min(1.0, metric + 0.1),
                                    "success": "" if env_id.startswith("Endless") else success,
                                }
                            )
    return rows


def training_rows(
    methods: Sequence[str] = ("ppo", "gru"),
    tasks: dict[str, str] | None = None,
    runs: int = 3,
    updates: int = 30,
    steps_per_update: int = 1024,
    seed: int = 0,
) -> list[dict]:
    """One row per PPO update: a noisy return rising with the method's skill; every fifth update without episodes."""
    rng = np.random.default_rng(seed + 1)
    rows = []
    for method in methods:
        for task, env_id in (tasks or TASKS).items():
            for run in range(runs):
                for update in range(1, updates + 1):
                    value = SKILL.get(method, 0.5) * update / updates + 0.05 * rng.normal()
                    rows.append(
                        {
                            "run": f"{method}-{task}-{run}",
                            "method": method,
                            "task": task,
                            "env_id": env_id,
                            "step": update * steps_per_update,
                            "return": "" if update % 5 == 0 else value,
                            "length": 50,
                            "metric": "",
                        }
                    )
    return rows


def write_csv(path: Path, rows: list[dict], columns: Sequence[str]) -> None:
    extra = [name for name in rows[0] if name not in columns] if rows else []
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=[*columns, *extra])
        writer.writeheader()
        writer.writerows(rows)


def write_results(directory: Path, training: bool = True, **options) -> Path:
    """A results directory with ``episodes.csv`` and (with ``training``) ``training.csv``; returns it."""
    seed = options.get("seed", 0)
    write_csv(directory / "episodes.csv", episode_rows(**options), EPISODE_COLUMNS)
    if training:
        keep = {key: options[key] for key in ("methods", "tasks", "runs") if key in options}
        write_csv(directory / "training.csv", training_rows(**keep, seed=seed), TRAINING_COLUMNS)
    return directory
