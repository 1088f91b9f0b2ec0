"""Loading: a config from a YAML file or nested dicts, with ``--set key=value`` overrides, validated as a whole (a
grid config: every point of its grid); and the resolved config back as YAML (a run's ``config.yaml``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml

from agents.config.building import build, config_to_dict, parse_override
from agents.config.grids import apply_override, expand_grid
from agents.config.schema import Config, check_cross_fields
from agents.settings import ConfigError, deep_copy


def read_config_file(path: str | Path) -> dict[str, Any]:
    """The mapping a YAML config file holds, or a :class:`ConfigError` naming what is wrong with the file."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {str(path)!r} does not exist")
    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: {_yaml_error(err)}") from err
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level, got {type(raw).__name__}")
    return raw


def _yaml_error(err: yaml.YAMLError) -> str:
    """A YAML syntax error as 'line L, column C: problem' (1-based, where the parser stopped), without a traceback."""
    mark = getattr(err, "problem_mark", None)
    problem = getattr(err, "problem", None) or str(err)
    context = getattr(err, "context", None)
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    return f"{where}invalid YAML: {problem}" + (f" ({context})" if context else "")


def load_config(path: str | Path, overrides: Iterable[str] = ()) -> Config:
    """Read a YAML config, apply ``key=value`` overrides and validate everything."""
    return config_from_dict(read_config_file(path), overrides)


def config_from_dict(raw: Mapping[str, Any], overrides: Iterable[str] = ()) -> Config:
    """Build a validated :class:`Config` from nested dicts plus ``key=value`` overrides.

    With a ``grid`` block the result is the base of the grid (base file plus overrides, each block validated), and
    every point of the grid is expanded and validated as a whole config (:func:`~agents.config.grids.expand_grid`)."""
    overrides = list(overrides)
    merged = deep_copy(raw)
    for item in overrides:
        key, value = parse_override(item)
        apply_override(merged, key, value)
    config = build(Config, merged, prefix="")
    if not config.grid:
        check_cross_fields(config)
        return config
    expand_grid(raw, overrides)
    return config


def dump_config(config: Config) -> str:
    """The config as the YAML of a run's ``config.yaml`` (keys in the schema's order)."""
    return yaml.safe_dump(config_to_dict(config), sort_keys=False)
