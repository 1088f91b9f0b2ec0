"""Interquartile mean and stratified-bootstrap confidence intervals across runs (Agarwal et al. 2021).

Scores are arranged as in the paper's evaluation: one row per training run, one column per task, and for curves a
third axis of checkpoints. The point estimate is the interquartile mean (IQM) of all values: ``floor(n / 4)`` values
are dropped at each end of the sorted scores and the rest averaged (no fractional weights). The interval is the
percentile interval of a stratified bootstrap: every replicate redraws, within each task column on its own, as many
runs as the column has, with replacement, and takes the IQM of the redrawn matrix.

Everything is vectorised over replicates and seeded through ``numpy.random.default_rng(seed)``; no global state.
Checked against the ``rliable`` package in ``tests/agents/test_stats.py``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["curve_estimates", "interval_estimates", "iqm", "stratified_bootstrap", "stratified_estimates"]

_CHUNK_VALUES = 4_000_000  # float64 values gathered at once while bootstrapping (~32 MB)


def _finite(scores: ArrayLike, what: str = "scores") -> np.ndarray:
    array = np.asarray(scores, dtype=np.float64)
    if array.size == 0:
        raise ValueError(f"{what} are empty")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{what} contain NaN or infinite values")
    return array


def _trimmed_mean(values: np.ndarray) -> np.ndarray:
    """IQM along the last axis: ``floor(n / 4)`` values cut at each end; works on stacked replicates."""
    n = values.shape[-1]
    cut = n // 4
    if cut == 0:
        return values.mean(axis=-1)
    kept = np.partition(values, (cut, n - cut - 1), axis=-1)[..., cut : n - cut]
    return kept.mean(axis=-1)


def iqm(scores: ArrayLike) -> float:
    """The interquartile mean of all values of ``scores`` (shape (runs,) or (runs, tasks)).

    Equal to ``scipy.stats.trim_mean(scores, 0.25, axis=None)``, which rliable's ``aggregate_iqm`` calls.
    """
    return float(_trimmed_mean(_finite(scores).reshape(-1)))


def _as_columns(scores: ArrayLike, curve: bool) -> list[np.ndarray]:
    """A (runs, tasks) matrix or (runs, tasks, checkpoints) array as one (runs, checkpoints) array per task."""
    array = _finite(scores)
    if curve:
        if array.ndim != 3:
            raise ValueError(f"curves must have shape (runs, tasks, checkpoints), got {array.shape}")
        return [array[:, task, :] for task in range(array.shape[1])]
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2:
        raise ValueError(f"scores must have shape (runs,) or (runs, tasks), got {array.shape}")
    return [array[:, task, None] for task in range(array.shape[1])]


def _column_arrays(columns: Sequence[ArrayLike]) -> list[np.ndarray]:
    if len(columns) == 0:
        raise ValueError("no task columns")
    arrays = [_finite(column, f"scores of task column {task}") for task, column in enumerate(columns)]
    arrays = [array[:, None] if array.ndim == 1 else array for array in arrays]
    checkpoints = {array.shape[1:] for array in arrays}
    if any(array.ndim != 2 for array in arrays) or len(checkpoints) != 1:
        raise ValueError(
            "task columns must have shape (runs,) or (runs, checkpoints) with the same checkpoints, got "
            + ", ".join(str(array.shape) for array in arrays)
        )
    return arrays


def stratified_bootstrap(columns: Sequence[ArrayLike], reps: int = 2000, seed: int = 0) -> np.ndarray:
    """The IQMs of ``reps`` stratified-bootstrap replicates, shape (reps, checkpoints).

    ``columns`` holds one array per task of shape (runs,) or (runs, checkpoints); tasks may have different numbers of
    runs. Each replicate redraws, for every task independently, that task's runs with replacement; a redrawn run keeps
    its whole curve. The draws depend only on ``seed``, ``reps`` and the run counts, so a curve's replicates at one
    checkpoint are exactly the replicates of that checkpoint's matrix.
    """
    arrays = _column_arrays(columns)
    if reps < 1:
        raise ValueError(f"reps must be positive, got {reps}")
    rng = np.random.default_rng(seed)
    draws = [rng.integers(0, len(array), size=(reps, len(array))) for array in arrays]
    values = sum(len(array) for array in arrays)
    checkpoints = arrays[0].shape[1]
    chunk = max(1, _CHUNK_VALUES // (values * checkpoints))
    replicates = np.empty((reps, checkpoints))
    for start in range(0, reps, chunk):  # chunks of replicates bound the memory; each chunk is one array operation
        stop = min(reps, start + chunk)
        resampled = np.concatenate([array[draw[start:stop]] for array, draw in zip(arrays, draws, strict=True)], axis=1)
        replicates[start:stop] = _trimmed_mean(np.moveaxis(resampled, 1, -1))  # (chunk, checkpoints, values)
    return replicates


def stratified_estimates(
    columns: Sequence[ArrayLike], reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IQM and percentile interval per checkpoint of task columns with possibly different run counts.

    ``columns`` as in :func:`stratified_bootstrap`; returns (point, low, high), each of shape (checkpoints,).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    arrays = _column_arrays(columns)
    point = _trimmed_mean(np.concatenate(arrays, axis=0).T)
    replicates = stratified_bootstrap(arrays, reps=reps, seed=seed)
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(replicates, [tail, 100.0 - tail], axis=0)  # linear interpolation
    return point, low, high


def interval_estimates(
    score_dict: Mapping[str, ArrayLike], reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> dict[str, tuple[float, float, float]]:
    """IQM and ``confidence`` stratified-bootstrap interval for every method: name -> (point, low, high).

    ``score_dict`` maps a method name to its (runs, tasks) scores (a (runs,) array is one task). Every method is
    bootstrapped with its own ``default_rng(seed)``, so its interval does not depend on the other methods present.
    """
    estimates = {}
    for name, scores in score_dict.items():
        point, low, high = stratified_estimates(_as_columns(scores, curve=False), reps, confidence, seed)
        estimates[name] = (float(point[0]), float(low[0]), float(high[0]))
    return estimates


def curve_estimates(
    curve_dict: Mapping[str, ArrayLike], reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """IQM and interval per checkpoint for every method: name -> (point, low, high), each of shape (checkpoints,).

    ``curve_dict`` maps a method name to its (runs, tasks, checkpoints) scores. A replicate redraws whole runs (the
    same draw at every checkpoint); with the same ``seed``, checkpoint k gets exactly what :func:`interval_estimates`
    gives for the matrix ``scores[:, :, k]``.
    """
    return {
        name: stratified_estimates(_as_columns(scores, curve=True), reps, confidence, seed)
        for name, scores in curve_dict.items()
    }
