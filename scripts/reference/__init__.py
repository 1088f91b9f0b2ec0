"""Tooling around the reference package memory-gym==1.0.2: record its traces, time it, compare our envs with it.

Two sides, one package:

* run inside the reference's isolated venv (gymnasium 0.29, memory_gym; our ``envs`` cannot be imported there):
  ``recorder`` (records and verifies the traces), ``bench`` (the reference's steps/s), and what they use,
  ``trace_format`` (digests, JSON files), ``protocol`` (the single-env timing protocol) and this module. These import
  only the standard library, numpy, gymnasium, memory_gym, this package and ``agents.runtime.io``;
* run with the project's python: ``venv`` (builds the reference venv and starts the two modules above in it) and
  ``parity`` (replays the traces through our ``envs``). Nothing here imports them, so the reference venv never
  reaches ``envs``.

The ids and the data paths below are the only definitions of them; ``tests/reference`` checks that the ids are
those of ``envs.ENV_IDS`` without the project's own ones.
"""

from __future__ import annotations

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]

# Every id of memory-gym 1.0.2, in the order of ``envs.ENV_IDS``: the ids with recorded traces and the ids that the
# environment benchmark measures beside the reference.
REFERENCE_IDS: tuple[str, ...] = (
    "MortarMayhem-v0",
    "MortarMayhem-Grid-v0",
    "MortarMayhemB-v0",
    "MortarMayhemB-Grid-v0",
    "Endless-MortarMayhem-v0",
    "MysteryPath-v0",
    "MysteryPath-Grid-v0",
    "SearingSpotlights-v0",
    "Endless-MysteryPath-v0",
    "Endless-SearingSpotlights-v0",
)
# Ids of ours that memory-gym does not have (no trace, no reference to measure).
PROJECT_ONLY_IDS: tuple[str, ...] = ("ProofOfMemory-v0",)

# The recorded reference data: test fixtures, also read by the parity report (format: tests/data/README.md).
DATA_DIR = REPO_ROOT / "tests" / "data"
TRACES_DIR = DATA_DIR / "traces"  # <env_id>.json.gz
MP_PATHS_FILE = DATA_DIR / "mp_paths.json.gz"
