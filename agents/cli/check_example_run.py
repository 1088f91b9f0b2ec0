"""Check that the committed example run regenerates: ``python scripts/check_example_run.py``.

Runs the command that produced ``results/examples/proof_of_memory/`` (README there)::

    python scripts/sweep.py configs/examples/proof_of_memory.yaml --root ROOT --jobs 2 --evaluate

into a temporary ``--root`` (a few minutes on two cores; ``--keep`` leaves it), then compares the panel's results
directory with the committed one: ``episodes.csv`` and ``training.csv`` byte for byte, ``summary.json`` in every
key but the provenance of its evaluation (time, command, versions, git revision, machine). ``--results DIR`` compares
a results directory made before instead of running the sweep. The same code on the same machine regenerates a run
byte for byte (``run.torch_threads: 1``); another machine or build of PyTorch may round differently, so the check also
takes ``--reference DIR``: the results of a regeneration made before a change, to show that the change moved nothing.

Exit status: 0 the same, 1 a difference (each printed), 2 bad arguments or a sweep that failed.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from agents.analysis.compare import differences
from agents.cli.sweep import main as sweep
from agents.config import ConfigError, grid_panel, read_config_file
from agents.runtime.io import ROOT

CONFIG = ROOT / "configs" / "examples" / "proof_of_memory.yaml"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", type=Path, default=CONFIG, help="the panel's grid config (default: the example)")
    parser.add_argument(
        "--reference", type=Path, help="the results to compare with (default: results/examples/<panel>)"
    )
    parser.add_argument("--results", type=Path, help="compare these results instead of running the sweep")
    parser.add_argument("--root", type=Path, help="where the sweep runs (default: a temporary directory)")
    parser.add_argument("--jobs", type=int, default=2, help="runs trained at once (default 2, as the example was)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary root")
    args = parser.parse_args(argv)
    try:
        panel = grid_panel(read_config_file(args.config).get("grid") or {}) or args.config.stem
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    reference = args.reference or ROOT / "results" / "examples" / panel
    if not (reference / "summary.json").is_file():
        print(f"error: {reference} holds no results (summary.json): give --reference DIR", file=sys.stderr)
        return 2
    if args.results is not None:
        return _report(args.results, reference)
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    root = args.root or Path(tempfile.mkdtemp(prefix="check-example-"))
    try:
        # the config by its absolute path: the summary's config is compared as a file, not as the text given
        code = sweep([str(args.config.resolve()), "--root", str(root), "--jobs", str(args.jobs), "--evaluate"])
        if code != 0:
            print(f"error: the sweep failed (exit status {code})", file=sys.stderr)
            return 2
        return _report(root / panel / "results", reference)
    finally:
        if args.root is None and not args.keep:
            shutil.rmtree(root, ignore_errors=True)
        elif args.root is None:
            print(f"the runs are kept in {root}")


def _report(results: Path, reference: Path) -> int:
    found = differences(results, reference)
    for line in found:
        print(line)
    print(f"{results} {'differs from' if found else 'is the same as'} {reference}")
    return 1 if found else 0
