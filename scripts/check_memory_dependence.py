"""Regression check: does GRU-PPO still beat memory-less PPO beyond doubt on a CPU-scale Memory Gym task?

    python scripts/check_memory_dependence.py [--config configs/cpu/mm_grid_1.yaml] [--seeds 0 1 2]
        [--root runs/check] [--jobs 2] [--better gru] [--worse ppo]

Trains (or resumes, or reuses) the two methods of the panel on the given seeds with ``scripts/sweep.py``, evaluates
them on the novel seeds, and exits 0 when, at the last step, the 95% stratified-bootstrap interval of ``--better``'s
IQM lies wholly above ``--worse``'s on every task of the panel, 1 when it does not (the numbers are printed either
way). Run it before trusting a change to the trainer, the models or the environments: a memory mechanism that no
longer helps on a task that needs memory is a regression.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from agents.analysis.scores import separation
from agents.config import read_config_file
from scripts import sweep as sweep_script

ROOT = Path(__file__).resolve().parent.parent


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default=str(ROOT / "configs" / "cpu" / "mm_grid_1.yaml"), help="a grid panel")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="run.seed of the runs")
    parser.add_argument("--root", default="runs/check", help="where the runs and results go")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--better", default="gru", help="the method that must win (a bundle of the method axis)")
    parser.add_argument("--worse", default="ppo", help="the method that must lose")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override (repeatable)")
    args = parser.parse_args(argv)
    if len(set(args.seeds)) < 2:
        # an interval over one run per method is a single point: "separated" would then only mean "different"
        parser.error(f"--seeds needs at least 2 distinct seeds (got {args.seeds}): the 95% intervals are over runs")
    grid = read_config_file(args.config).get("grid", {})
    bundles = grid.get("method", {})
    missing = [name for name in (args.better, args.worse) if name not in bundles]
    if missing:
        parser.error(f"{args.config} has no method bundle {missing}; its methods: {', '.join(bundles) or 'none'}")
    methods = json.dumps({name: bundles[name] for name in (args.better, args.worse)})
    overrides = [f"grid.method={methods}", f"grid.run.seed={json.dumps(args.seeds)}", *args.set]
    sweep_args = [args.config, "--root", args.root, "--jobs", str(args.jobs), "--evaluate"]
    code = sweep_script.main([*sweep_args, *(item for o in overrides for item in ("--set", o))])
    if code != 0:
        print(f"error: the sweep failed (exit status {code})", file=sys.stderr)
        return 2
    panel = grid.get("panel") or Path(args.config).stem
    summary = json.loads((Path(args.root) / panel / "results" / "summary.json").read_text())
    verdict = separation(summary["aggregate"], args.better, args.worse)
    for task, entry in verdict["tasks"].items():
        high, low = entry["better"], entry["worse"]
        print(
            f"{task} at step {verdict['step']}: {args.better} IQM {high['iqm']:.3f} [{high['low']:.3f}, "
            f"{high['high']:.3f}] vs {args.worse} {low['iqm']:.3f} [{low['low']:.3f}, {low['high']:.3f}] over "
            f"{high['runs']} and {low['runs']} runs: {'separated' if entry['separated'] else 'NOT separated'}"
        )
    return 0 if verdict["separated"] else 1


if __name__ == "__main__":
    sys.exit(main())
