"""Plot evaluation results: ``memgym-plot RESULTS_DIR [RESULTS_DIR ...] --out DIR`` (the same command as
``python scripts/plot.py``).

Reads every directory's ``episodes.csv`` (and ``training.csv`` where present) and writes, as PNG and PDF, the
sample-efficiency curves (``curves``: training-seed return beside the novel-seed metric, one row per task) and the
final performance (``final``: each run's last checkpoint), both as the IQM across runs with a 95% stratified-bootstrap
interval, and for several tasks the aggregate across them (``across_tasks``: final scores normalised per task; IQM,
mean, optimality gap, probability of improvement over GRU-PPO, performance profiles); prints the final-performance
table. A metric with a known range (success, commands executed: [0, 1]) is
shown on that whole range, with a dashed line at the task's chance level where it is known; ``--zoom`` fits the axes
to the data instead.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from agents.analysis import plots, results, scores
from agents.analysis.across_tasks_figure import plot_across_tasks


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", nargs="+", metavar="RESULTS_DIR", help="directories holding episodes.csv")
    parser.add_argument("--out", required=True, help="directory for the figures")
    parser.add_argument("--column", default="metric", help="episodes.csv column to score (default: metric)")
    parser.add_argument("--training-column", default="return", help="training.csv column (default: return)")
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap replicates (default: 2000)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default: 0)")
    parser.add_argument(
        "--zoom", action="store_true", help="fit the metric's axis to the data instead of its whole range (e.g. [0, 1])"
    )
    args = parser.parse_args(argv)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", results.ResultsWarning)
        try:
            written = plots.plot_results(
                args.results,
                args.out,
                column=args.column,
                training_column=args.training_column,
                reps=args.reps,
                seed=args.seed,
                zoom=args.zoom,
            )
            written += plot_across_tasks(args.results, args.out, args.column, reps=args.reps, seed=args.seed)
            final = scores.aggregate(
                results.read_episodes(*args.results), args.column, steps="last", reps=args.reps, seed=args.seed
            )
        except (FileNotFoundError, NotADirectoryError, KeyError, ValueError) as err:
            message = err.args[0] if isinstance(err, KeyError) and err.args else err
            print(f"error: {message}", file=sys.stderr)
            return 2
    for warning in {str(w.message): w for w in caught if issubclass(w.category, results.ResultsWarning)}:
        print(f"warning: {warning}", file=sys.stderr)
    print(scores.format_table(final, ("method", "task", "step", "iqm", "low", "high", "runs", "episodes")))
    for path in written:
        print(f"wrote {path}")
    return 0
