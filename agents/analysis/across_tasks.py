"""Aggregates across tasks (Agarwal et al., NeurIPS 2021) of scores normalised per task, each with a
stratified-bootstrap interval: IQM, mean, median, optimality gap, the probability of improvement of one method over
another, and performance profiles (run-score distributions); and :func:`across_tasks`, what a panel of several tasks
writes to its ``summary.json`` (``across_tasks``).

Scores are (runs, tasks) matrices, one per method, normalised per task so that 0 is the task's floor (chance, or
memory-less PPO where the task has no chance level) and 1 its ceiling (the metric's maximum, or the best run's score
on an unbounded task): :func:`normalise`. A bootstrap replicate redraws, within each task column on its own, as many
runs as it has, with replacement, and recomputes the statistic (:func:`interval`); the probability of improvement
redraws both methods' runs independently (:func:`improvement_interval`). Intervals are percentile intervals of
``reps`` replicates drawn from ``numpy.random.default_rng(seed)``. The point estimates equal ``rliable``'s
(``metrics.aggregate_*``, ``probability_of_improvement``, ``library.create_performance_profile``), and the intervals
its intervals up to Monte-Carlo error (``tests/agents/analysis/test_across_tasks.py``). numpy only (the config is
imported where a task's options are resolved).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from agents.analysis.metrics import metric_of
from agents.analysis.results import Records, task_options
from agents.analysis.scores import score_matrices

__all__ = [
    "STATISTICS",
    "across_tasks",
    "aggregate_mean",
    "aggregate_median",
    "improvement_interval",
    "interval",
    "iqm",
    "method_aggregates",
    "normalise",
    "task_bounds",
    "optimality_gap",
    "probability_of_improvement",
    "score_profile",
]

Statistic = Callable[[np.ndarray], np.ndarray]  # (..., runs, tasks) -> (...)
_CHUNK_VALUES = 4_000_000  # values gathered at once while bootstrapping (~32 MB of float64)


def _matrix(scores: ArrayLike, what: str = "scores") -> np.ndarray:
    array = np.asarray(scores, dtype=np.float64)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2 or 0 in array.shape:
        raise ValueError(f"{what} must be a non-empty (runs, tasks) matrix, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{what} contain NaN or infinite values")
    return array


def normalise(scores: ArrayLike, low: ArrayLike, high: ArrayLike) -> np.ndarray:
    """(scores - low) / (high - low) per task column; ``low`` and ``high`` are one value per task (or one for all)."""
    matrix = _matrix(scores)
    low, high = np.broadcast_to(low, matrix.shape[1:]), np.broadcast_to(high, matrix.shape[1:])
    span = np.asarray(high, dtype=np.float64) - np.asarray(low, dtype=np.float64)
    if np.any(span <= 0):
        raise ValueError(f"every task's high must exceed its low, got low {low.tolist()}, high {high.tolist()}")
    return (matrix - low) / span


def iqm(values: np.ndarray) -> np.ndarray:
    """Interquartile mean of all runs x tasks values (the last two axes): floor(n / 4) cut at each end."""
    flat = values.reshape(*values.shape[:-2], -1)
    n = flat.shape[-1]
    cut = n // 4
    if cut == 0:
        return flat.mean(axis=-1)
    return np.partition(flat, (cut, n - cut - 1), axis=-1)[..., cut : n - cut].mean(axis=-1)


def aggregate_mean(values: np.ndarray) -> np.ndarray:
    """The mean over tasks of each task's mean over runs."""
    return values.mean(axis=-2).mean(axis=-1)


def aggregate_median(values: np.ndarray) -> np.ndarray:
    """The median over tasks of each task's mean over runs."""
    return np.median(values.mean(axis=-2), axis=-1)


def optimality_gap(values: np.ndarray, gamma: float = 1.0) -> np.ndarray:
    """How far the runs stay below the target ``gamma`` on average: gamma - mean(min(score, gamma))."""
    return gamma - np.minimum(values, gamma).reshape(*values.shape[:-2], -1).mean(axis=-1)


STATISTICS: dict[str, Statistic] = {
    "iqm": iqm,
    "mean": aggregate_mean,
    "median": aggregate_median,
    "optimality_gap": optimality_gap,
}


def _column_draws(rng: np.random.Generator, reps: int, runs: int, tasks: int) -> np.ndarray:
    """Run indices (reps, runs, tasks): each task column redrawn on its own, with replacement."""
    return rng.integers(0, runs, size=(reps, runs, tasks))


def _resampled(matrix: np.ndarray, draws: np.ndarray) -> np.ndarray:
    return np.take_along_axis(matrix[None], draws, axis=1)


def interval(
    scores: ArrayLike, statistic: Statistic, reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> tuple[float, float, float]:
    """(point, low, high): ``statistic`` of the (runs, tasks) ``scores`` and its stratified-bootstrap percentile
    interval. ``statistic`` maps (..., runs, tasks) arrays to (...), e.g. one of :data:`STATISTICS`."""
    matrix = _matrix(scores)
    replicates = _replicates(
        lambda rng, n: statistic(_resampled(matrix, _column_draws(rng, n, *matrix.shape))), matrix.size, reps, seed
    )
    return _point_and_interval(float(statistic(matrix)), replicates, confidence)


def probability_of_improvement(x: ArrayLike, y: ArrayLike) -> float:
    """P(X > Y) averaged over tasks, ties counted half: per task, the share of (run of x, run of y) pairs in which x
    scores higher, plus half the share of equal pairs (the Mann-Whitney U statistic over nx * ny)."""
    return float(_improvement(_matrix(x, "x"), _matrix(y, "y")))


def _improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per leading index of (..., runs_x, tasks) and (..., runs_y, tasks): P(X > Y) + P(X = Y) / 2, task-averaged."""
    above = (x[..., :, None, :] > y[..., None, :, :]).mean(axis=(-3, -2))
    equal = (x[..., :, None, :] == y[..., None, :, :]).mean(axis=(-3, -2))
    return (above + 0.5 * equal).mean(axis=-1)


def improvement_interval(
    x: ArrayLike, y: ArrayLike, reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> tuple[float, float, float]:
    """(point, low, high) of :func:`probability_of_improvement` of ``x`` over ``y``; a replicate redraws the runs
    of both methods, task by task, independently."""
    mx, my = _matrix(x, "x"), _matrix(y, "y")
    if mx.shape[1] != my.shape[1]:
        raise ValueError(f"x and y must score the same tasks, got {mx.shape[1]} and {my.shape[1]} task columns")

    def replicate(rng: np.random.Generator, n: int) -> np.ndarray:
        rx = _resampled(mx, _column_draws(rng, n, *mx.shape))
        ry = _resampled(my, _column_draws(rng, n, *my.shape))
        return _improvement(rx, ry)

    replicates = _replicates(replicate, mx.shape[0] * my.shape[0] * mx.shape[1], reps, seed)
    return _point_and_interval(float(_improvement(mx, my)), replicates, confidence)


def score_profile(
    scores: ArrayLike, taus: Sequence[float], reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The run-score distribution (performance profile): for each threshold tau, the share of all runs x tasks
    scores above tau, with stratified-bootstrap intervals; (points, lows, highs), each of shape (len(taus),)."""
    matrix = _matrix(scores)
    thresholds = np.asarray(taus, dtype=np.float64)

    def profile(values: np.ndarray) -> np.ndarray:
        flat = values.reshape(*values.shape[:-2], -1)
        return (flat[..., None, :] > thresholds[:, None]).mean(axis=-1)

    replicates = _replicates(
        lambda rng, n: profile(_resampled(matrix, _column_draws(rng, n, *matrix.shape))),
        matrix.size * len(thresholds),
        reps,
        seed,
    )
    tail = 100.0 * (1.0 - _checked(confidence)) / 2.0
    low, high = np.percentile(replicates, [tail, 100.0 - tail], axis=0)
    return profile(matrix), low, high


def _checked(confidence: float) -> float:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    return confidence


def _replicates(draw: Callable[[np.random.Generator, int], np.ndarray], size: int, reps: int, seed: int) -> np.ndarray:
    """``reps`` replicates of ``draw(rng, n)`` (n replicates at a time, bounded in memory), from default_rng(seed)."""
    if reps < 1:
        raise ValueError(f"reps must be positive, got {reps}")
    rng = np.random.default_rng(seed)
    chunk = max(1, _CHUNK_VALUES // max(size, 1))
    return np.concatenate([draw(rng, min(chunk, reps - start)) for start in range(0, reps, chunk)])


def _point_and_interval(point: float, replicates: np.ndarray, confidence: float) -> tuple[float, float, float]:
    tail = 100.0 * (1.0 - _checked(confidence)) / 2.0
    low, high = np.percentile(replicates, [tail, 100.0 - tail])
    return point, float(low), float(high)


def method_aggregates(
    matrices: dict[str, np.ndarray],
    reference: str | None = None,
    taus: Sequence[float] | None = None,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> dict[str, object]:
    """The aggregates of several methods' normalised (runs, tasks) score matrices as plain data (for summary.json):
    per method every :data:`STATISTICS` entry as [point, low, high] and, when ``reference`` is one of them, the
    probability of improvement over it; and the run-score distributions at ``taus`` (default 0, 0.05, ..., the largest
    score rounded up to 0.05). Every estimate draws from its own ``default_rng(seed)``."""
    methods = {name: _matrix(scores, f"scores of {name}") for name, scores in matrices.items()}
    tasks = {matrix.shape[1] for matrix in methods.values()}
    if len(tasks) > 1:
        columns = {name: matrix.shape[1] for name, matrix in methods.items()}
        raise ValueError(f"every method needs the same tasks; task columns per method: {columns}")
    if taus is None:
        top = max(1.0, max(float(m.max()) for m in methods.values()))
        taus = np.round(np.arange(0.0, np.ceil(top / 0.05) * 0.05 + 1e-9, 0.05), 10)
    found: dict[str, object] = {"taus": [float(t) for t in taus], "methods": {}}
    for name, matrix in methods.items():
        entry: dict[str, object] = {
            statistic: list(interval(matrix, function, reps, confidence, seed))
            for statistic, function in STATISTICS.items()
        }
        if reference in methods and name != reference:
            entry[f"improvement_over_{reference}"] = list(
                improvement_interval(matrix, methods[reference], reps, confidence, seed)
            )
        points, lows, highs = score_profile(matrix, taus, reps, confidence, seed)
        entry["profile"] = {"point": points.tolist(), "low": lows.tolist(), "high": highs.tolist()}
        found["methods"][name] = entry
    return found


def task_bounds(
    finals: Mapping[str, Mapping[str, np.ndarray]],
    env_ids: Mapping[str, str],
    options: Mapping[str, Mapping[str, Any] | None],
    floor_method: str = "ppo",
) -> dict[str, dict[str, Any]]:
    """Per task, the score that normalises to 0 and the one that normalises to 1, with where each comes from.

    ``finals``: task -> method -> final run scores. 0 is the task's chance level where its metric has one (with the
    task's ``options``), else the mean final score of ``floor_method`` (memory-less PPO) on the task; 1 is the
    metric's maximum where it is bounded (success, commands executed, task progress: 1.0), else the best final run
    score of any method on the task (the endless tasks' counts). A task whose floor is unknown or not below its
    ceiling gets ``None``: it cannot be normalised."""
    from agents.config import resolved_options

    bounds: dict[str, dict[str, Any]] = {}
    for task, methods in finals.items():
        metric = metric_of(env_ids[task])
        low, low_from = None, None
        if options.get(task) is not None:
            try:
                low = metric.chance_level(resolved_options(env_ids[task], options[task]))
            except ValueError:  # options of another version of the environment
                low = None
            low_from = "chance" if low is not None else None
        if low is None and floor_method in methods:
            low, low_from = float(np.mean(methods[floor_method])), f"{floor_method} (mean final score)"
        if metric.high is not None:
            high, high_from = float(metric.high), f"{metric.name} maximum"
        else:
            high, high_from = float(max(np.max(s) for s in methods.values())), "best final run"
        usable = low is not None and high > low
        bounds[task] = {
            "metric": metric.name,
            "low": low,
            "low_from": low_from,
            "high": high,
            "high_from": high_from,
            "normalised": usable,
        }
    return bounds


def across_tasks(
    episodes: Records,
    column: str = "metric",
    floor_method: str = "ppo",
    reference: str = "gru",
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
    options: Mapping[str, Mapping[str, Any] | None] | None = None,
    in_progress: Mapping[str, str] | None = None,
) -> dict[str, Any] | None:
    """The aggregate across the tasks of a panel (None for fewer than two tasks): every run's final score (its last
    checkpoint) normalised per task by :func:`task_bounds`, then per method that has the same number of runs on every
    normalisable task :func:`method_aggregates` (IQM, mean, median, optimality gap with intervals, the probability of
    improvement over ``reference`` and the run-score distribution). Methods left out are listed with the reason.

    ``in_progress``: task -> why (e.g. "1 of 15 runs finished"): tasks whose runs are still being trained stay out
    of the aggregate (listed as ``tasks_in_progress``), so that a suite filled in over several sessions keeps the
    aggregate of its finished tasks rather than dropping every method that has not reached the new task yet."""
    env_ids = {str(task): str(env) for task, env in zip(episodes["task"], episodes["env_id"], strict=True)}
    if len(env_ids) < 2:
        return None
    options = task_options(episodes) if options is None else options
    matrices = score_matrices(episodes, "last", column)
    finals: dict[str, dict[str, np.ndarray]] = {task: {} for task in sorted(env_ids)}
    for method, found in matrices.items():
        for task, scores in zip(found.tasks, found.columns, strict=True):
            finals[task][method] = scores[:, 0]
    bounds = task_bounds(finals, env_ids, options, floor_method)
    in_progress = {task: why for task, why in (in_progress or {}).items() if task in finals}
    tasks = [task for task in finals if bounds[task]["normalised"] and task not in in_progress]
    normalised: dict[str, np.ndarray] = {}
    left_out: dict[str, str] = {}
    for method in sorted(matrices):
        missing = [task for task in tasks if method not in finals[task]]
        counts = {len(finals[task][method]) for task in tasks if method in finals[task]}
        if missing:
            left_out[method] = f"no finished runs on {', '.join(missing)}"
        elif len(counts) != 1:
            left_out[method] = "different numbers of runs per task"
        else:
            columns = [finals[task][method] for task in tasks]
            lows = [bounds[task]["low"] for task in tasks]
            highs = [bounds[task]["high"] for task in tasks]
            normalised[method] = normalise(np.stack(columns, axis=1), lows, highs)
    summary: dict[str, Any] = {
        "tasks": tasks,
        "bounds": bounds,
        "reference": reference,
        "left_out": left_out,
        "tasks_in_progress": in_progress,
        "statistics": "per method over its runs x tasks of normalised final scores; [point, low, high]",
        "interval": f"stratified bootstrap over runs within each task, percentile, {confidence:.0%}, {reps} reps",
    }
    if len(tasks) < 2 or not normalised:
        summary["methods"] = {}
        return summary
    summary.update(method_aggregates(normalised, reference, reps=reps, confidence=confidence, seed=seed))
    return summary
