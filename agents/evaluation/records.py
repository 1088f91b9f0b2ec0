"""Evaluation records: one row per episode, as CSV (:data:`RECORD_COLUMNS` first, then the environment's own
metrics in sorted order), read back with their numbers parsed; seed ranges as the command line and the config write
them.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.analysis.results import EPISODE_COLUMNS
from agents.runtime.io import atomic_write_text

RECORD_COLUMNS = list(EPISODE_COLUMNS)  # the first columns of episodes.csv, in this order


def seed_list(seeds: Sequence[int]) -> list[int]:
    """An inclusive [low, high] range as the list of its seeds."""
    low, high = seeds
    return list(range(int(low), int(high) + 1))


def record_means(records: Iterable[dict[str, Any]]) -> dict[str, float]:
    """Mean of every numeric column of some records (return, length, metric, the environment's metrics)."""
    records = list(records)
    skip = {"step", "seed", "repetition"}
    keys = sorted({k for r in records for k, v in r.items() if is_record_number(v)} - skip)
    return {key: float(np.mean([float(r[key]) for r in records if is_record_number(r.get(key))])) for key in keys}


def write_records(path: str | Path, records: Sequence[dict[str, Any]]) -> None:
    """Write records as CSV atomically (:func:`records_csv_text`)."""
    atomic_write_text(path, records_csv_text(records))


def records_csv_text(records: Sequence[dict[str, Any]]) -> str:
    """Records as CSV: :data:`RECORD_COLUMNS` first, then every other key in sorted order."""
    extra = sorted({key for record in records for key in record} - set(RECORD_COLUMNS))
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=RECORD_COLUMNS + extra, lineterminator="\n")
    writer.writeheader()
    writer.writerows(records)
    return text.getvalue()


def read_records(path: str | Path, skip_malformed: bool = False) -> list[dict[str, Any]]:
    """Records written by :func:`write_records`, numbers parsed (empty cells dropped). ``skip_malformed`` leaves out
    rows with too few or too many cells (a line cut short) instead of returning them with holes."""
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    if skip_malformed:
        rows = [row for row in rows if None not in row and None not in row.values()]
    return [{k: _parse(v) for k, v in row.items() if v != ""} for row in rows]


def _parse(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            continue
    return text


def record_number(value: Any) -> Any:
    """Booleans as 0/1 (the environments report some flags as bools, others as ints)."""
    return int(value) if isinstance(value, bool | np.bool_) else value


def is_record_number(value: Any) -> bool:
    return (
        isinstance(value, int | float | np.integer | np.floating)
        and not isinstance(value, bool)
        and (not isinstance(value, float) or math.isfinite(value))
    )


def parse_seed_range(text: str) -> list[int]:
    """``LOW..HIGH`` (both ends included, like the config's ``eval.seeds``) or ``LOW:HIGH`` (HIGH excluded, as a
    Python range) -> the inclusive [low, high] of those seeds."""
    inclusive = ".." in text
    low, sep, high = text.partition(".." if inclusive else ":")
    try:
        first, last = int(low), int(high) - (0 if inclusive else 1)
    except ValueError:
        first, last = -1, -2
    if not sep or first < 0 or last < first:
        raise ValueError(
            f"--seeds {text!r} is invalid: expected LOW..HIGH (both ends included, 0 <= LOW <= HIGH, e.g. "
            "100000..100029) or LOW:HIGH (HIGH excluded, 0 <= LOW < HIGH, e.g. 100000:100030)"
        )
    return [first, last]


def describe_seeds(seed_range: Sequence[int]) -> str:
    """An inclusive [low, high] as the command line prints it: ``novel seeds 100000..100029 (30 seeds)``."""
    low, high = int(seed_range[0]), int(seed_range[1])
    count = high - low + 1
    return f"novel seeds {low}..{high} ({count} seed{'' if count == 1 else 's'})"
