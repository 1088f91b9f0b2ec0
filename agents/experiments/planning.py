"""Planning a sweep: a grid config (one figure panel) expanded into named runs, and the runs ``--only`` selects.

Layout under the root (``scripts/sweep.py --root``, default ``runs/``)::

    <root>/<panel>/<method>/<task>/seed<k>/   one run directory per grid point, as scripts/train.py writes it:
        config.yaml, run_info.json, checkpoints/, training.csv, eval/episodes.csv, TensorBoard events,
        stdout.log (the local launcher's log of every attempt), evaluation/ (the final evaluation)
    <root>/<panel>/results/                   the panel's results: episodes.csv, training.csv, summary.json, plots
    <root>/<panel>/slurm/                     submitit's job files and logs (the SLURM launcher, experiments/slurm.py)

Names. The panel is ``grid.panel`` or the config file's stem; method and task are the names of the bundles of the
``method`` / ``task`` axes (without such an axis: ``Config.method`` / ``Config.task``); k is ``run.seed``. A plain
axis other than ``run.seed`` adds a ``<key>=<value>`` component before ``seed<k>``. Two points with the same name
are an error (name them with a bundle axis).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from agents.config import (
    NAMED_AXES,
    Config,
    ConfigError,
    GridPoint,
    SlurmConfig,
    check_name,
    config_from_dict,
    expand_grid,
    grid_panel,
    grid_slurm,
    read_config_file,
)

Echo = Callable[[str], None]  # where a sweep says what it does (print, or a test's list)


class SweepError(RuntimeError):
    """A sweep cannot go on as asked: a run directory disagrees with the grid, submitit is missing, ..."""


@dataclass(frozen=True)
class SweepRun:
    """One run of a panel: its name (``<panel>/<method>/<task>/seed<k>``), directory and grid point."""

    name: str
    run_dir: Path
    point: GridPoint

    @property
    def config(self) -> Config:
        return self.point.config

    @property
    def steps(self) -> int:
        """Agent steps (decisions) of the whole run: whole updates only, as the trainer runs them."""
        return self.config.num_updates * self.config.batch_size

    @property
    def frames(self) -> int:
        """Environment frames of the whole run (steps x ``env.frame_skip``)."""
        return self.steps * self.config.env.frame_skip

    def grid_overrides(self) -> list[tuple[str, Any]]:
        """What the grid sets for this run, in order, without the ``run.method`` / ``run.task`` that the bundles'
        names set (they are in the run's name)."""
        implicit = [(f"run.{axis}", label) for axis, label in self.point.choices if axis in NAMED_AXES]
        return [(key, value) for key, value, _ in self.point.overrides if (key, value) not in implicit]


@dataclass(frozen=True)
class Panel:
    """The runs of one grid config under ``root/name``, with the cluster settings of its ``grid.slurm``; after
    :func:`select_runs`, only the selected runs."""

    name: str
    root: Path
    runs: tuple[SweepRun, ...]
    slurm: SlurmConfig
    source: Path | None = None
    overrides: tuple[str, ...] = ()
    grid: dict[str, Any] = dataclasses.field(default_factory=dict)
    selection: tuple[str, ...] = ()  # the --only items that cut ``runs`` down (:func:`select_runs`)

    @property
    def directory(self) -> Path:
        return self.root / self.name

    @property
    def results_dir(self) -> Path:
        return self.directory / "results"

    @property
    def slurm_dir(self) -> Path:
        return self.directory / "slurm"


def load_panel(path: str | Path, overrides: Sequence[str] = (), root: str | Path = "runs") -> Panel:
    """The panel of a grid config file: the base validated, every point expanded and named."""
    path = Path(path)
    raw = read_config_file(path)
    try:
        return panel_from_dict(raw, overrides, root=root, name=None, source=path)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from err


def panel_from_dict(
    raw: dict[str, Any],
    overrides: Sequence[str] = (),
    *,
    root: str | Path = "runs",
    name: str | None = None,
    source: Path | None = None,
) -> Panel:
    """The panel of a config given as nested dicts. Its name: ``name``, else ``grid.panel``, else the stem of
    ``source``."""
    base = config_from_dict(raw, overrides)  # validates the base and every point
    panel = name or grid_panel(base.grid) or (source.stem if source is not None else None)
    if panel is None:
        raise ConfigError("the panel has no name: give grid.panel (or load it from a file)")
    check_name("panel", panel)
    root = Path(root)
    runs, seen = [], {}
    for point in map(separate_cells, expand_grid(raw, overrides)):
        run_name = _run_name(panel, point)
        if run_name in seen:
            raise ConfigError(
                f"grid points ({_choices(seen[run_name])}) and ({_choices(point)}) both make the run {run_name}: "
                "name what differs with a method or task bundle"
            )
        seen[run_name] = point
        runs.append(SweepRun(run_name, root.joinpath(*run_name.split("/")), point))
    return Panel(panel, root, tuple(runs), grid_slurm(base.grid), source, tuple(overrides), dict(base.grid))


def _run_name(panel: str, point: GridPoint) -> str:
    config = point.config
    check_name("the method's name", config.method)
    check_name("the task's name", config.task)
    return "/".join([panel, config.method, config.task, f"seed{config.run.seed}"])


def separate_cells(point: GridPoint) -> GridPoint:
    """The point with its plain axes other than ``run.seed`` written into its cell's names, so that the runs of one
    (method, task) cell differ by their seed only, as the panel's results demand (different experiments are never
    pooled): ``env.*`` axes extend the task (``pom+env.options.delay=8``), the others the method
    (``gru+ppo.gamma=0.9``). A point without such axes is returned as it is."""
    config = point.config
    extra = [(axis, label) for axis, label in point.choices if "." in axis and axis != "run.seed"]
    if not extra:
        return point

    def extended(name: str, axes: list[tuple[str, str]]) -> str:
        return name + "".join(f"+{axis}={_path_safe(label)}" for axis, label in axes)

    method = extended(point.choice("method") or config.method, [a for a in extra if not a[0].startswith("env.")])
    task = extended(point.choice("task") or config.task, [a for a in extra if a[0].startswith("env.")])
    run = dataclasses.replace(config.run, method=method, task=task)
    return dataclasses.replace(point, config=dataclasses.replace(config, run=run))


def _path_safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.+=-]+", "_", text).strip("_") or "_"


def _choices(point: GridPoint) -> str:
    return ", ".join(f"{axis}={label}" for axis, label in point.choices)


# ------------------------------------------------------------------------------------------------ selection
SELECTION_ALIASES = {"seed": "run.seed", "run.method": "method", "run.task": "task"}  # --only's short keys
_PAIR_START = re.compile(r",\s*(?=[A-Za-z_][\w.]*\s*=)")  # a comma that starts the next key=value pair


def run_coordinates(run: SweepRun) -> dict[str, str]:
    """What ``--only`` selects a run by: the method, task and ``run.seed`` of its name (every run has them) and its
    label on every axis of the grid (a bundle's name, a plain axis' value as one line of YAML)."""
    _, method, task, *_ = run.name.split("/")
    return {"method": method, "task": task, "run.seed": str(run.config.run.seed), **dict(run.point.choices)}


def parse_selection(text: str) -> dict[str, str]:
    """One ``--only`` value: ``key=value`` pairs joined by commas, e.g. ``method=gru,task=mm_grid_1,seed=0``. A comma
    starts a new pair only where a key and ``=`` follow, so a value such as ``[0, 1]`` stays whole."""
    selection: dict[str, str] = {}
    for pair in _PAIR_START.split(text.strip()):
        key, equals, value = (part.strip() for part in pair.partition("="))
        if not (key and equals and value):
            raise SweepError(f"--only {text}: expected key=value pairs joined by commas, e.g. method=gru,seed=0")
        key = SELECTION_ALIASES.get(key, key)
        if key in selection:  # a run has one value per key: the pair could never match
            raise SweepError(
                f"--only {text} names {key} twice; one --only selects the runs that match all its pairs, "
                "repeat --only to add the runs of another value"
            )
        selection[key] = value
    return selection


def select_runs(panels: Sequence[Panel], only: Sequence[str]) -> list[Panel]:
    """The panels cut down to the runs ``only`` selects (``scripts/sweep.py --only``): a run is kept when it matches
    every pair of at least one item (within an item AND, across items OR). Keys are the axes of the grids plus
    ``method``, ``task`` and ``run.seed`` (``seed``); a key or a value that no run has is an error naming the valid
    ones, and so is a selection that keeps no run. Panels left without a run are dropped. Without ``only``: the
    panels as they are."""
    if not only:
        return list(panels)
    selections = [parse_selection(text) for text in only]
    coordinates = {run.name: run_coordinates(run) for panel in panels for run in panel.runs}
    valid: dict[str, list[str]] = {}
    for found in coordinates.values():
        for key, value in found.items():
            if value not in valid.setdefault(key, []):
                valid[key].append(value)
    where = ", ".join(panel.name for panel in panels)
    for text, selection in zip(only, selections, strict=True):
        for key, value in selection.items():
            if key not in valid:
                keys = ", ".join(f"{k} (seed)" if k == "run.seed" else k for k in valid)
                raise SweepError(f"--only {text}: {key!r} is not an axis of {where}; valid keys: {keys}")
            if _label(value, valid[key]) is None:
                raise SweepError(
                    f"--only {text}: no run of {where} has {key}={value}; valid values: {', '.join(valid[key])}"
                )
    wanted = [{key: _label(value, valid[key]) for key, value in selection.items()} for selection in selections]

    def selected(run: SweepRun) -> bool:
        found = coordinates[run.name]
        return any(all(found.get(key) == value for key, value in selection.items()) for selection in wanted)

    kept = [
        dataclasses.replace(panel, runs=tuple(filter(selected, panel.runs)), selection=tuple(only)) for panel in panels
    ]
    kept = [panel for panel in kept if panel.runs]
    if not kept:
        raise SweepError(f"--only {' '.join(only)}: no run of {where} matches all the pairs of one --only")
    return kept


def _label(value: str, labels: Sequence[str]) -> str | None:
    """The label ``value`` names: itself, or the same value written as the grid writes it (``0.90`` -> ``0.9``)."""
    if value in labels:
        return value
    try:
        parsed = short_yaml(yaml.safe_load(value), 10_000)
    except yaml.YAMLError:
        return None
    return parsed if parsed in labels else None


def short_yaml(value: Any, width: int) -> str:
    """A value as one line of YAML; a longer mapping as ``{N keys}`` (the axes list it in full)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10_000, sort_keys=False).strip()
    text = text.removesuffix("...").strip()
    if len(text) <= width:
        return text
    return f"{{{len(value)} keys}}" if isinstance(value, dict) else text[: width - 3] + "..."
