"""Reading the records of results directories and checking that they fit together.

A results directory holds ``episodes.csv`` (one row per evaluated episode, written by the evaluation) and, optionally,
``training.csv`` (one row per PPO update of every run). Their first columns are fixed (:data:`EPISODE_COLUMNS`,
:data:`TRAINING_COLUMNS`; records written before ``env_options`` and ``config_digest`` existed lack those two and still
load, with the columns empty); any further numeric column (``success``, ``commands_completed``, ...) is kept and may be
empty in some rows.

One (method, task) cell pools runs that differ only by their seeds: ``config_digest``
(:func:`agents.analysis.digest.config_digest`) names what the rest of a run's config sets, and records whose digests
disagree within a cell are refused (:func:`check_configs`), naming the runs and, where their saved ``config.yaml`` can
be found, the keys that differ. The scores across runs are in :mod:`agents.analysis.scores`. numpy and the standard
library only.
"""

from __future__ import annotations

import csv
import json
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agents.analysis.digest import describe_differences, experiment_settings

if TYPE_CHECKING:
    from agents.config import Config

EPISODE_COLUMNS = (
    "run",
    "method",
    "task",
    "env_id",
    "step",
    "seed",
    "repetition",
    "return",
    "length",
    "metric",
    "metric_reference",
    "env_options",
    "config_digest",
)
TRAINING_COLUMNS = ("run", "method", "task", "env_id", "step", "return", "length", "metric", "config_digest")
TEXT_COLUMNS = ("run", "method", "task", "env_id")
OPTIONS_COLUMN = "env_options"  # the env's non-default reset options as sorted JSON ("{}": all default)
CONFIG_COLUMN = "config_digest"  # what defines the experiment, seeds and bookkeeping left out (config_digest())
OPTIONAL_COLUMNS = (OPTIONS_COLUMN, CONFIG_COLUMN)  # absent from older records: read as empty text
_INTEGER_COLUMNS = ("step", "seed", "repetition")
_REQUIRED_VALUES = {  # numeric columns that may not be empty
    "episodes.csv": ("step", "seed", "repetition", "return", "length"),
    "training.csv": ("step",),
}


class ResultsWarning(UserWarning):
    """Something was left out of an aggregate (checkpoints not shared by all runs, empty columns, missing files)."""


def warn(message: str) -> None:
    warnings.warn(message, ResultsWarning, stacklevel=3)


class Records:
    """A column-oriented table: name -> 1-D numpy array (text as ``str`` arrays, numbers as int64/float64)."""

    def __init__(self, columns: Mapping[str, np.ndarray]) -> None:
        self.columns = {name: np.asarray(values) for name, values in columns.items()}
        lengths = {len(values) for values in self.columns.values()}
        if len(lengths) > 1:
            raise ValueError(f"columns of different lengths: {sorted(lengths)}")

    @property
    def names(self) -> list[str]:
        return list(self.columns)

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    def __contains__(self, name: object) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> np.ndarray:
        """A column by name."""
        if name not in self.columns:
            raise KeyError(f"no column {name!r}; columns: {', '.join(self.columns)}")
        return self.columns[name]

    def take(self, names: Sequence[str]) -> Records:
        """A table of the given columns."""
        return Records({name: self[name] for name in names})

    def select(self, mask: np.ndarray) -> Records:
        """The rows where ``mask`` is true (or the rows at the given indices)."""
        return Records({name: values[mask] for name, values in self.columns.items()})

    def where(self, **equal: Any) -> Records:
        """The rows whose columns equal the given values, e.g. ``records.where(method="gru", task="MysteryPath")``."""
        mask = np.ones(len(self), dtype=bool)
        for name, value in equal.items():
            mask &= self[name] == value
        return self.select(mask)

    def unique(self, name: str) -> list:
        """The distinct values of a column, sorted, as Python objects."""
        return np.unique(self[name]).tolist()

    @staticmethod
    def concat(tables: Sequence[Records]) -> Records:
        """Rows of all tables; a column missing from some table is empty (NaN) there."""
        names: list[str] = []
        for table in tables:
            names += [name for name in table.names if name not in names]
        columns = {}
        for name in names:
            parts = [table[name] if name in table else np.full(len(table), np.nan) for table in tables]
            columns[name] = np.concatenate(parts) if parts else np.array([])
        return Records(columns)


@dataclass(frozen=True)
class Results:
    """The records of one or several results directories."""

    episodes: Records
    training: Records | None
    directories: tuple[Path, ...]


def _parse_csv(path: Path, columns: Sequence[str]) -> Records:
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    required = [name for name in columns if name not in OPTIONAL_COLUMNS]
    if not rows:
        raise ValueError(f"{path} is empty: expected a header starting with {', '.join(required)}")
    header, body = rows[0], rows[1:]
    missing = [name for name in required if name not in header]
    if missing:
        raise ValueError(f"{path} lacks the column(s) {', '.join(missing)}; its header is: {', '.join(header)}")
    if tuple(header[: len(required)]) != tuple(required):
        raise ValueError(
            f"{path}: the first columns must be, in this order, {', '.join(required)}; found {', '.join(header)}"
        )
    if len(set(header)) != len(header):
        raise ValueError(f"{path}: repeated column names in the header {', '.join(header)}")
    for line, row in enumerate(body, start=2):
        if len(row) != len(header):
            raise ValueError(f"{path}, line {line}: {len(row)} fields where the header has {len(header)}")
    cells = list(zip(*body, strict=True)) if body else [() for _ in header]
    must_have = _REQUIRED_VALUES.get(path.name, ())
    found: dict[str, np.ndarray] = {}
    for index, name in enumerate(header):
        values = cells[index]
        if name in TEXT_COLUMNS or name in OPTIONAL_COLUMNS:
            found[name] = np.array(values, dtype=str)
            continue
        numbers = _numbers(values)
        if numbers is None:
            if name in required:
                line, value = next((i, v) for i, v in enumerate(values, start=2) if _numbers([v]) is None)
                raise ValueError(f"{path}, line {line}: column {name!r} holds {value!r}, not a number") from None
            found[name] = np.array(values, dtype=str)  # an extra column of text: kept as it is
            continue
        if name in must_have and not np.all(np.isfinite(numbers)):
            line = 2 + int(np.flatnonzero(~np.isfinite(numbers))[0])
            raise ValueError(f"{path}, line {line}: column {name!r} is empty or not finite")
        if name in _INTEGER_COLUMNS and name in must_have:
            if not np.all(numbers == np.round(numbers)):
                raise ValueError(f"{path}: column {name!r} holds values that are not whole numbers")
            numbers = numbers.astype(np.int64)
        found[name] = numbers
    for name in ("run", "method", "env_id"):
        empty = np.flatnonzero(found[name] == "")
        if len(empty):
            raise ValueError(f"{path}, line {2 + int(empty[0])}: column {name!r} is empty")
    found["task"] = np.where(found["task"] == "", found["env_id"], found["task"])  # the task defaults to the id
    for name in columns:  # older records lack the optional columns: empty text, in their place
        found.setdefault(name, np.full(len(body), "", dtype=str))
    return Records({**{name: found[name] for name in columns}, **found})


def _numbers(values: Sequence[str]) -> np.ndarray | None:
    """Cells as float64, an empty cell as NaN; None if a cell is not a number."""
    try:
        return np.array([float(value) if value.strip() else math.nan for value in values], dtype=np.float64)
    except ValueError:
        return None


def _directory(path: str | Path) -> Path:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"results directory {path} does not exist")
    if not path.is_dir():
        raise NotADirectoryError(f"{path} is not a directory (expected a results directory holding episodes.csv)")
    return path


RUN_KEYS = ("method", "task", "run")  # a run is named within its method and task (sweeps: .../<method>/<task>/seed<k>)


def run_ids(records: Records) -> np.ndarray:
    """One identifier per row for the run it belongs to: ``method/task/run``."""
    return np.char.add(
        np.char.add(np.char.add(records["method"].astype(str), "/"), records["task"].astype(str) + "/"),
        records["run"].astype(str),
    )


def _check_runs(records: Records, what: str) -> None:
    """Every run (method/task/run) belongs to one environment; every task to one environment id."""
    identified = Records({**records.columns, "run": run_ids(records)})
    for key, others in (("run", ("env_id",)), ("task", ("env_id",))):
        for other in others:
            table = identified
            pairs = np.unique(np.stack([table[key], table[other]]), axis=1) if len(table) else np.empty((2, 0))
            names, counts = np.unique(pairs[0], return_counts=True)
            if np.any(counts > 1):
                name = str(names[counts > 1][0])
                values = sorted(pairs[1][pairs[0] == name].tolist())
                raise ValueError(f"{what}: {key} {name!r} appears with several {other} values: {', '.join(values)}")


def _check_unique(records: Records, keys: Sequence[str], what: str) -> None:
    if not len(records):
        return
    table = np.stack([records[key].astype(str) for key in keys])
    _, first, counts = np.unique(table, axis=1, return_index=True, return_counts=True)
    if np.any(counts > 1):
        row = int(first[counts > 1][0])
        described = ", ".join(f"{key}={records[key][row]}" for key in keys)
        raise ValueError(f"{what}: {int(counts.max())} rows for the same {described} (the same run read twice?)")


def check_configs(records: Records, what: str, directories: Sequence[str | Path] = ()) -> None:
    """Refuse records whose runs of one (method, task) cell have different ``config_digest`` values: such runs are
    different experiments, not seeds of one. A run's digest is that of its latest rows (a run lengthened on resume
    changes ``run.total_steps`` midway). The error names the cell, the runs of every digest and, where a run's saved
    ``config.yaml`` is found next to ``directories`` (``<dir or its parents>/<run>/config.yaml``), the keys that
    differ. Rows without a digest (older records) are not checked."""
    if CONFIG_COLUMN not in records or not len(records):
        return
    known = records.select(records[CONFIG_COLUMN].astype(str) != "")
    if not len(known):
        return
    ids = run_ids(known)
    order = np.lexsort((known["step"], ids))
    last = order[np.append(ids[order][1:] != ids[order][:-1], True)]  # every run's row of its largest step
    known = known.select(last)
    cells = np.stack([known["method"].astype(str), known["task"].astype(str), known[CONFIG_COLUMN].astype(str)])
    pairs, counts = np.unique(np.unique(cells, axis=1)[:2], axis=1, return_counts=True)  # digests per cell
    if not np.any(counts > 1):
        return
    method, task = (str(name) for name in pairs[:, np.flatnonzero(counts > 1)[0]])
    rows = known.where(method=method, task=task)
    by_digest = {
        digest: sorted(set(rows["run"][rows[CONFIG_COLUMN] == digest].tolist()))
        for digest in np.unique(rows[CONFIG_COLUMN]).tolist()
    }
    groups = "; ".join(f"{digest}: run(s) {', '.join(runs)}" for digest, runs in by_digest.items())
    raise ValueError(
        f"{what}: method {method!r}, task {task!r} holds runs whose configs differ in more than the seed "
        f"(config_digest {groups}). {_differences(by_digest, directories)} Give them different run.method or "
        "run.task names, or read their results apart."
    )


def _differences(by_digest: Mapping[str, Sequence[str]], directories: Sequence[str | Path]) -> str:
    """The keys whose values differ between the saved configs of one run per digest, as a sentence."""
    settings = {}
    for digest, runs in by_digest.items():
        found = next((s for s in (_saved_settings(run, directories) for run in runs) if s is not None), None)
        if found is None:
            return "Their config.yaml files were not found next to the results: compare the runs' configs."
        settings[digest] = found
    return describe_differences(settings)


def _saved_settings(run: str, directories: Sequence[str | Path]) -> dict[str, Any] | None:
    config = _saved_config(run, directories)
    return None if config is None else experiment_settings(config, changed_only=False)


def _saved_config(run: str, directories: Sequence[str | Path]) -> Config | None:
    """``run``'s saved config, looked up as ``<dir>/<run>``, ``<dir>/../<run>`` and ``<dir>/../../<run>`` (a run's
    own directory or its ``eval/``, a sweep's ``<root>/<panel>/results``); None if not found or not readable."""
    from agents.config import config_from_dict, read_config_file

    for directory in directories:
        directory = Path(directory).resolve()
        for base in (directory, *directory.parents[:2]):
            path = base / run / "config.yaml"
            if path.is_file():
                try:
                    return config_from_dict(read_config_file(path))
                except (ValueError, OSError):  # ConfigError is a ValueError; another version's config, say
                    return None
    return None


def task_options(records: Records, directories: Sequence[str | Path] = ()) -> dict[str, dict[str, Any] | None]:
    """Per task, the non-default reset options of its environment: from the ``env_options`` column, else (older
    records) from the saved configs of its runs found next to ``directories`` (as :func:`check_configs` finds them);
    None where they are unknown or the task's runs disagree."""
    from agents.config import resolved_options

    found: dict[str, dict[str, Any] | None] = {}
    texts = records[OPTIONS_COLUMN].astype(str) if OPTIONS_COLUMN in records else np.full(len(records), "")
    for task in np.unique(records["task"]).tolist():
        mine = records["task"] == task
        values = set(texts[mine].tolist())
        if len(values) == 1 and "" not in values:
            found[task] = json.loads(values.pop())
            continue
        options = set()
        for run in np.unique(records["run"][mine]).tolist():
            config = _saved_config(run, directories)
            if config is None:
                options.add(None)
                break
            changed = resolved_options(config.env.id, config.env.options, changed_only=True)
            options.add(json.dumps(changed, sort_keys=True))
        found[task] = json.loads(options.pop()) if len(options) == 1 and None not in options else None
    return found


def read_episodes(*directories: str | Path) -> Records:
    """The ``episodes.csv`` of every directory, concatenated and checked (columns, one method/task per run)."""
    if not directories:
        raise ValueError("no results directory given")
    tables = []
    for directory in map(_directory, directories):
        path = directory / "episodes.csv"
        if not path.is_file():
            raise FileNotFoundError(f"{directory} has no episodes.csv (the evaluation's per-episode records)")
        tables.append(_parse_csv(path, EPISODE_COLUMNS))
        if not len(tables[-1]):
            raise ValueError(f"{path} holds no episode records (only a header)")
    records = Records.concat(tables)
    what = "episodes.csv of " + ", ".join(map(str, directories))
    _check_runs(records, what)
    _check_unique(records, (*RUN_KEYS, "step", "seed", "repetition"), what)
    check_configs(records, what, directories)
    return records


def read_training(*directories: str | Path) -> Records | None:
    """The ``training.csv`` of every directory that has one, concatenated; None if none has one (with a warning)."""
    tables, missing = [], []
    for directory in map(_directory, directories):
        path = directory / "training.csv"
        if path.is_file():
            tables.append(_parse_csv(path, TRAINING_COLUMNS))
        else:
            missing.append(str(directory))
    if missing:
        warn(f"no training.csv in {', '.join(missing)}: no training curves for the runs there")
    if not tables:
        return None
    records = Records.concat(tables)
    what = "training.csv of " + ", ".join(map(str, directories))
    _check_runs(records, what)
    _check_unique(records, (*RUN_KEYS, "step"), what)
    check_configs(records, what, directories)
    return records


def read_results(*directories: str | Path) -> Results:
    """Episodes and training logs of one or several results directories; a run must agree between the two."""
    episodes = read_episodes(*directories)
    training = read_training(*directories)
    if training is not None:
        both = Records.concat([episodes.take(TEXT_COLUMNS), training.take(TEXT_COLUMNS)])
        _check_runs(both, "episodes.csv and training.csv")
    return Results(episodes, training, tuple(Path(directory) for directory in directories))
