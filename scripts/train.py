"""Train one config: ``python scripts/train.py --config FILE [--set key=value ...] [--run-dir DIR]``.

``--resume DIR`` continues a run from its newest checkpoint with the config saved in DIR. The run directory
(default ``runs/<config name>/<timestamp>-seed<seed>``) receives the resolved config, run_info.json (seed, versions,
git revision), TensorBoard events and checkpoints.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout without installing

from agents.config import ConfigError, load_config, rounding_notice  # noqa: E402
from agents.trainer import Trainer, TrainingDiverged, default_run_dir  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", help="YAML config file")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override (repeatable)")
    parser.add_argument("--run-dir", help="run directory (default: runs/<config name>/<timestamp>-seed<seed>)")
    parser.add_argument("--resume", metavar="DIR", help="continue the run in DIR from its newest checkpoint")
    args = parser.parse_args(argv)
    if args.resume and (args.config or args.set or args.run_dir):
        parser.error("--resume DIR takes the config saved in DIR; it cannot be combined with --config/--set/--run-dir")
    if not args.resume and not args.config:
        parser.error("give --config FILE (or --resume DIR)")
    try:
        if args.resume:
            trainer = Trainer.resume(args.resume)
        else:
            config = load_config(args.config, args.set)
            run_dir = Path(args.run_dir) if args.run_dir else default_run_dir(args.config, config.run.seed)
            if (run_dir / "config.yaml").exists():
                parser.error(f"{run_dir} already holds a run; use --resume {run_dir} or another --run-dir")
            trainer = Trainer(config, run_dir)
    except (ConfigError, FileNotFoundError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    notice = rounding_notice(trainer.config)
    if notice and not args.resume:
        print(f"note: {notice}", flush=True)
    print(f"run directory: {trainer.run_dir}", flush=True)
    try:
        history = trainer.train()
    except TrainingDiverged as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    if history:
        last = history[-1]
        summary = {k: v for k, v in last.items() if k.startswith(("charts/episodic", "env/"))}
        print("last update: " + ", ".join(f"{k}={v:.4g}" for k, v in summary.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
