"""Fuzz every environment at length (the ``long`` Hypothesis profile) and write the figures.

    python scripts/fuzz_envs.py --out results/reliability.json        # the committed figures (about 10 minutes)
    python scripts/fuzz_envs.py --ids MortarMayhem-v0 --max-examples 5 # a quick look, into runs/reliability.json

The properties and strategies are those of the CI tests (envs/fuzzing.py, run by tests/envs/test_fuzz.py
under the bounded ``ci`` profile): faces agree slot for slot, a reset after any history plays the fresh episode,
invalid input is refused by name. The record holds, per id, the cases tried per property, the failures (falsifying
examples) and the seconds, with the git revision, the versions, the profile, the command and the bugs the fuzzing
found and that were fixed. It goes to ``runs/reliability.json`` unless ``--out`` names another file (written
atomically; other top-level sections of an existing file are kept); a partial run (some ids or properties, or
another profile) never replaces a full record.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

from agents.runtime.io import SCRATCH, ResultFile, add_out_argument

ROOT = Path(__file__).resolve().parents[1]

DEFAULT_OUT = SCRATCH / "reliability.json"
SECTION = "fuzzed_environments"
PACKAGES = ("numpy", "gymnasium", "pygame", "hypothesis")


def partial_reasons(record: dict) -> str:
    """Why a reliability record's fuzz section is not a full run (empty when it is one)."""
    from envs.fuzzing import ALL_IDS, PROPERTIES

    section = record.get(SECTION, record)
    reasons = []
    if set(section.get("per_id", {})) != set(ALL_IDS):
        reasons.append(f"{len(section.get('per_id', {}))} of {len(ALL_IDS)} ids")
    if set(section.get("properties", [])) != set(PROPERTIES):
        reasons.append("some properties")
    if section.get("profile") != "long":
        reasons.append(f"profile {section.get('profile')!r}")
    return ", ".join(reasons)


def holds_full(path: Path) -> bool:
    try:
        record = json.loads(Path(path).read_text())
        return isinstance(record, dict) and SECTION in record and not partial_reasons(record)
    except (OSError, ValueError, TypeError, AttributeError):
        return False


def git_revision() -> str:
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()

    dirty = git("status", "--porcelain", "--untracked-files=no", "--", "envs", "tests/envs", "tests/support")
    return git("rev-parse", "HEAD") + ("+dirty" if dirty else "")


def main(argv: list[str] | None = None) -> dict:
    os.environ.setdefault("HYPOTHESIS_PROFILE", "long")
    from hypothesis import settings

    from envs import fuzzing as env_fuzz

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ids", nargs="+", default=env_fuzz.ALL_IDS, choices=env_fuzz.ALL_IDS, metavar="ID")
    parser.add_argument("--properties", nargs="+", default=list(env_fuzz.PROPERTIES), choices=list(env_fuzz.PROPERTIES))
    parser.add_argument("--max-examples", type=int, help="cases per property and id (default: the profile's)")
    add_out_argument(parser, DEFAULT_OUT, "the reliability record")
    args = parser.parse_args(argv)
    profile = env_fuzz.PROFILE
    loaded = settings.get_profile(profile)
    if args.max_examples is not None:
        settings.register_profile(profile, loaded, max_examples=args.max_examples)
        settings.load_profile(profile)
    partial = {"per_id": dict.fromkeys(args.ids), "properties": args.properties, "profile": profile}
    target = ResultFile.for_command(parser, args.out, DEFAULT_OUT, holds_full, partial_reasons(partial))
    start = time.perf_counter()
    try:
        per_id = env_fuzz.fuzz(args.ids, args.properties)
        max_examples = settings.default.max_examples
    finally:  # a caller in the same process (a test) keeps its profile
        settings.register_profile(profile, loaded)
        settings.load_profile(profile)
    section = {
        "command": " ".join(["python", "scripts/fuzz_envs.py", *(sys.argv[1:] if argv is None else argv)]),
        "git_revision": git_revision(),
        "versions": {"python": platform.python_version(), **{p: metadata.version(p) for p in PACKAGES}},
        "profile": profile,
        "max_examples": max_examples,
        "scale": vars(env_fuzz.SCALE),
        "properties": args.properties,
        "seconds": round(time.perf_counter() - start, 1),
        "cases_total": sum(sum(entry["cases"].values()) for entry in per_id.values()),
        "failures_total": sum(len(entry["failures"]) for entry in per_id.values()),
        "per_id": per_id,
        "found_and_fixed": env_fuzz.FOUND_AND_FIXED,
        "harness_fixes": env_fuzz.HARNESS_FIXES,
    }
    record = {}
    if target.path.exists():  # keep the other sections of the record (the other reliability figures)
        try:
            record = json.loads(target.path.read_text())
        except ValueError:
            record = {}
    record[SECTION] = section
    target.save_json(record, partial_reasons(record))
    print(f"{section['cases_total']} cases, {section['failures_total']} failures -> {target.path}")
    return record


if __name__ == "__main__":
    main()
