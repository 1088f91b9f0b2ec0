"""Replay all reference traces and report the share of identical steps per id.

Usage: python scripts/parity_report.py [--out results/parity.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from envs import ENV_IDS  # noqa: E402
from tests.parity import REFERENCE_IDS, replay  # noqa: E402


def write_json_atomic(path: Path, data: object) -> None:
    """Write JSON next to its final place, then rename, so no half-written file is ever left behind."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile("w", dir=path.parent, suffix=".tmp", delete=False) as f:
        json.dump(data, f, indent=2, sort_keys=True)
        f.write("\n")
    os.replace(f.name, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "parity.json")
    args = parser.parse_args()
    report = {}
    for env_id in REFERENCE_IDS:
        if env_id not in ENV_IDS:
            print(f"{env_id:32s} not implemented")
            continue
        result = replay(env_id)
        report[env_id] = {
            "episodes": result.episodes,
            "steps": result.steps,
            "identical": result.identical,
            "percent": round(result.percent, 3),
        }
        print(f"{env_id:32s} {result.episodes:4d} episodes {result.steps:7d} steps {result.percent:8.3f}% identical")
        for line in result.mismatches[:3]:
            print("    ", line[:300])
    write_json_atomic(args.out, report)


if __name__ == "__main__":
    main()
