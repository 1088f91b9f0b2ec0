"""Score trained runs on novel seeds, the paper's way (30 seeds x 5 repetitions, actions sampled); the same
command as ``python scripts/evaluate.py``.

    memgym-evaluate --run DIR [DIR ...] [--seeds LOW..HIGH | LOW:HIGH] [--repetitions 5]
        [--checkpoints last|all|STEP,...] [--greedy] [--out DIR] [--force] [--method NAME] [--task NAME]
        [--video DIR]

Every run is rebuilt from its own saved config and checkpoint(s) (memory module, frame stack, HELM branch), and
all seed x repetition episodes of a checkpoint play at once in one batched environment. The records are merged into
``OUT/episodes.csv`` (one row per episode: rows of other runs and checkpoints already there are kept; rows of the
same run, step, seed and repetition are replaced only with ``--force``), the runs' training logs into
``OUT/training.csv`` (the training-seed curves of ``scripts/plot.py``), and ``OUT/summary.json`` is recomputed over
all of them (per run and checkpoint: mean, IQM and the paper's metric; IQM with 95% stratified-bootstrap intervals
across runs per method and task); every file is written atomically. A run is named after its directory (``seed1``),
or by the shortest path suffix that sets it apart from another run of the same method and task (``a/seed1``).
The default seeds are the run's ``eval`` seeds (30 right after ``env.train_seeds`` unless the config names others);
the resolved inclusive range is printed, and seeds that overlap the training range are refused. ``--video DIR``
writes GIFs of the first episodes: the agent's view beside the ground truth, with the step, action, reward and
running return.

Several evaluations may write into one --out directory at once: each merges into what is there when it ends (under a
lock on OUT/.lock), so the directory ends with every record. summary.json records the size and SHA-256 of the files
beside it; a truncated or corrupted episodes.csv or training.csv is refused by name. SIGTERM (or SIGUSR2) stops an
evaluation with exit status 76, never in the middle of writing its files. Exit status: 0 done, 2 bad input, 76
pre-empted.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from agents.analysis.scores import format_table
from agents.config import ConfigError
from agents.evaluation.records import parse_seed_range
from agents.evaluation.runs import evaluate_runs
from agents.runtime.devices import check_device
from agents.runtime.preemption import EXIT_PREEMPTED, Preempted, raising_preempted

SEED_LIMIT = 2**63 - 1  # torch's generator takes seeds up to here


def whole_number(low: int, high: int | None = None) -> Callable[[str], int]:
    """An argparse type: a whole number in [low, high], else a message with the valid range (exit status 2)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low or high is not None and value > high:
            bound = f">= {low}" if high is None else f"in [{low}, {high}]"
            raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected a whole number {bound}")
        return value

    return parse


def seed_range(text: str) -> str:
    """An argparse type for --seeds: checked here, resolved per run by evaluate_runs."""
    try:
        parse_seed_range(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err).replace("--seeds ", "", 1)) from None
    return text


def device(text: str) -> str:
    try:
        check_device(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", nargs="+", required=True, metavar="DIR", help="run directories")
    parser.add_argument(
        "--seeds",
        type=seed_range,
        metavar="RANGE",
        help="novel seeds: LOW..HIGH, both ends included (100000..100029 is 30 seeds, as eval.seeds: [100000, "
        "100029] in a config), or LOW:HIGH with HIGH excluded (100000:100030, the same 30 seeds); "
        "default: the run's eval seeds",
    )
    parser.add_argument(
        "--repetitions", type=whole_number(1), help="episodes per seed, >= 1 (default: the run's eval.repetitions)"
    )
    parser.add_argument("--checkpoints", default="last", help="last, all, or environment steps STEP,STEP,...")
    parser.add_argument("--greedy", action="store_true", help="argmax actions instead of sampling")
    parser.add_argument(
        "--sampling-seed",
        type=whole_number(0, SEED_LIMIT),
        default=None,
        help="seed of the action sampling, >= 0 (default: the run's eval.seed)",
    )
    parser.add_argument("--out", help="results directory (default: DIR/evaluation for a single run)")
    parser.add_argument(
        "--force", action="store_true", help="replace records of the same run, step, seed and repetition in --out"
    )
    parser.add_argument("--method", help="method name in the records (default: from each run's config)")
    parser.add_argument("--task", help="task name in the records (default: from each run's config)")
    parser.add_argument("--video", metavar="DIR", help="write GIFs of a few episodes per checkpoint into DIR")
    parser.add_argument(
        "--videos", type=whole_number(1), default=3, help="episodes per checkpoint in --video, >= 1 (default 3)"
    )
    parser.add_argument("--device", type=device, default="cpu", help="cpu, cuda or cuda:N (default: cpu)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.out is None and len(args.run) > 1:
        parser.error("give --out DIR when evaluating several runs")
    out = Path(args.out) if args.out else Path(args.run[0]) / "evaluation"
    try:
        with raising_preempted("evaluation"):
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
                force=args.force,
                echo=print,
            )
    except (ConfigError, FileNotFoundError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except Preempted as err:
        print(f"pre-empted: {err}; {out} holds what was written before, whole; run it again", file=sys.stderr)
        return EXIT_PREEMPTED
    print(format_table(summary["runs"], ["run", "method", "task", "step", "episodes", "mean", "iqm", "metric"]))
    print(format_table(summary["aggregate"]))
    written = [out / name for name in ("episodes.csv", "training.csv", "summary.json") if (out / name).is_file()]
    print("wrote " + ", ".join(map(str, written)))
    return 0
