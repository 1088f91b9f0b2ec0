"""Reading evaluation records and aggregating them across runs: run-level scores, score matrices, curves, summaries.

A results directory holds ``episodes.csv`` (one row per evaluated episode, written by the evaluation) and, optionally,
``training.csv`` (one row per PPO update of every run). Their first columns are fixed (:data:`EPISODE_COLUMNS`,
:data:`TRAINING_COLUMNS`; records written before ``env_options`` and ``config_digest`` existed lack those two and still
load, with the columns empty); any further numeric column (``success``, ``commands_completed``, ...) is kept and may be
empty in some rows.

One (method, task) cell pools runs that differ only by their seeds: ``config_digest`` (:func:`config_digest`) names
what the rest of a run's config sets, and records whose digests disagree within a cell are refused
(:func:`check_configs`), naming the runs and, where their saved ``config.yaml`` can be found, the keys that differ.

The paper's protocol: a run's score at a checkpoint is the mean of its episodes (30 novel seeds x 5 repetitions);
runs are aggregated with the interquartile mean and a 95% stratified-bootstrap interval (:mod:`agents.stats`).
Runs of one method that were evaluated at different checkpoints are compared only at the steps they share, with a
:class:`ResultsWarning` saying what was left out. numpy and the standard library only.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from agents import stats

if TYPE_CHECKING:
    from agents.config import Config

__all__ = [
    "CONFIG_COLUMN",
    "EPISODE_COLUMNS",
    "OPTIONS_COLUMN",
    "TRAINING_COLUMNS",
    "MethodScores",
    "Records",
    "Results",
    "ResultsWarning",
    "aggregate",
    "check_configs",
    "config_digest",
    "describe_differences",
    "env_options_text",
    "estimate",
    "experiment_settings",
    "format_table",
    "read_episodes",
    "read_results",
    "read_training",
    "run_scores",
    "run_summary",
    "score_curves",
    "score_matrices",
    "summarize",
    "task_options",
    "training_curves",
]

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

Steps = Literal["all", "last"] | int | Sequence[int]


class ResultsWarning(UserWarning):
    """Something was left out of an aggregate (checkpoints not shared by all runs, empty columns, missing files)."""


def _warn(message: str) -> None:
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


def _run_ids(records: Records) -> np.ndarray:
    """One identifier per row for the run it belongs to: ``method/task/run``."""
    return np.char.add(
        np.char.add(np.char.add(records["method"].astype(str), "/"), records["task"].astype(str) + "/"),
        records["run"].astype(str),
    )


def _check_runs(records: Records, what: str) -> None:
    """Every run (method/task/run) belongs to one environment; every task to one environment id."""
    identified = Records({**records.columns, "run": _run_ids(records)})
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


# ------------------------------------------------------------------------------------ what defines an experiment
def experiment_settings(config: Config, greedy: bool | None = None, changed_only: bool = True) -> dict[str, Any]:
    """What defines the experiment of a run, as ``{dotted key: value}``: every config key but those the config's one
    table leaves out (:data:`agents.config.NOT_IN_DIGEST`),
    the env's reset options resolved (``env.options.<name>``), and ``eval.greedy`` as the evaluation used it
    (``greedy``; default: the config's). ``changed_only``: only the values that differ from the defaults (of
    :class:`agents.config.Config` and of the env's options), so that a field added to the config later leaves the
    settings of existing configs unchanged."""
    from agents.config import Config, config_to_dict, in_digest, resolved_options

    def flat(config: Config, changed: bool, greedy: bool | None = None) -> dict[str, Any]:
        tree = config_to_dict(config)
        tree["env"]["options"] = resolved_options(config.env.id, config.env.options, changed_only=changed)
        if greedy is not None:
            tree["eval"]["greedy"] = bool(greedy)
        return {key: value for key, value in _flatten(tree).items() if in_digest(key)}

    found = flat(config, changed_only, greedy)
    if not changed_only:
        return found
    defaults = flat(Config(), False)
    return {key: value for key, value in found.items() if key not in defaults or defaults[key] != value}


def config_digest(config: Config, greedy: bool | None = None) -> str:
    """The ``config_digest`` column: ``c`` and the first 12 hex digits of the SHA-256 of :func:`experiment_settings`
    (changed values only) as sorted, compact JSON; the letter keeps CSV readers from taking it for a number. Runs
    that differ only in seeds, names, device, threads or bookkeeping (:data:`agents.config.NOT_IN_DIGEST`) share it; the
    same config gives the same digest in any process and on any machine."""
    text = json.dumps(experiment_settings(config, greedy), sort_keys=True, separators=(",", ":"))
    return "c" + hashlib.sha256(text.encode()).hexdigest()[:12]


def env_options_text(config: Config) -> str:
    """The ``env_options`` column: the env's non-default reset options as sorted, compact JSON (``{}``: defaults)."""
    from agents.config import resolved_options

    changed = resolved_options(config.env.id, config.env.options, changed_only=True)
    return json.dumps(changed, sort_keys=True, separators=(",", ":"))


def _flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(tree, Mapping):
        return {prefix: tree}
    found: dict[str, Any] = {}
    for key, value in tree.items():
        found.update(_flatten(value, f"{prefix}.{key}" if prefix else str(key)))
    return found


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
    ids = _run_ids(known)
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


def describe_differences(settings: Mapping[str, Mapping[str, Any]]) -> str:
    """The keys whose values differ between the :func:`experiment_settings` of several runs (``{where: settings}``,
    ``where`` naming each in the sentence), as a sentence."""
    keys = sorted(set().union(*settings.values()))
    differing = [key for key in keys if len({json.dumps(s.get(key), sort_keys=True) for s in settings.values()}) > 1]
    if not differing:
        return (
            "Their saved configs agree on every key the digest covers: the records were evaluated differently "
            "(eval.greedy) or written by another version."
        )
    shown = [
        f"{key} ({', '.join(f'{json.dumps(s.get(key))} in {d}' for d, s in settings.items())})" for key in differing
    ]
    more = f" and {len(shown) - 8} more" if len(shown) > 8 else ""
    return f"Differing keys: {'; '.join(shown[:8])}{more}."


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
        _warn(f"no training.csv in {', '.join(missing)}: no training curves for the runs there")
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


def _groups(records: Records, keys: Sequence[str]) -> tuple[Records, np.ndarray]:
    """The distinct key combinations (sorted) and, for every row, the index of its combination."""
    codes, firsts = [], []
    for key in keys:
        uniques, inverse = np.unique(records[key], return_inverse=True)
        codes.append(inverse.reshape(-1))
        firsts.append(len(uniques))
    combined = np.zeros(len(records), dtype=np.int64)
    for code, size in zip(codes, firsts, strict=True):
        combined = combined * size + code
    _, first, inverse = np.unique(combined, return_index=True, return_inverse=True)
    return records.take(keys).select(first), inverse.reshape(-1)


def run_scores(episodes: Records, column: str = "metric") -> Records:
    """One score per run and checkpoint: the mean of ``column`` over the run's episodes at that step.

    Columns: run, method, task, env_id, step, score, episodes. A run/step whose episodes all leave ``column`` empty
    is left out (with a warning: ``success`` is empty for the endless tasks); a partly empty one is an error.
    """
    if column not in episodes:
        raise KeyError(f"no column {column!r} in the episodes; columns: {', '.join(episodes.names)}")
    if episodes[column].dtype.kind not in "fiu":
        raise ValueError(f"column {column!r} is not numeric")
    check_configs(episodes, "episodes")  # records built in memory are checked here, read ones also when read
    values = np.asarray(episodes[column], dtype=np.float64)
    keys, group = _groups(episodes, (*RUN_KEYS, "step"))
    present = np.isfinite(values)
    count = np.bincount(group, minlength=len(keys))
    filled = np.bincount(group, weights=present, minlength=len(keys)).astype(np.int64)
    total = np.bincount(group, weights=np.where(present, values, 0.0), minlength=len(keys))
    partial = np.flatnonzero((filled > 0) & (filled < count))
    if len(partial):
        at = int(partial[0])
        raise ValueError(
            f"column {column!r} is empty in {count[at] - filled[at]} of the {count[at]} episodes of run "
            f"{keys['run'][at]!r} at step {keys['step'][at]}"
        )
    empty = filled == 0
    if np.any(empty):
        runs = sorted(set(keys["run"][empty].tolist()))
        _warn(f"column {column!r} is empty for {int(empty.sum())} run/step pair(s) (runs {', '.join(runs)}): left out")
    first = np.unique(group, return_index=True)[1]  # a row of every (run, step), in the order of ``keys``
    described = episodes.take(("run", "method", "task", "env_id", "step")).select(first)
    scores = Records({**described.columns, "score": total / np.maximum(count, 1), "episodes": count})
    return scores.select(~empty)


@dataclass(frozen=True)
class MethodScores:
    """Run-level scores of one method, one column per task (tasks may have different numbers of runs).

    ``columns[j]`` has shape (runs of ``tasks[j]``, checkpoints); ``steps[j]`` the same shape: the step each score was
    taken at (one row of ``checkpoints`` for curves; each run's own last step for final scores). ``runs[j]`` names the
    rows; ``episodes[j]`` counts the episodes behind each score (None for training curves).
    """

    method: str
    tasks: tuple[str, ...]
    runs: tuple[tuple[str, ...], ...]
    steps: tuple[np.ndarray, ...]
    columns: tuple[np.ndarray, ...]
    episodes: tuple[np.ndarray, ...] | None

    @property
    def checkpoints(self) -> np.ndarray:
        """The step of every checkpoint (the largest where runs end at different steps)."""
        return np.max(np.concatenate(self.steps, axis=0), axis=0)

    def array(self) -> np.ndarray:
        """Scores as one (runs, tasks, checkpoints) array; every task must have the same number of runs."""
        counts = {len(column) for column in self.columns}
        if len(counts) != 1:
            described = ", ".join(f"{task}: {len(runs)}" for task, runs in zip(self.tasks, self.runs, strict=True))
            raise ValueError(f"method {self.method!r} has different numbers of runs per task ({described})")
        return np.stack(self.columns, axis=1)

    def matrix(self) -> np.ndarray:
        """Scores as a (runs, tasks) matrix; only for one checkpoint (:func:`score_matrices`)."""
        array = self.array()
        if array.shape[2] != 1:
            raise ValueError(f"{array.shape[2]} checkpoints: take array() or one step with score_matrices()")
        return array[:, :, 0]


def _select_steps(scores: Records, steps: Steps) -> Records:
    if isinstance(steps, str):
        return scores
    wanted = np.atleast_1d(np.asarray(steps, dtype=np.int64))
    found = np.isin(wanted, scores["step"])
    if not np.all(found):
        raise ValueError(f"no episodes at step(s) {', '.join(map(str, wanted[~found]))}")
    ids = _run_ids(scores)
    lacking = [run for run in np.unique(ids) if not np.all(np.isin(wanted, scores["step"][ids == run]))]
    if lacking:
        _warn(f"run(s) {', '.join(lacking)} have no episodes at some of the step(s) {wanted.tolist()}: left out there")
    return scores.select(np.isin(scores["step"], wanted))


def _shared_steps(scores: Records, label: str) -> np.ndarray:
    """The steps at which every run of ``scores`` has a score; warns about the others."""
    ids = _run_ids(scores)
    runs = np.unique(ids)
    per_run = {run: np.unique(scores["step"][ids == run]) for run in runs}
    shared = per_run[runs[0]]
    for run_steps in per_run.values():
        shared = np.intersect1d(shared, run_steps)
    every = np.unique(scores["step"])
    if len(shared) < len(every):
        dropped = np.setdiff1d(every, shared)
        counts = ", ".join(f"{run}: {len(per_run[run])}" for run in runs)
        _warn(
            f"{label}: runs were evaluated at different steps (checkpoints per run: {counts}); using the "
            f"{len(shared)} step(s) all runs share and leaving out {len(dropped)} (first: {dropped[:5].tolist()})"
        )
    return shared


def _method_scores(scores: Records, method: str, steps: Steps, label: str) -> MethodScores | None:
    tasks = tuple(np.unique(scores["task"]).tolist())
    if steps == "last":
        runs, columns, at, counts = [], [], [], []
        for task in tasks:
            rows = scores.where(task=task)
            names = np.unique(rows["run"])
            last = [int(rows["step"][rows["run"] == run].max()) for run in names]
            picked = [
                int(np.flatnonzero((rows["run"] == run) & (rows["step"] == s))[0])
                for run, s in zip(names, last, strict=True)
            ]
            runs.append(tuple(names.tolist()))
            columns.append(rows["score"][picked][:, None])
            at.append(np.asarray(last, dtype=np.int64)[:, None])
            counts.append(rows["episodes"][picked][:, None])
        ends = np.unique(np.concatenate(at))
        if len(ends) > 1:
            _warn(f"{label}: runs end at different steps ({', '.join(map(str, ends))}); each run's last is taken")
        return MethodScores(method, tasks, tuple(runs), tuple(at), tuple(columns), tuple(counts))
    shared = _shared_steps(scores, label)
    if len(shared) == 0:
        _warn(f"{label}: the runs share no checkpoint step; left out")
        return None
    runs, columns, at, counts = [], [], [], []
    for task in tasks:
        rows = scores.where(task=task)
        rows = rows.select(np.isin(rows["step"], shared))
        names = np.unique(rows["run"])
        order = np.lexsort((rows["step"], np.searchsorted(names, rows["run"])))  # by run, then step
        shape = (len(names), len(shared))
        runs.append(tuple(names.tolist()))
        columns.append(rows["score"][order].reshape(shape))
        at.append(np.broadcast_to(shared, shape).copy())
        counts.append(rows["episodes"][order].reshape(shape))
    return MethodScores(method, tasks, tuple(runs), tuple(at), tuple(columns), tuple(counts))


def score_curves(episodes: Records, column: str = "metric", steps: Steps = "all") -> dict[str, MethodScores]:
    """Per method, its run-level scores at the checkpoint steps all its runs share: ``.array()`` is (runs, tasks,
    checkpoints). ``steps`` limits the checkpoints (a step or a list of steps)."""
    scores = _select_steps(run_scores(episodes, column), steps)
    found = {}
    for method in np.unique(scores["method"]).tolist():
        method_scores = _method_scores(scores.where(method=method), method, "all", f"method {method!r}")
        if method_scores is not None:
            found[method] = method_scores
    return found


def score_matrices(
    episodes: Records, step: int | Literal["last"] = "last", column: str = "metric"
) -> dict[str, MethodScores]:
    """Per method, its run-level scores at one step (or at each run's last checkpoint): ``.matrix()`` is (runs,
    tasks)."""
    scores = run_scores(episodes, column)
    if step != "last":
        scores = _select_steps(scores, int(step))
    found = {}
    for method in np.unique(scores["method"]).tolist():
        rows = scores.where(method=method)
        method_scores = _method_scores(rows, method, "last", f"method {method!r}")
        if method_scores is not None:
            found[method] = method_scores
    return found


def estimate(
    scores: MethodScores, task: str, reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> list[dict[str, Any]]:
    """IQM and stratified-bootstrap interval across the runs of ``scores`` at every checkpoint, as rows:
    method, task (the given label), step, iqm, low, high, runs, episodes."""
    point, low, high = stats.stratified_estimates(scores.columns, reps=reps, confidence=confidence, seed=seed)
    runs = sum(len(column) for column in scores.columns)
    episodes = None if scores.episodes is None else np.sum(np.concatenate(scores.episodes, axis=0), axis=0)
    return [
        {
            "method": scores.method,
            "task": task,
            "step": int(step),
            "iqm": float(point[k]),
            "low": float(low[k]),
            "high": float(high[k]),
            "runs": runs,
            "episodes": None if episodes is None else int(episodes[k]),
        }
        for k, step in enumerate(scores.checkpoints)
    ]


def aggregate(
    episodes: Records,
    column: str = "metric",
    steps: Steps = "all",
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
    overall: bool = True,
) -> list[dict[str, Any]]:
    """IQM and 95% stratified-bootstrap interval across runs, per method and task and, with ``overall``, per method
    over all its tasks (task ``"all"``, only for methods with several tasks).

    Rows: method, task, step, iqm, low, high, runs, episodes; sorted by method, task, step. ``steps``: ``"all"``
    (every checkpoint the runs share), ``"last"`` (each run's last checkpoint; the row's step is the largest of
    them, with a warning where runs differ), a step or a list of steps.
    """
    scores = _select_steps(run_scores(episodes, column), steps)
    rows: list[dict[str, Any]] = []
    for method in np.unique(scores["method"]).tolist():
        of_method = scores.where(method=method)
        tasks = np.unique(of_method["task"]).tolist()
        groups = [(task, of_method.where(task=task), f"method {method!r}, task {task!r}") for task in tasks]
        if overall and len(tasks) > 1:
            groups.append(("all", of_method, f"method {method!r}, all tasks"))
        for task, rows_of_group, label in groups:
            method_scores = _method_scores(rows_of_group, method, "last" if steps == "last" else "all", label)
            if method_scores is not None:
                rows += estimate(method_scores, task, reps=reps, confidence=confidence, seed=seed)
    return rows


def run_summary(episodes: Records) -> list[dict[str, Any]]:
    """Per run and checkpoint: episodes, ``mean`` and ``iqm`` of the return over the run's episodes, ``metric`` and
    ``metric_reference`` (means; None where empty). Sorted by run, then step."""
    keys, group = _groups(episodes, (*RUN_KEYS, "step"))
    order = np.argsort(group, kind="stable")
    bounds = np.searchsorted(group[order], np.arange(len(keys) + 1))
    rows = []
    for index in range(len(keys)):
        members = order[bounds[index] : bounds[index + 1]]
        first = members[0]
        returns = episodes["return"][members]
        rows.append(
            {
                "run": str(episodes["run"][first]),
                "method": str(episodes["method"][first]),
                "task": str(episodes["task"][first]),
                "env_id": str(episodes["env_id"][first]),
                "step": int(episodes["step"][first]),
                "episodes": len(members),
                "mean": float(np.mean(returns)),
                "iqm": stats.iqm(returns),
                "metric": _mean_or_none(episodes["metric"][members]),
                "metric_reference": _mean_or_none(episodes["metric_reference"][members]),
            }
        )
    return rows


def _mean_or_none(values: np.ndarray) -> float | None:
    present = values[np.isfinite(values)]
    return float(np.mean(present)) if len(present) else None


def summarize(
    episodes: Records, column: str = "metric", reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> dict[str, Any]:
    """What the evaluation writes to ``summary.json``: the per-run summary and the aggregate rows (JSON-ready)."""
    return {
        "runs": run_summary(episodes),
        "aggregate": aggregate(episodes, column=column, reps=reps, confidence=confidence, seed=seed),
        "aggregate_of": {
            "column": column,
            "statistic": "iqm",
            "interval": "stratified bootstrap, percentile",
            "confidence": confidence,
            "reps": reps,
            "seed": seed,
        },
    }


def training_curves(
    training: Records, column: str = "return", points: int = 100, smoothing: float = 0.02
) -> dict[tuple[str, str], MethodScores]:
    """Training curves per (method, task): every run's log smoothed lightly and read on one grid of steps.

    Each run's finite values of ``column`` are averaged over a centred window of ``smoothing`` x its updates (at least
    one), then interpolated linearly at ``points`` evenly spaced steps (fewer for short logs) from the latest first
    step to the earliest last step of the runs (runs that end earlier cut the curve, with a warning).
    """
    found: dict[tuple[str, str], MethodScores] = {}
    check_configs(training, "training logs")
    keys, _ = _groups(training, ("method", "task"))
    for method, task in zip(keys["method"].tolist(), keys["task"].tolist(), strict=True):
        rows = training.where(method=method, task=task)
        label = f"training of method {method!r}, task {task!r}"
        logs = {}
        for run in np.unique(rows["run"]).tolist():
            of_run = rows.where(run=run)
            order = np.argsort(of_run["step"], kind="stable")
            steps, values = of_run["step"][order].astype(np.float64), np.asarray(of_run[column], float)[order]
            keep = np.isfinite(values)
            if keep.any():
                logs[run] = (steps[keep], _moving_average(values[keep], max(1, round(smoothing * keep.sum()))))
        if not logs:
            _warn(f"{label}: column {column!r} is empty; left out")
            continue
        start = max(steps[0] for steps, _ in logs.values())
        ends = sorted({steps[-1] for steps, _ in logs.values()})
        if ends[0] < start:
            _warn(f"{label}: the runs' logs do not overlap; left out")
            continue
        if len(ends) > 1:
            _warn(
                f"{label}: logs end at different steps ({ends[0]:.0f} to {ends[-1]:.0f}); curves cut at {ends[0]:.0f}"
            )
        count = max(1, min(points, min(len(steps) for steps, _ in logs.values())))
        grid = np.linspace(start, ends[0], count)
        names = tuple(logs)
        column_values = np.stack([np.interp(grid, *logs[run]) for run in names])
        steps = np.broadcast_to(np.round(grid).astype(np.int64), column_values.shape).copy()
        found[(method, task)] = MethodScores(method, (task,), (names,), (steps,), (column_values,), None)
    return found


def _moving_average(values: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average; the window shrinks at the ends instead of padding."""
    if window <= 1:
        return values
    kernel = np.ones(window)
    return np.convolve(values, kernel, mode="same") / np.convolve(np.ones_like(values), kernel, mode="same")


def format_table(rows: Iterable[Mapping[str, Any]], columns: Sequence[str] | None = None) -> str:
    """Rows as an aligned text table (floats with 4 decimals)."""
    rows = list(rows)
    if not rows:
        return "(no rows)"
    columns = list(columns or rows[0])

    def cell(value: Any) -> str:
        if value is None:
            return "-"
        if isinstance(value, float):
            return f"{value:.4f}"
        return str(value)

    table = [columns] + [[cell(row.get(name)) for name in columns] for row in rows]
    widths = [max(len(line[i]) for line in table) for i in range(len(columns))]
    return "\n".join("  ".join(text.rjust(width) for text, width in zip(line, widths, strict=True)) for line in table)


def separation(rows: Sequence[Mapping[str, Any]], better: str, worse: str, step: int | None = None) -> dict[str, Any]:
    """Whether method ``better`` beats ``worse`` beyond doubt at ``step`` (default: the last step both have), per
    task: its 95% interval lies wholly above the other's (the intervals of :func:`aggregate` rows do not overlap).
    Returns ``{"step", "tasks": {task: {"better": row, "worse": row, "separated": bool}}, "separated": all}``."""
    by_key = {(row["method"], row["task"], row["step"]): row for row in rows if row["task"] != "all"}
    tasks = sorted({task for method, task, _ in by_key if method == better} & {t for m, t, _ in by_key if m == worse})
    if not tasks:
        raise ValueError(f"no task has aggregate rows of both {better!r} and {worse!r}")
    shared = set.intersection(*({s for m, t, s in by_key if m in (better, worse) and t == task} for task in tasks))
    if step is None:
        if not shared:
            raise ValueError(f"{better!r} and {worse!r} share no evaluated step")
        step = max(shared)
    found = {}
    for task in tasks:
        high, low = by_key.get((better, task, step)), by_key.get((worse, task, step))
        if high is None or low is None:
            raise ValueError(f"no aggregate rows of both {better!r} and {worse!r} for task {task!r} at step {step}")
        found[task] = {"better": dict(high), "worse": dict(low), "separated": bool(high["low"] > low["high"])}
    return {"step": step, "tasks": found, "separated": all(entry["separated"] for entry in found.values())}
