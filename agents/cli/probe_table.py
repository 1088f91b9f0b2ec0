"""The calibration table of a panel of probe runs: ``python scripts/probe_table.py results/cpu/probes``.

For every run under the panel directory (``<panel>/<method>/<task>/seed<k>``), one row: the task's environment and
non-default options, the method, the steps it trained (and whether it finished or was stopped), its mean novel-seed
metric at each in-training evaluation (``eval/episodes.csv``) and its wall time; and per task the metric of a
uniformly random policy on the same novel seeds (``--random-episodes`` episodes, seeded), the floor a probe must
clear. Printed as a Markdown table (``--out FILE`` also writes it), sorted by task, then method.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agents.analysis.metrics import metric_of
from agents.cli.results_table import run_minutes
from agents.runtime.io import atomic_write_text


def random_policy_metric(env_id: str, options: dict[str, Any], episodes: int, seed: int) -> float:
    """The mean metric of uniformly random actions over ``episodes`` episodes of ``env_id`` with ``options``, on the
    seeds from ``seed`` on (one per episode; the actions from ``default_rng(seed)``)."""
    import gymnasium as gym

    import envs  # noqa: F401 (registers the ids)

    metric = metric_of(env_id)
    slots = min(episodes, 32)
    vec = gym.make_vec(env_id, num_envs=slots, options=options)
    vec.action_space.seed(seed)
    vec.reset(seed=seed)
    values: list[float] = []
    while len(values) < episodes:
        _, _, terminated, truncated, info = vec.step(vec.action_space.sample())
        ended = np.flatnonzero(terminated | truncated)
        final = info.get("final_info", info)
        for slot in ended:
            values.append(float(metric.value({key: v[slot] for key, v in final.items() if not key.startswith("_")})))
    vec.close()
    return float(np.mean(values[:episodes]))


def probe_rows(panel_dir: Path) -> list[dict[str, Any]]:
    """One row per run directory of ``panel_dir``."""
    rows = []
    for config_path in sorted(panel_dir.glob("*/*/seed*/config.yaml")):
        run = config_path.parent
        config = yaml.safe_load(config_path.read_text())
        info = json.loads((run / "run_info.json").read_text()) if (run / "run_info.json").is_file() else {}
        curve: dict[int, list[float]] = defaultdict(list)
        if (run / "eval" / "episodes.csv").is_file():
            with open(run / "eval" / "episodes.csv", newline="") as handle:
                for record in csv.DictReader(handle):
                    curve[int(record["step"])].append(float(record["metric"]))
        steps = 0
        if (run / "training.csv").is_file():
            with open(run / "training.csv", newline="") as handle:
                logged = list(csv.DictReader(handle))
            steps = int(logged[-1]["step"]) if logged else 0
        finished = info.get("finished")
        timed = run_minutes(run)
        minutes = None if timed is None else timed[0]
        rows.append(
            {
                "task": run.parent.name,
                "method": run.parent.parent.name,
                "seed": run.name,
                "env_id": config["env"]["id"],
                "options": config["env"].get("options") or {},
                "steps": steps,
                "finished": finished is not None,
                "curve": {step: float(np.mean(values)) for step, values in sorted(curve.items())},
                "minutes": minutes,
            }
        )
    return rows


def markdown(rows: list[dict[str, Any]], floors: dict[str, float]) -> str:
    lines = [
        "| task | env id and options | method | steps | novel-seed metric by evaluation (k steps: mean) | random | "
        "wall min |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in sorted(rows, key=lambda r: (r["task"], r["method"], r["seed"])):
        options = ", ".join(f"{key}: {json.dumps(value)}" for key, value in row["options"].items())
        curve = ", ".join(f"{step // 1000}: {value:.3f}" for step, value in row["curve"].items()) or "none"
        steps = f"{row['steps'] // 1000}k" + ("" if row["finished"] else " (stopped)")
        minutes = f"{row['minutes']:.0f}" if row["minutes"] is not None else ""
        floor = floors.get(row["task"])
        metric = metric_of(row["env_id"]).name
        lines.append(
            f"| {row['task']} | {row['env_id']} ({options}) | {row['method']} | {steps} | {metric} {curve} | "
            f"{'' if floor is None else f'{floor:.3f}'} | {minutes} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("panel", type=Path, help="the probes' panel directory, e.g. results/cpu/probes")
    parser.add_argument("--random-episodes", type=int, default=300, help="episodes of the random policy per task")
    parser.add_argument("--seed", type=int, default=100000, help="first seed of the random policy's episodes")
    parser.add_argument("--out", type=Path, help="also write the table to this file")
    args = parser.parse_args(argv)
    rows = probe_rows(args.panel)
    if not rows:
        print(f"error: {args.panel} holds no run (<method>/<task>/seed<k>/config.yaml)", file=sys.stderr)
        return 2
    tasks = {row["task"]: (row["env_id"], row["options"]) for row in rows}
    floors = {
        task: random_policy_metric(env_id, options, args.random_episodes, args.seed)
        for task, (env_id, options) in tasks.items()
    }
    table = markdown(rows, floors)
    print(table, end="")
    if args.out is not None:
        atomic_write_text(args.out, table)
    return 0
