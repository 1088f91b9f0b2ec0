"""Typed settings: what a block of the config is made of, shared by the config's schema (:mod:`agents.config`) and
any settings dataclass that a part of the agent brings along.

A block is a dataclass whose fields are :func:`param` (a default, its documentation, numeric bounds) and which
derives from :class:`Settings`. The loader (:mod:`agents.config.building`) builds every block from YAML strictly
(unknown keys, wrong types and values out of bounds are a :class:`ConfigError`), then calls the block's
:meth:`Settings.check` with the block's dotted key: what a type annotation cannot express (a choice among names, one
field bounded by another) is checked there, by the block itself. No import of this project: every room may use it.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping
from dataclasses import field
from typing import Any


class ConfigError(ValueError):
    """A config key or value is invalid; the message names the key and what would have been valid."""


def param(default: Any, doc: str, low: float | None = None, high: float | None = None, expect: str = "") -> Any:
    """A config field with its documentation, (inclusive) numeric bounds and, for unions, what it expects."""
    factory = (lambda: default.copy()) if isinstance(default, dict | list) else None
    meta = {"doc": doc, "low": low, "high": high, "expect": expect}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    if dataclasses.is_dataclass(default):
        return field(default_factory=lambda: dataclasses.replace(default), metadata=meta)
    return field(default=default, metadata=meta)


class Settings:
    """Base of a settings block (a dataclass of :func:`param` fields): the loader calls :meth:`check` on every block
    it builds, after the block's own sub-blocks."""

    def check(self, prefix: str) -> None:
        """Checks of this block that its field types cannot express; ``prefix`` is its dotted key (``model.lru``),
        to name a bad value in the :class:`ConfigError`. Nothing by default."""


def check_choice(key: str, value: str, choices: tuple[str, ...]) -> None:
    """A :class:`ConfigError` naming ``key``, a close match and the valid choices when ``value`` is not one of them."""
    if value not in choices:
        close = difflib.get_close_matches(str(value), choices, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(f"{key}={value!r} is invalid{hint}; valid choices: {', '.join(choices)}")


def deep_copy(raw: Any) -> Any:
    """A copy of a raw settings tree as YAML gives it: its mappings (as dicts) and lists copied, other values kept."""
    if isinstance(raw, Mapping):
        return {k: deep_copy(v) for k, v in raw.items()}
    if isinstance(raw, list):
        return [deep_copy(v) for v in raw]
    return raw
