"""Grids: one config file as a set of runs (one figure panel), the product of its axes.

* A **plain axis** is a dotted key with a list of values: ``run.seed: [0, 1, 2]``, ``ppo.gamma: [0.99, 0.995]``, or a
  whole block ``model.helm: [{lm: none}, {lm: random}]`` (a mapping value replaces that block; keys it omits take
  their defaults, not the base file's).
* A **named axis** (``method`` or ``task``) maps names to bundles of overrides, so that one value sets several keys::

      grid:
        method:
          ppo:    {model.memory: none}
          stack4: {model.memory: none, model.frame_stack: 4}
        task:
          mmact_grid: {env.id: MortarMayhemB-Grid-v0, env.options: {}}
        run.seed: [0, 1, 2, 3, 4]

  A bundle sets ``run.method`` / ``run.task`` to its name (the names in records and plots), then its own keys.
* ``panel:`` names the panel (default: the file's stem); ``slurm:`` holds the cluster settings of the sweep
  (:class:`SlurmConfig`).
* ``exclude:`` leaves cells out of the product: a list of mappings from axes to a label or a list of labels; a point
  that matches every key of one entry is not a run (``exclude: [{method: trxl_recon, task: [endless_mp]}]``: the
  reconstruction variant on the other tasks only).

Override order, lowest first: the base file (everything outside ``grid``) < the bundles, axis by axis in the order
the file lists the named axes (a bundle's keys in its own order) < the plain axes, in file order < command-line
``--set`` overrides. ``--set grid.AXIS=VALUE`` replaces an axis (``--set grid.run.seed=[0]``) and
``--set grid.slurm.KEY=VALUE`` one cluster setting, before the grid is expanded. Loading a grid config expands it and
validates every point (:func:`expand_grid`): an error names the point, the axis and bundle, and the key.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import yaml

from agents.config.building import build, parse_override, set_dotted
from agents.config.schema import Config, SlurmConfig, check_cross_fields
from agents.settings import ConfigError, deep_copy

NAMED_AXES = ("method", "task")  # axes whose values are named bundles; a bundle sets run.<axis> to its name
PANEL, SLURM, EXCLUDE = "panel", "slurm", "exclude"
GRID_SETTINGS = (PANEL, SLURM, EXCLUDE)  # grid keys that are not axes
RESERVED_NAMES = ("results", "slurm")  # sub-directories of a panel's directory that runs cannot take
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+=-]*\Z")


@dataclass(frozen=True)
class GridPoint:
    """One point of a grid: its choice on every axis and the whole config it makes.

    ``choices``: ``(axis, label)`` per axis in application order (named axes, then plain axes), the label being the
    bundle's name or the plain value written as YAML. ``overrides``: ``(dotted key, value, source)`` in the order they
    were applied (``source`` names the grid entry, e.g. ``grid.method.stack4`` or ``grid.run.seed``); command-line
    overrides come after them and are not listed."""

    choices: tuple[tuple[str, str], ...]
    overrides: tuple[tuple[str, Any, str], ...]
    config: Config

    def choice(self, axis: str) -> str | None:
        """The label of ``axis`` at this point (None when the grid has no such axis)."""
        return dict(self.choices).get(axis)


def expand_grid(raw: Mapping[str, Any], overrides: Iterable[str] = ()) -> list[GridPoint]:
    """Every point of the grid of ``raw`` (a config with a ``grid`` block) as a validated config, in product order
    (the first axis varies slowest). ``overrides``: ``key=value`` items; ``grid.AXIS=...`` ones change the grid,
    the others apply to every point last. A config without a grid is one point."""
    base = deep_copy(dict(raw))
    grid = base.pop("grid", None) or {}
    if not isinstance(grid, Mapping):
        raise ConfigError(f"grid must be a mapping of axes to values, got {grid!r}")
    grid = deep_copy(dict(grid))
    late = []
    for item in overrides:
        key, value = parse_override(item)
        if key.split(".")[0] == "grid":
            holder = {"grid": grid}
            apply_override(holder, key, value)
            grid = holder["grid"]
        else:
            late.append((key, value))
    if SLURM in grid:
        grid_slurm(grid)
    grid_panel(grid)
    axes = _grid_axes(grid, base)
    excluded = _exclusions(grid.get(EXCLUDE), axes)
    points = []
    for combination in itertools.product(*(options for _, options in axes)):
        labels = {axis: label for (axis, _), (label, _) in zip(axes, combination, strict=True)}
        if any(all(labels.get(axis) in names for axis, names in entry.items()) for entry in excluded):
            continue
        tree = deep_copy(base)
        applied = []
        for (axis, _), (label, sets) in zip(axes, combination, strict=True):
            source = f"grid.{axis}.{label}" if axis in NAMED_AXES else f"grid.{axis}"
            for key, value in sets:
                set_dotted(tree, key, deep_copy(value))
                applied.append((key, value, source))
        for key, value in late:
            set_dotted(tree, key, deep_copy(value))
        choices = tuple((axis, label) for (axis, _), (label, _) in zip(axes, combination, strict=True))
        try:
            config = build(Config, tree, prefix="")
            check_cross_fields(config)
        except ConfigError as err:
            where = ", ".join(f"{axis}={label}" for axis, label in choices)
            by_source: dict[str, list[str]] = {}
            for key, value, source in applied:
                by_source.setdefault(source, []).append(f"{key}={_flow(value)}")
            sets = "; ".join(f"{source} sets {', '.join(items)}" for source, items in by_source.items())
            raise ConfigError(f"grid point ({where}) is invalid: {err} [{sets}]") from err
        points.append(GridPoint(choices, tuple(applied), config))
    return points


def _exclusions(raw: Any, axes: list[tuple[str, list[tuple[str, list]]]]) -> list[dict[str, set[str]]]:
    """``grid.exclude`` checked against the axes: per entry, axis -> the labels it leaves out."""
    if raw is None:
        return []
    labels = {axis: [label for label, _ in options] for axis, options in axes}
    if not isinstance(raw, list) or not all(isinstance(entry, Mapping) and entry for entry in raw):
        raise ConfigError(f"grid.exclude={raw!r} is invalid: expected a list of mappings axis -> label(s)")
    entries = []
    for index, entry in enumerate(raw):
        found = {}
        for axis, value in entry.items():
            axis = str(axis)
            if axis not in labels:
                raise ConfigError(f"grid.exclude[{index}]: {axis!r} is not an axis; the axes: {', '.join(labels)}")
            names = {
                _flow(item) if not isinstance(item, str) else item
                for item in (value if isinstance(value, list) else [value])
            }
            unknown = sorted(names - set(labels[axis]))
            if unknown:
                raise ConfigError(
                    f"grid.exclude[{index}]: {axis} has no {', '.join(unknown)}; its labels: {', '.join(labels[axis])}"
                )
            found[axis] = names
        entries.append(found)
    return entries


def grid_panel(grid: Mapping[str, Any]) -> str | None:
    """The panel name a grid gives itself (``grid.panel``), or None."""
    panel = grid.get(PANEL)
    if panel is None:
        return None
    if not isinstance(panel, str):
        raise ConfigError(f"grid.panel={panel!r} is invalid: expected a name")
    check_name("grid.panel", panel)
    return panel


def grid_slurm(grid: Mapping[str, Any]) -> SlurmConfig:
    """The cluster settings of a grid (``grid.slurm``; defaults when absent), validated."""
    return build(SlurmConfig, grid.get(SLURM) or {}, prefix="grid.slurm")


def check_name(key: str, name: str) -> None:
    """A panel, bundle or value name is one path component of run directories: letters, digits and ``_.+=-``."""
    if not _NAME.match(name) or name in RESERVED_NAMES:
        reserved = f" and not one of {', '.join(RESERVED_NAMES)}" if name in RESERVED_NAMES else ""
        raise ConfigError(
            f"{key}: {name!r} cannot name a directory: expected letters, digits and _.+=-, starting with a letter "
            f"or a digit{reserved}"
        )


def _grid_axes(grid: Mapping[str, Any], base: Mapping[str, Any]) -> list[tuple[str, list[tuple[str, list]]]]:
    """The axes of a grid in application order: ``(axis, [(label, [(key, value), ...]), ...])``, named axes first
    (file order), then plain axes (file order). Checks names and keys; values are checked with the whole point."""
    named, plain = [], []
    for axis, values in grid.items():
        axis = str(axis)
        if axis in GRID_SETTINGS:
            continue
        if axis in NAMED_AXES:
            named.append((axis, _bundles(axis, values, base)))
            continue
        if "." not in axis:
            raise ConfigError(
                f"grid.{axis} is not a grid key: expected a dotted config key with a list of values (e.g. run.seed), "
                f"a named axis ({', '.join(NAMED_AXES)}) or a setting ({', '.join(GRID_SETTINGS)})"
            )
        if axis.split(".")[0] == "grid":
            raise ConfigError(f"grid.{axis}: the grid cannot sweep itself")
        if not isinstance(values, list) or not values:
            raise ConfigError(f"grid.{axis}={values!r} is invalid: expected a non-empty list of values")
        _check_grid_key(f"grid.{axis}", axis, values[0], base)
        labels = [_flow(value) for value in values]
        for label in labels:
            if labels.count(label) > 1:
                raise ConfigError(f"grid.{axis} lists the value {label} more than once")
        plain.append((axis, [(label, [(axis, value)]) for label, value in zip(labels, values, strict=True)]))
    return named + plain


def _bundles(axis: str, values: Any, base: Mapping[str, Any]) -> list[tuple[str, list]]:
    if not isinstance(values, Mapping) or not values:
        raise ConfigError(
            f"grid.{axis}={values!r} is invalid: expected a mapping of names to bundles of overrides, "
            f"e.g. {{gru: {{model.memory: gru}}}}"
        )
    bundles = []
    for name, bundle in values.items():
        name = str(name)
        check_name(f"grid.{axis}.{name}", name)
        bundle = {} if bundle is None else bundle
        if not isinstance(bundle, Mapping):
            raise ConfigError(
                f"grid.{axis}.{name}={bundle!r} is invalid: expected a mapping of dotted keys to values, "
                "e.g. {model.memory: none, model.frame_stack: 4}"
            )
        sets = [(f"run.{axis}", name)]
        for key, value in bundle.items():
            key = str(key)
            if key.split(".")[0] == "grid":
                raise ConfigError(f"grid.{axis}.{name}: a bundle cannot set the grid ({key})")
            _check_grid_key(f"grid.{axis}.{name}", key, value, base)
            sets.append((key, value))
        bundles.append((name, sets))
    return bundles


def _check_grid_key(where: str, key: str, value: Any, base: Mapping[str, Any]) -> None:
    """That ``key`` names a config field (with a suggestion when it does not), whatever the other axes choose."""
    try:
        set_dotted(deep_copy(dict(base)), key, deep_copy(value))
    except ConfigError as err:
        raise ConfigError(f"{where}: {err}") from err


def apply_override(tree: dict, key: str, value: Any) -> None:
    """:func:`set_dotted`, except that ``grid.AXIS`` names an axis (its dots belong to the axis) and
    ``grid.slurm.KEY`` one cluster setting."""
    if key.split(".")[0] != "grid":
        set_dotted(tree, key, value)
        return
    rest = key[len("grid.") :]
    if not rest:
        raise ConfigError(f"override {key!r}: name the grid entry, e.g. grid.run.seed=[0, 1]")
    grid = tree.get("grid")
    if not isinstance(grid, dict):
        grid = tree["grid"] = {}
    setting, _, sub = rest.partition(".")
    if setting == SLURM and sub:
        if not isinstance(grid.get(setting), dict):
            grid[setting] = {}
        grid[setting][sub] = value
    else:
        grid[rest] = value


def _flow(value: Any) -> str:
    """A value as one line of YAML (``0.99``, ``max``, ``[0, 9]``, ``{lm: random}``)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10_000, sort_keys=False).strip()
    return text[: -len("\n...")].strip() if text.endswith("\n...") else text.removesuffix("...").strip()
