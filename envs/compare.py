"""Comparing what environments return, as plain values: shared by the parity replays (scripts/reference/parity.py),
the fuzzing harness (:mod:`envs.fuzzing`) and the batching tests."""

from __future__ import annotations

import math
from typing import Any


def values_equal(a: Any, b: Any) -> bool:
    """Equality for JSON-like values: numbers compare with a 1e-9 tolerance and NaN equals NaN."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(values_equal(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(values_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, int | float) and isinstance(b, int | float):
        if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
            return True
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9)
    return a == b


def jsonable(value: Any) -> Any:
    """Numpy arrays and scalars as plain python lists and numbers (as the traces store them)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    return value
