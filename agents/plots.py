"""Figures of evaluation results: sample-efficiency curves and final performance, IQM with 95% stratified-bootstrap
intervals across runs (:mod:`agents.results`, :mod:`agents.stats`).

Figures are built on ``matplotlib.figure.Figure`` with an Agg canvas (no pyplot, no global backend switch; matplotlib
is imported inside the functions), returned for display and written as PNG and PDF through
:func:`agents.io.atomic_write_bytes`. Every method keeps one colour: the known agents have fixed Okabe-Ito colours,
any other method takes the next spare colour in the sorted order of the unknown names.
"""

from __future__ import annotations

import io
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agents import results
from agents.io import atomic_write_bytes
from agents.metrics import METRICS

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "METHOD_COLORS",
    "SPARE_COLORS",
    "curves_figure",
    "final_figure",
    "method_colors",
    "metric_label",
    "plot_results",
    "save_figure",
]

METHOD_COLORS = {  # Okabe-Ito, colour-blind safe; fixed per method in every figure
    "ppo": "#d55e00",  # vermillion
    "gru": "#0072b2",  # blue
    "lstm": "#009e73",  # bluish green
    "stack4": "#e69f00",  # orange
    "stack16": "#cc79a7",  # reddish purple
    "helm": "#56b4e9",  # sky blue
    "trxl": "#000000",  # black
}
SPARE_COLORS = (  # for other methods, in this order: Paul Tol's muted scheme, then Okabe-Ito's yellow
    "#332288",
    "#117733",
    "#882255",
    "#44aa99",
    "#999933",
    "#aa4499",
    "#88ccee",
    "#cc6677",
    "#ddcc77",
    "#f0e442",
)
STEPS_LABEL = "Environment steps (millions)"
BAND_ALPHA = 0.2


def method_colors(methods: Iterable[str]) -> dict[str, str]:
    """A colour per method: the fixed colour of a known method, spare colours for the others in sorted order.

    The dict lists the known methods in the order of :data:`METHOD_COLORS`, then the others sorted: the order of
    legends and charts."""
    methods = set(methods)
    known = [method for method in METHOD_COLORS if method in methods]
    unknown = sorted(methods - set(known))
    return {
        **{method: METHOD_COLORS[method] for method in known},
        **{method: SPARE_COLORS[i % len(SPARE_COLORS)] for i, method in enumerate(unknown)},
    }


def _complete(colors: dict[str, str] | None, methods: Iterable[str]) -> dict[str, str]:
    """The given colours, with :func:`method_colors` for any method they leave out."""
    defaults = method_colors(methods)
    if not colors:
        return defaults
    return {**colors, **{method: color for method, color in defaults.items() if method not in colors}}


def metric_label(env_id: str, column: str = "metric") -> str:
    """The axis label of a task's metric (from :data:`agents.metrics.METRICS`); the column name for other columns."""
    if column == "metric" and env_id in METRICS:
        return METRICS[env_id].label
    if column == "metric_reference" and env_id in METRICS:
        return f"{METRICS[env_id].label} (as the reference counts)"
    return column.replace("_", " ").capitalize()


def _new_figure(width: float, height: float) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _env_ids(*tables: results.Records | None) -> dict[str, str]:
    """task -> env id."""
    found: dict[str, str] = {}
    for table in tables:
        if table is not None:
            found.update(zip(table["task"].tolist(), table["env_id"].tolist(), strict=True))
    return found


def _draw_curves(axes: Axes, rows: Sequence[dict[str, Any]], colors: dict[str, str]) -> None:
    present = {row["method"] for row in rows}
    for method in (method for method in colors if method in present):
        mine = sorted((row for row in rows if row["method"] == method), key=lambda row: row["step"])
        steps = np.array([row["step"] for row in mine]) / 1e6
        low, high = np.array([row["low"] for row in mine]), np.array([row["high"] for row in mine])
        color = colors[method]
        axes.plot(steps, [row["iqm"] for row in mine], color=color, marker="o", markersize=3, linewidth=1.5)
        axes.fill_between(steps, low, high, color=color, alpha=BAND_ALPHA, linewidth=0)
    if not rows:
        axes.text(0.5, 0.5, "no data", transform=axes.transAxes, ha="center", va="center", color="grey")
    axes.grid(alpha=0.3)


def curves_figure(
    episodes: results.Records,
    training: results.Records | None = None,
    column: str = "metric",
    training_column: str = "return",
    colors: dict[str, str] | None = None,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
    points: int = 100,
) -> Figure:
    """Sample-efficiency curves, one row of panels per task: the training-seed ``training_column`` (left, when
    ``training`` is given; lightly smoothed, :func:`agents.results.training_curves`) beside the novel-seed ``column``
    (IQM and interval across runs at every checkpoint the runs share)."""
    env_ids = _env_ids(episodes, training)
    tasks = sorted(env_ids)
    methods = set(episodes["method"].tolist()) | (set(training["method"].tolist()) if training is not None else set())
    colors = _complete(colors, methods)
    columns = 2 if training is not None else 1
    figure = _new_figure(4.6 * columns, 3.0 * len(tasks) + 0.6)
    panels = figure.subplots(len(tasks), columns, squeeze=False)
    for row, task in enumerate(tasks):
        novel = panels[row, -1]
        of_task = episodes.where(task=task)
        rows = (
            results.aggregate(of_task, column, reps=reps, confidence=confidence, seed=seed, overall=False)
            if len(of_task)
            else []
        )
        _draw_curves(novel, rows, colors)
        novel.set_title(f"{task}: novel seeds", fontsize=10)
        novel.set_ylabel(metric_label(env_ids[task], column))
        if training is not None:
            left = panels[row, 0]
            curves = results.training_curves(training.where(task=task), column=training_column, points=points)
            rows = [
                estimate
                for (_, curve_task), scores in curves.items()
                for estimate in results.estimate(scores, curve_task, reps=reps, confidence=confidence, seed=seed)
            ]
            _draw_curves(left, rows, colors)
            left.set_title(f"{task}: training seeds", fontsize=10)
            left.set_ylabel(training_column.replace("_", " ").capitalize())
        for axes in panels[row]:
            axes.set_xlabel(STEPS_LABEL if row == len(tasks) - 1 else "")
    _legend(figure, colors, confidence)
    return figure


def _legend(figure: Figure, colors: dict[str, str], confidence: float = 0.95) -> None:
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=color, linewidth=2, label=method) for method, color in colors.items()]
    figure.legend(
        handles=handles,
        loc="outside upper center",
        ncols=min(len(handles), 7),
        frameon=False,
        title=f"IQM across runs, {confidence:.0%} stratified-bootstrap CI",
        title_fontsize=9,
    )


def final_figure(
    episodes: results.Records,
    column: str = "metric",
    colors: dict[str, str] | None = None,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Figure:
    """Final performance, one panel per task: per method, the IQM (black tick) and interval (bar) across runs at each
    run's last checkpoint."""
    env_ids = _env_ids(episodes)
    tasks = sorted(env_ids)
    colors = _complete(colors, episodes["method"].tolist())
    rows = results.aggregate(episodes, column, steps="last", reps=reps, confidence=confidence, seed=seed, overall=False)
    columns = min(3, len(tasks))
    grid_rows = -(-len(tasks) // columns)
    present = {row["method"] for row in rows}
    methods = [method for method in colors if method in present]
    figure = _new_figure(4.2 * columns, 0.9 + (0.45 * len(methods) + 0.9) * grid_rows)
    panels = figure.subplots(grid_rows, columns, squeeze=False)
    for axes in panels.flat[len(tasks) :]:
        axes.set_visible(False)
    for axes, task in zip(panels.flat, tasks, strict=False):
        mine = {row["method"]: row for row in rows if row["task"] == task}
        for y, method in enumerate(methods):
            if method not in mine:
                continue
            row = mine[method]
            width = max(row["high"] - row["low"], 1e-9)
            axes.barh(y, width, left=row["low"], height=0.6, color=colors[method], alpha=0.75)
            axes.vlines(row["iqm"], y - 0.3, y + 0.3, color="black", linewidth=2)
        axes.set_yticks(range(len(methods)), methods)
        if mine:  # bars pin the x limits at their ends (sticky edges), so margins would not show an interval at 0 or 1
            low = min(row["low"] for row in mine.values())
            high = max(row["high"] for row in mine.values())
            pad = 0.08 * ((high - low) or max(abs(high), 1.0))
            axes.set_xlim(low - pad, high + pad)
        axes.set_ylim(-0.6, len(methods) - 0.4)
        axes.invert_yaxis()
        axes.set_xlabel(metric_label(env_ids[task], column))
        steps = sorted({row["step"] for row in mine.values()})
        at = f"{steps[0] / 1e6:.3g}M steps" if len(steps) == 1 else "each run's last checkpoint"
        axes.set_title(f"{task} ({at})", fontsize=10)
        axes.grid(axis="x", alpha=0.3)
    separator = "\n" if columns == 1 else " "  # one panel is too narrow for the title on one line
    title = f"Final performance:{separator}IQM across runs, {confidence:.0%} stratified-bootstrap CI"
    figure.suptitle(title, fontsize=10)
    return figure


def save_figure(
    figure: Figure, stem: str | Path, formats: Sequence[str] = ("png", "pdf"), dpi: int = 150
) -> list[Path]:
    """Write ``figure`` as ``stem.png``, ``stem.pdf``, ... atomically; returns the paths."""
    written = []
    for fmt in formats:
        path = Path(f"{stem}.{fmt}")
        buffer = io.BytesIO()
        metadata = {"CreationDate": None} if fmt == "pdf" else None  # the same figure gives the same bytes
        figure.savefig(buffer, format=fmt, dpi=dpi, metadata=metadata)
        atomic_write_bytes(path, buffer.getvalue())
        written.append(path)
    return written


def plot_results(
    directories: Sequence[str | Path],
    out: str | Path,
    column: str = "metric",
    training_column: str = "return",
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> list[Path]:
    """Read results directories and write ``curves.png/.pdf`` and ``final.png/.pdf`` into ``out``; returns the paths.

    Both figures share one colour per method.
    """
    loaded = results.read_results(*directories)
    if column not in loaded.episodes:
        raise KeyError(f"no column {column!r} in episodes.csv; columns: {', '.join(loaded.episodes.names)}")
    if loaded.training is not None and training_column not in loaded.training:
        raise KeyError(f"no column {training_column!r} in training.csv; columns: {', '.join(loaded.training.names)}")
    methods = set(loaded.episodes["method"].tolist())
    if loaded.training is not None:
        methods |= set(loaded.training["method"].tolist())
    colors = method_colors(methods)
    options = {"reps": reps, "confidence": confidence, "seed": seed}
    out = Path(out)
    curves = curves_figure(loaded.episodes, loaded.training, column, training_column, colors, **options)
    final = final_figure(loaded.episodes, column, colors, **options)
    return save_figure(curves, out / "curves") + save_figure(final, out / "final")
