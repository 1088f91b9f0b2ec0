"""Replay all reference traces and report the share of identical steps per id.

    python scripts/parity_report.py --out results/parity.json        # the committed report
    python scripts/parity_report.py --ids MortarMayhem-v0            # one id, into runs/parity.json

Command line of ``scripts.reference.parity`` (replays through ``gymnasium.make`` and in one batched core). The report
goes to ``runs/parity.json`` (git-ignored) unless ``--out`` names another file; the committed report is replaced only
where ``--out`` names it, and a report of some of the ids never replaces one of all of them.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable
from pathlib import Path

from agents.runtime.io import SCRATCH, ResultFile, add_out_argument, json_table
from scripts.reference import REFERENCE_IDS
from scripts.reference.parity import replay, replay_batched

ROOT = Path(__file__).resolve().parents[1]

DEFAULT_OUT = SCRATCH / "parity.json"


def partial_reasons(ids: Iterable[str]) -> str:
    """Why a report is not a full one (every id), empty when it is one."""
    replayed = set(ids) & set(REFERENCE_IDS)
    return "" if len(replayed) == len(REFERENCE_IDS) else f"{len(replayed)} of {len(REFERENCE_IDS)} ids"


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--ids", nargs="+", default=REFERENCE_IDS, choices=REFERENCE_IDS, metavar="ID", help="default: every id"
    )
    add_out_argument(parser, DEFAULT_OUT, "the report")
    args = parser.parse_args(argv)
    target = ResultFile.for_command(
        parser, args.out, DEFAULT_OUT, json_table(partial_reasons), partial_reasons(args.ids)
    )
    report = {}
    for env_id in args.ids:
        report[env_id] = {}
        for face, result in (("single", replay(env_id)), ("batched", replay_batched(env_id))):
            report[env_id][face] = {
                "episodes": result.episodes,
                "steps": result.steps,
                "identical": result.identical,
                "percent": round(result.percent, 3),
            }
            print(
                f"{env_id:30s} {face:8s} {result.episodes:3d} episodes {result.steps:6d} steps "
                f"{result.percent:8.3f}% identical"
            )
            for line in result.mismatches[:3]:
                print("    ", line[:300])
    target.save_json(report, partial_reasons(report))
    return report


if __name__ == "__main__":
    main()
