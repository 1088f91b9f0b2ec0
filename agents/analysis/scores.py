"""Scores across runs: run-level scores, score matrices and curves, IQM aggregates with stratified-bootstrap
intervals, the per-run summary of ``summary.json``, training curves, and text tables.

The paper's protocol: a run's score at a checkpoint is the mean of its episodes (30 novel seeds x 5 repetitions);
runs are aggregated with the interquartile mean and a 95% stratified-bootstrap interval (:mod:`agents.analysis.stats`).
Runs of one method that were evaluated at different checkpoints are compared only at the steps they share, with a
:class:`~agents.analysis.results.ResultsWarning` saying what was left out. numpy and the standard library only.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from agents.analysis import stats
from agents.analysis.results import RUN_KEYS, Records, check_configs, run_ids, warn

Steps = Literal["all", "last"] | int | Sequence[int]


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
        warn(f"column {column!r} is empty for {int(empty.sum())} run/step pair(s) (runs {', '.join(runs)}): left out")
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
    ids = run_ids(scores)
    lacking = [run for run in np.unique(ids) if not np.all(np.isin(wanted, scores["step"][ids == run]))]
    if lacking:
        warn(f"run(s) {', '.join(lacking)} have no episodes at some of the step(s) {wanted.tolist()}: left out there")
    return scores.select(np.isin(scores["step"], wanted))


def _shared_steps(scores: Records, label: str) -> np.ndarray:
    """The steps at which every run of ``scores`` has a score; warns about the others."""
    ids = run_ids(scores)
    runs = np.unique(ids)
    per_run = {run: np.unique(scores["step"][ids == run]) for run in runs}
    shared = per_run[runs[0]]
    for run_steps in per_run.values():
        shared = np.intersect1d(shared, run_steps)
    every = np.unique(scores["step"])
    if len(shared) < len(every):
        dropped = np.setdiff1d(every, shared)
        counts = ", ".join(f"{run}: {len(per_run[run])}" for run in runs)
        warn(
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
            # Tasks may have different budgets; only runs of one task ending apart are worth a word.
            ends = np.unique(last)
            if len(ends) > 1:
                warn(
                    f"{label}, task {task!r}: runs end at different steps ({', '.join(map(str, ends))}); each run's "
                    "last is taken"
                )
            runs.append(tuple(names.tolist()))
            columns.append(rows["score"][picked][:, None])
            at.append(np.asarray(last, dtype=np.int64)[:, None])
            counts.append(rows["episodes"][picked][:, None])
        return MethodScores(method, tasks, tuple(runs), tuple(at), tuple(columns), tuple(counts))
    shared = _shared_steps(scores, label)
    if len(shared) == 0:
        warn(f"{label}: the runs share no checkpoint step; left out")
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
            warn(f"{label}: column {column!r} is empty; left out")
            continue
        start = max(steps[0] for steps, _ in logs.values())
        ends = sorted({steps[-1] for steps, _ in logs.values()})
        if ends[0] < start:
            warn(f"{label}: the runs' logs do not overlap; left out")
            continue
        if len(ends) > 1:
            warn(f"{label}: logs end at different steps ({ends[0]:.0f} to {ends[-1]:.0f}); curves cut at {ends[0]:.0f}")
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
