"""Score trained runs on novel seeds, the paper's way (30 seeds x 5 repetitions, actions sampled).

    python scripts/evaluate.py --run DIR [DIR ...] [--seeds 100000:100030] [--repetitions 5]
        [--checkpoints last|all|STEP,...] [--greedy] [--out DIR] [--method NAME] [--task NAME] [--video DIR]

Every run is rebuilt from its own saved config and checkpoint(s) (memory module, frame stack, HELM branch), and
all seed x repetition episodes of a checkpoint play at once in one batched environment. Writes
``OUT/episodes.csv`` (one record per episode) and ``OUT/summary.json`` (per run and checkpoint: mean, IQM and the
paper's metric; IQM with 95% stratified-bootstrap intervals across runs per method and task), both atomically.
The default seeds are the run's ``eval`` seeds (30 right after ``env.train_seeds`` unless the config names others);
seeds that overlap the training range are refused. ``--video DIR`` writes GIFs of the first episodes: the agent's
view beside the ground truth.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout without installing

from agents.config import ConfigError  # noqa: E402
from agents.evaluation import evaluate_runs  # noqa: E402
from agents.results import format_table  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", nargs="+", required=True, metavar="DIR", help="run directories")
    parser.add_argument("--seeds", help="novel seeds LOW:HIGH (end excluded), e.g. 100000:100030")
    parser.add_argument("--repetitions", type=int, help="episodes per seed (default: the run's eval.repetitions)")
    parser.add_argument("--checkpoints", default="last", help="last, all, or environment steps STEP,STEP,...")
    parser.add_argument("--greedy", action="store_true", help="argmax actions instead of sampling")
    parser.add_argument("--sampling-seed", type=int, default=None, help="seed of the action sampling")
    parser.add_argument("--out", help="results directory (default: DIR/evaluation for a single run)")
    parser.add_argument("--method", help="method name in the records (default: from each run's config)")
    parser.add_argument("--task", help="task name in the records (default: from each run's config)")
    parser.add_argument("--video", metavar="DIR", help="write GIFs of a few episodes per checkpoint into DIR")
    parser.add_argument("--videos", type=int, default=3, help="episodes per checkpoint in --video (default 3)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.out is None and len(args.run) > 1:
        parser.error("give --out DIR when evaluating several runs")
    out = Path(args.out) if args.out else Path(args.run[0]) / "evaluation"
    try:
        summary = evaluate_runs(
            [Path(run) for run in args.run],
            out,
            seeds=args.seeds,
            repetitions=args.repetitions,
            checkpoints=args.checkpoints,
            greedy=args.greedy,
            sampling_seed=args.sampling_seed,
            method=args.method,
            task=args.task,
            video=Path(args.video) if args.video else None,
            videos=args.videos,
            device=args.device,
            progress=not args.no_progress,
        )
    except (ConfigError, FileNotFoundError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(format_table(summary["runs"], ["run", "method", "task", "step", "episodes", "mean", "iqm", "metric"]))
    print(format_table(summary["aggregate"]))
    print(f"wrote {out / 'episodes.csv'} and {out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
