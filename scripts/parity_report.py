"""Replay all reference traces and report the share of identical steps per id.

Usage: python scripts/parity_report.py [--out results/parity.json]

Command line of ``scripts.reference.parity`` (replays through ``gymnasium.make`` and in one batched core).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from agents.io import write_json_atomic  # noqa: E402
from scripts.reference import REFERENCE_IDS  # noqa: E402
from scripts.reference.parity import replay, replay_batched  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "parity.json")
    args = parser.parse_args()
    report = {}
    for env_id in REFERENCE_IDS:
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
    write_json_atomic(args.out, report)


if __name__ == "__main__":
    main()
