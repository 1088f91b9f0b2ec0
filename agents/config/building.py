"""Strict building: a validated config block from nested dicts (what YAML gives), and back.

:func:`build` makes an instance of a block's dataclass: unknown keys fail with the closest valid name, a value of the
wrong type or outside its range fails with what would have been valid, a partial block keeps the defaults of the
keys it omits, and every block checks itself once built (:meth:`agents.settings.Settings.check`). Dotted keys
(``ppo.gamma``, from ``--set`` or a grid) are checked against the fields on the way in (:func:`set_dotted`).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import numbers
import types
from collections.abc import Mapping
from typing import Any, Union, get_args, get_origin, get_type_hints

import yaml

from agents.config.schema import Config, Schedule
from agents.settings import ConfigError, Settings, deep_copy


def set_dotted(tree: dict, key: str, value: Any) -> None:
    """Set ``tree[a][b] = value`` for ``key = "a.b"``, checking each part against the dataclass fields."""
    parts = key.split(".")
    cls: Any = Config  # None inside a free-form mapping (env.options), where any key is allowed
    node = tree
    for depth, part in enumerate(parts):
        here = ".".join(parts[: depth + 1])
        if cls is not None and part not in (names := [f.name for f in dataclasses.fields(cls)]):
            raise ConfigError(_unknown_key_message(here, part, names))
        if depth == len(parts) - 1:
            node[part] = value
            return
        child = get_type_hints(cls)[part] if cls is not None else None
        if cls is not None and not (_is_dataclass_type(child) or get_origin(child) is dict):
            raise ConfigError(f"key {key!r}: {here!r} is a {getattr(child, '__name__', child)}, it has no sub-keys")
        if child is Schedule and _is_number(_float_or_text(node.get(part))):
            node[part] = _constant_schedule(_float_or_text(node[part]))
        elif not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
        cls = child if _is_dataclass_type(child) else None


def _constant_schedule(value: float) -> dict:
    """A plain number written for a schedule: that value, constant."""
    return {"initial": value, "final": None, "decay_updates": None}


def build(cls: type, raw: Any, prefix: str, defaults: Any = None) -> Any:
    """An instance of dataclass ``cls`` from ``raw``; missing keys come from ``defaults`` (or the class)."""
    if cls is Schedule and isinstance(raw, str):
        raw = _float_or_text(raw)  # YAML 1.1 reads 1e-3 (no dot) as a string
    if cls is Schedule and _is_number(raw):
        raw = _constant_schedule(raw)
    if cls is Schedule and not isinstance(raw, Mapping):  # neither form of a schedule: say both, not just one
        raise ConfigError(
            f"{prefix}={raw!r} is invalid: expected a number (a constant) or a mapping "
            "{initial: ..., final: ..., decay_updates: ...} (a linear schedule)"
        )
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{prefix or 'config'} must be a mapping of keys to values, got {raw!r}")
    names = [f.name for f in dataclasses.fields(cls)]
    for key in raw:
        if key not in names:
            raise ConfigError(_unknown_key_message(_join(prefix, str(key)), str(key), names))
    hints = get_type_hints(cls)
    defaults = cls() if defaults is None else defaults
    values = {}
    for f in dataclasses.fields(cls):
        if f.name not in raw:
            continue
        key, tp = _join(prefix, f.name), hints[f.name]
        if _is_dataclass_type(tp):  # a partial block keeps this field's own defaults for the keys it omits
            values[f.name] = build(tp, raw[f.name], key, defaults=getattr(defaults, f.name))
        else:
            values[f.name] = _convert(tp, raw[f.name], key, f.metadata)
    instance = dataclasses.replace(defaults, **values)
    if isinstance(instance, Settings):
        instance.check(prefix)
    return instance


def _convert(tp: Any, value: Any, key: str, meta: Mapping[str, Any], text_numbers: bool = True) -> Any:
    """Validate one value against its annotated type and bounds; return it in canonical form. ``text_numbers``: a
    string that spells a number is that number (off where the field also takes strings, e.g. ``int | str``)."""
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        options = [a for a in args if a is not type(None)]
        for option in options:
            try:
                return _convert(option, value, key, meta, text_numbers=str not in options)
            except ConfigError as err:
                errors.append(str(err))
        expected = meta.get("expect") or _describe(tp)
        raise ConfigError(errors[0] if len(errors) == 1 else f"{key}={value!r} is invalid: expected {expected}")
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}={value!r} is invalid: expected true or false")
        return value
    if tp in (int, float):
        return _number(tp, value, key, meta, text_numbers)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}={value!r} is invalid: expected a string")
        return value
    if origin is list:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{key}={value!r} is invalid: expected a list")
        (item_type,) = args or (Any,)
        return [value_ if item_type is Any else _convert(item_type, value_, key, {}) for value_ in value]
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key}={value!r} is invalid: expected a mapping")
        return deep_copy(dict(value))
    raise TypeError(f"config field {key} has an unsupported annotation {tp!r}")  # a bug in this module


def _number(tp: type, value: Any, key: str, meta: Mapping[str, Any], text_numbers: bool = True) -> int | float:
    """A number field's value. Scientific notation is accepted for ints too (``total_steps: 1e5``, ``1.0e5``,
    ``100000.0``) as long as the value is whole; YAML 1.1 reads ``1e5`` and ``1.0e5`` as strings, hence the parse."""
    low, high = meta.get("low"), meta.get("high")
    bounds = ""
    if low is not None or high is not None:
        bounds = f" in [{'-inf' if low is None else f'{low:g}'}, {'inf' if high is None else f'{high:g}'}]"
    expected = f"{'an int' if tp is int else 'a number'}{bounds}"
    given = value
    if text_numbers and isinstance(value, str):
        value = _float_or_text(value)
    if isinstance(value, bool) or not _is_number(value):
        raise ConfigError(f"{key}={given!r} is invalid: expected {expected}")
    if tp is int and not isinstance(value, numbers.Integral):
        if not (math.isfinite(value) and float(value).is_integer()):
            raise ConfigError(f"{key}={given!r} is invalid: expected {expected}; {value:g} is not a whole number")
    value = int(value) if tp is int else float(value)
    if not math.isfinite(value) or (low is not None and value < low) or (high is not None and value > high):
        raise ConfigError(f"{key}={value!r} is invalid: expected {expected}")
    return value


def parse_override(item: str) -> tuple[str, Any]:
    """Split ``a.b=value`` and parse the value as a YAML scalar (``0.1``, ``true``, ``[0, 9]``, ``max``)."""
    key, sep, text = item.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"override {item!r} is invalid: expected KEY=VALUE, e.g. ppo.gamma=0.995")
    try:
        value = yaml.safe_load(text) if text.strip() else ""
    except yaml.YAMLError as err:
        raise ConfigError(f"override {item!r}: cannot parse the value {text!r} ({err})") from err
    return key.strip(), value


def config_to_dict(config: Any) -> Any:
    """The config as plain nested dicts/lists (what ``config.yaml`` of a run holds)."""
    if dataclasses.is_dataclass(config):
        return {f.name: config_to_dict(getattr(config, f.name)) for f in dataclasses.fields(config)}
    if isinstance(config, dict):
        return {k: config_to_dict(v) for k, v in config.items()}
    if isinstance(config, list | tuple):
        return [config_to_dict(v) for v in config]
    return config


def differing_keys(a: Any, b: Any, prefix: str = "") -> list[str]:
    """The dotted keys at which two nested dicts differ (``a``'s order, then keys only ``b`` has)."""
    if not (isinstance(a, dict) and isinstance(b, dict)):
        return [] if a == b else [prefix or "(config)"]
    keys = list(a) + [key for key in b if key not in a]
    return [k for key in keys for k in differing_keys(a.get(key), b.get(key), f"{prefix}.{key}" if prefix else key)]


def _unknown_key_message(full_key: str, key: str, names: list[str]) -> str:
    close = difflib.get_close_matches(key, names, n=1, cutoff=0.5)
    parent = full_key[: -len(key)]
    hint = f" (did you mean {parent + close[0]!r}?)" if close else ""
    return f"unknown config key {full_key!r}{hint}; valid keys here: {', '.join(names)}"


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _float_or_text(text: Any) -> Any:
    """A string that spells a number (``1e-3``, ``1.0e-3``, ``0.001``) as that float; anything else unchanged."""
    if not isinstance(text, str):
        return text
    try:
        return float(text)
    except ValueError:
        return text


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _is_dataclass_type(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def _describe(tp: Any) -> str:
    args = [a for a in get_args(tp) if a is not type(None)]
    names = {int: "an int", float: "a number", str: "a string", bool: "true or false"}
    return " or ".join(names.get(a, getattr(a, "__name__", str(a))) for a in args)
