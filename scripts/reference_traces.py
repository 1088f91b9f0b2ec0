"""Ground-truth traces from the reference package memory-gym==1.0.2, recorded in an isolated venv.

Command line of ``scripts.reference.venv``: builds the reference venv when it is missing, then runs
``scripts.reference.recorder`` (or ``scripts.reference.bench``) in it. Standard library only; the project's python.

    python scripts/reference_traces.py                     # build the venv if missing, record everything, verify
    python scripts/reference_traces.py --ids MysteryPath-v0 --no-mp-paths
    python scripts/reference_traces.py --verify-only       # replay the committed traces on the reference
    python scripts/reference_traces.py --bench             # reference steps/s per id
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from scripts.reference import MP_PATHS_FILE, REFERENCE_IDS, TRACES_DIR
from scripts.reference.venv import (
    ensure_reference_venv,
    record_mp_paths,
    record_traces,
    run_reference_bench,
    verify_traces,
)


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ids", nargs="+", default=REFERENCE_IDS, choices=REFERENCE_IDS)
    parser.add_argument("--out", type=Path, default=TRACES_DIR)
    parser.add_argument("--mp-paths", type=Path, default=MP_PATHS_FILE)
    parser.add_argument("--no-mp-paths", action="store_true", help="do not (re)record the Mystery Path layouts")
    parser.add_argument("--verify-only", action="store_true", help="only replay the traces in --out on the reference")
    parser.add_argument("--bench", action="store_true", help="only print the reference steps/s per id")
    args = parser.parse_args(argv)
    if args.bench:
        ensure_reference_venv()
        print(json.dumps(run_reference_bench(args.ids), indent=1))
        return
    if not args.verify_only:
        record_traces(args.ids, args.out)
        if not args.no_mp_paths:
            record_mp_paths(args.mp_paths)
    verify_traces(args.ids, args.out)


if __name__ == "__main__":
    main()
