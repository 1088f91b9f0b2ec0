"""Check that a committed run regenerates: ``python scripts/check_run.py CONFIG --root ROOT --only SELECTION``.

Re-trains one run of a grid config (the one ``--only`` selects, with the sweep's syntax, e.g.
``method=ppo,task=endless_mp,seed=0``) from scratch in a temporary root, with the committed run's thread count, and
evaluates its last checkpoint as the sweep does; then compares its records with the committed run's under ``--root``
byte for byte: ``training.csv``, ``eval/episodes.csv`` (the in-training evaluations) and ``evaluation/episodes.csv``
(the final one), and its resolved config with the committed ``config.yaml`` (parsed: keys added to the config
since, at their defaults, and the settings no record depends on are no difference). For example, the regression
check of the CPU suite (``results/cpu/suite/README.md``)::

    python scripts/check_run.py configs/cpu/suite.yaml --root results/cpu --only method=ppo,task=endless_mp,seed=0

The same code on the same machine gives the same bytes; another machine or PyTorch build may round differently (the
first differing line is printed). ``--keep`` leaves the temporary root. Exit status: 0 the same, 1 a difference, 2 bad
arguments, a run that is not committed whole, or a failed sweep.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import yaml

from agents.analysis.compare import first_difference
from agents.cli.sweep import main as sweep
from agents.config import ConfigError
from agents.experiments.planning import SweepError, load_panel, select_runs
from agents.experiments.state import config_differences
from agents.policy.checkpoint import run_config

RECORDS = ("training.csv", "eval/episodes.csv", "evaluation/episodes.csv")  # compared byte for byte


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("config", type=Path, help="the grid config of the committed run")
    parser.add_argument("--root", type=Path, required=True, help="where the committed run lies (the sweep's --root)")
    parser.add_argument("--only", required=True, metavar="KEY=VALUE[,KEY=VALUE...]", help="selects exactly one run")
    parser.add_argument("--scratch", type=Path, help="where to re-train (default: a temporary directory)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary directory")
    args = parser.parse_args(argv)
    try:
        (panel,) = select_runs([load_panel(args.config, root=args.root)], [args.only])
    except (ConfigError, SweepError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if len(panel.runs) != 1:
        names = ", ".join(run.name for run in panel.runs)
        print(f"error: --only {args.only} selects {len(panel.runs)} runs ({names}): select one", file=sys.stderr)
        return 2
    committed = panel.runs[0].run_dir
    missing = [name for name in ("config.yaml", *RECORDS) if not (committed / name).is_file()]
    if missing:
        print(f"error: {committed} is not a finished, committed run: {', '.join(missing)} missing", file=sys.stderr)
        return 2
    saved = yaml.safe_load((committed / "config.yaml").read_text())
    scratch = args.scratch or Path(tempfile.mkdtemp(prefix="check-run-"))
    try:
        command = [str(args.config), "--root", str(scratch), "--jobs", "1", "--only", args.only, "--evaluate"]
        code = sweep([*command, "--set", f"run.torch_threads={saved['run']['torch_threads']}"])
        if code != 0:
            print(f"error: the sweep failed (exit status {code})", file=sys.stderr)
            return 2
        fresh = scratch / committed.relative_to(args.root)
        found = _differences(fresh, committed)
        for line in found:
            print(line)
        print(f"{fresh} {'differs from' if found else 'is the same as'} {committed}")
        return 1 if found else 0
    finally:
        if args.scratch is None and not args.keep:
            shutil.rmtree(scratch, ignore_errors=True)
        elif args.scratch is None:
            print(f"the re-trained run is kept in {scratch}")


def _differences(fresh: Path, committed: Path) -> list[str]:
    """What differs between the re-trained run and the committed one, one entry per file."""
    found = []
    # Parsed, so that keys added since the run (at their defaults) and settings no record depends on (W&B, progress
    # bar, checkpoint counts) are no difference
    differences = config_differences(run_config(committed), run_config(fresh))
    if differences:
        found.append(f"config.yaml: the resolved configs differ: {'; '.join(differences)}")
    for name in RECORDS:
        new, old = (fresh / name).read_bytes(), (committed / name).read_bytes()
        if new != old:
            found.append(f"{name}: {first_difference(new, old)}")
    return found
