"""Reset options: declared once per family, validated on every reset, applied to the episodes that reset starts
(one episode on the single face; the vector face keeps them for its slots' autoresets).

Each family lists its options as :class:`Option` specs (the reference's names and defaults). Unknown keys and values
of the wrong type or outside the valid range raise ``ValueError`` naming the key and what would have been valid.
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

KINDS = ("int", "float", "bool", "int_list", "float_list")
# Where the range of an int option is open (steps, counts, healths), it ends here: the cores add such values to step
# counters in int64 arrays, and larger ones overflowed (OverflowError) or asked for absurd allocations.
INT_LIMIT = 2**31 - 1


@dataclass(frozen=True)
class Option:
    """One reset option: its default, its kind and its valid range (bounds inclusive, ``None`` = unbounded)."""

    default: Any
    kind: str
    low: float | None = None
    high: float | None = None
    allow_empty: bool = False
    doc: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"Option kind {self.kind!r} is not one of {KINDS}")
        if self.kind in ("int", "int_list"):  # an open int range ends at +-INT_LIMIT (see there)
            object.__setattr__(self, "low", -INT_LIMIT if self.low is None else self.low)
            object.__setattr__(self, "high", INT_LIMIT if self.high is None else self.high)

    def describe(self) -> str:
        """A short description of the valid values, used in error messages."""
        bounds = ""
        if self.low is not None or self.high is not None:
            lo = "-inf" if self.low is None else _number_text(self.low)
            hi = "inf" if self.high is None else _number_text(self.high)
            bounds = f" in [{lo}, {hi}]"
        return {
            "int": f"an int{bounds}",
            "float": f"a finite number{bounds}",
            "bool": "a bool",
            "int_list": f"a {'' if self.allow_empty else 'non-empty '}list of ints{bounds}",
            "float_list": f"a {'' if self.allow_empty else 'non-empty '}list of finite numbers{bounds}",
        }[self.kind]

    def _in_range(self, v: float) -> bool:
        return (self.low is None or v >= self.low) and (self.high is None or v <= self.high)

    def validate(self, key: str, value: Any) -> Any:
        """Return the value in canonical form (python int/float/bool/list) or raise ``ValueError``."""
        bad = ValueError(f"option {key!r}={value!r} is invalid: expected {self.describe()}")
        if self.kind == "bool":
            if isinstance(value, bool | _np_bool()):
                return bool(value)
            raise bad
        if self.kind in ("int", "float"):
            return self._scalar(value, self.kind, bad)
        if not isinstance(value, list | tuple) or (not value and not self.allow_empty):
            raise bad
        scalar_kind = "int" if self.kind == "int_list" else "float"
        return [self._scalar(v, scalar_kind, bad) for v in value]

    def _scalar(self, value: Any, kind: str, bad: ValueError) -> int | float:
        if isinstance(value, bool | _np_bool()) or not isinstance(value, numbers.Real):
            raise bad
        if kind == "int":
            if not isinstance(value, numbers.Integral):
                raise bad
            value = int(value)
        else:
            value = float(value) if not isinstance(value, numbers.Integral) else value
            try:
                finite = math.isfinite(value)  # NaN passes no range test, and no option means an infinite value
            except OverflowError:  # an int too large for a float
                finite = False
            if not finite:
                raise bad
        if not self._in_range(value):
            raise bad
        return value


def _number_text(value: float) -> str:
    """A bound as messages show it: 6, 0.04, 2147483647, 1e+09."""
    return str(int(value)) if float(value).is_integer() and abs(value) <= INT_LIMIT else f"{value:g}"


def _np_bool() -> type:
    import numpy as np

    return np.bool_


def resolve_options(
    specs: Mapping[str, Option],
    options: Mapping[str, Any] | None,
    base: Mapping[str, Any] | None = None,
    name: str = "",
) -> dict[str, Any]:
    """Merge ``options`` over ``base`` (or the spec defaults) after validating every key and value."""
    check_mapping(options, specs, name)
    merged = (
        {k: _copy(spec.default) for k, spec in specs.items()}
        if base is None
        else {k: _copy(v) for k, v in base.items()}
    )
    for key, value in (options or {}).items():
        if key not in specs:
            close = difflib.get_close_matches(str(key), list(specs), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            where = f" for {name}" if name else ""
            raise ValueError(f"unknown option {key!r}{where}{hint}; valid options: {', '.join(sorted(specs))}")
        merged[key] = specs[key].validate(key, value)
    return merged


def check_mapping(options: Any, specs: Mapping[str, Any], name: str = "", extra: tuple[str, ...] = ()) -> None:
    """``ValueError`` unless ``options`` is ``None`` or a mapping (``reset(options=[1, 2])`` would otherwise fail
    later with an AttributeError that names neither the argument nor what it should be)."""
    if options is None or isinstance(options, Mapping):
        return
    where = f" for {name}" if name else ""
    valid = ", ".join([*sorted(specs), *extra]) or "none"
    raise ValueError(
        f"options={options!r} is invalid{where}: expected None or a mapping (a dict) of option names to values; "
        f"valid options: {valid}"
    )


def _copy(value: Any) -> Any:
    return list(value) if isinstance(value, list) else value
