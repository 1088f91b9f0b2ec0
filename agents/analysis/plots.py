"""Figures of evaluation results: sample-efficiency curves and final performance, IQM with 95% stratified-bootstrap
intervals across runs (:mod:`agents.analysis.scores`, :mod:`agents.analysis.stats`).

Figures are built on ``matplotlib.figure.Figure`` with an Agg canvas (no pyplot, no global backend switch; matplotlib
is imported inside the functions), returned for display and written as PNG and PDF through
:func:`agents.runtime.io.atomic_write_bytes`. Every method keeps one colour: the known agents have fixed colours, any
other method takes the next spare colour in the sorted order of the unknown names.

Methods are labelled as in the paper (PPO, GRU-PPO, 4-Stack, ...), tasks by their environment id and non-default
options (:func:`task_title`). An agent named after a memory (``gru``, ``trxl``, a variant such as ``gtrxl``) takes
its label, colour and place in legends from the memory's own file (the registry, :data:`agents.memory.MEMORY_SPECS`);
the agents that are no memory (PPO, the frame stacks, HELM) from this module's tables (:data:`METHOD_COLORS`,
:data:`METHOD_LABELS`, :data:`METHOD_PLACES`). Names the configs derive are read by rules: ``gru-stack4`` joins its
parts' labels, ``trxl_recon`` adds an auxiliary loss to its method's (:data:`SUFFIX_LABELS`).

A metric with a known range (:mod:`agents.analysis.metrics`: success and commands executed in [0, 1], counts from 0)
is shown on that whole range unless ``zoom`` is set, and a dashed line marks the task's chance level where the
metric table knows it for the task's options.
"""

from __future__ import annotations

import functools
import io
import json
import textwrap
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agents.analysis import results, scores
from agents.analysis.metrics import METRICS, SPEC_COLUMN, metric_of, read_metric_spec
from agents.runtime.io import atomic_write_bytes

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "METHOD_COLORS",
    "METHOD_LABELS",
    "METHOD_PLACES",
    "SPARE_COLORS",
    "SUFFIX_LABELS",
    "chance_level",
    "curves_figure",
    "final_figure",
    "known_methods",
    "method_colors",
    "method_label",
    "metric_label",
    "metric_range",
    "plot_results",
    "save_figure",
    "task_title",
]

# The agents that are no memory of the registry (a memory's colour, label and place are in its file, agents/memory/).
METHOD_COLORS = {  # Okabe-Ito, colour-blind safe; fixed per method in every figure
    "ppo": "#d55e00",  # vermillion
    "stack4": "#e69f00",  # orange
    "stack16": "#cc79a7",  # reddish purple
    "helm": "#56b4e9",  # sky blue
}
SPARE_COLORS = (  # for other methods, in this order: the rest of Paul Tol's muted scheme, then Okabe-Ito's yellow
    "#44aa99",
    "#999933",
    "#88ccee",
    "#cc6677",
    "#ddcc77",
    "#f0e442",
)
METHOD_LABELS = {  # the paper's names of these agents, keyed by the method names of configs/ (run.method, method)
    "ppo": "PPO",
    "stack4": "4-Stack",
    "stack16": "16-Stack",
    "helm": "HELM",
}
# Their places in legends among the memories' (MemorySpec.order: the built-ins take 0, 10, ..., 70): PPO with the
# memory-less one, the frame stacks and HELM after the recurrent memories (10, 20) and before the transformer (30).
METHOD_PLACES = {"ppo": 0, "stack4": 21, "stack16": 22, "helm": 23}
PART_LABELS = {"helm": "HELM"}  # parts of derived names such as gru-helm besides the memories' (and stackN)
SUFFIX_LABELS = {  # auxiliary losses that configs name as <method>_<suffix> (trxl_recon: "TrXL-PPO + recon.")
    "recon": "recon.",  # observation reconstruction (ppo.reconstruction_coef)
    "gt": "GT",  # ground-truth estimation (ppo.ground_truth_coef)
}
STEPS_LABEL = "Environment steps (millions)"
LEGEND_ENTRY_WIDTH = 1.75  # inches per legend column ("TrXL-PPO + recon." with its line), so a legend fits its figure
BAND_ALPHA = 0.2
RANGE_PAD = 0.03  # a fixed range is padded by this fraction, so that a curve at 0 or 1 stays visible
CHANCE_STYLE = {"color": "0.3", "linestyle": "--", "linewidth": 1.0, "zorder": 1.5}
CHANCE_LABEL = "chance"
TITLE_WIDTH = 52  # characters per line of a curves panel's title (4.6 inches wide)
FINAL_TITLE_WIDTH = 32  # and of a final-performance panel's (its axes take ~2.7 of its 4.2 inches)


@functools.cache
def known_methods() -> tuple[dict[str, str], dict[str, str], dict[str, str]]:
    """The fixed colours (in legend order), the labels and the part labels of the known methods: this module's
    agents and the memories of the registry (each memory's name and its variants' method names; the part label of a
    memory is its label without ``-PPO``). Legends order them by place (:data:`METHOD_PLACES`, ``MemorySpec.order``),
    this module's agents first at a shared place, then the registry's order."""
    from agents.memory import MEMORY_SPECS  # imported when a figure is drawn: reading results needs no torch

    places = [(place, 0, index, method) for index, (method, place) in enumerate(METHOD_PLACES.items())]
    places += [(spec.order, 1, index, spec.name) for index, spec in enumerate(MEMORY_SPECS.values())]
    fixed = {**METHOD_COLORS, **{spec.name: spec.colour for spec in MEMORY_SPECS.values()}}
    colours = {method: fixed[method] for *_, method in sorted(places)}
    labels = dict(METHOD_LABELS)
    parts = dict(PART_LABELS)
    for spec in MEMORY_SPECS.values():
        labels |= {spec.name: spec.label, **spec.variants}
        if not spec.stateless:  # a memory-less run is named after its other parts: none is never a part
            parts[spec.name] = spec.label.removesuffix("-PPO")
    return colours, labels, parts


def method_colors(methods: Iterable[str]) -> dict[str, str]:
    """A colour per method: the fixed colour of a known method (:func:`known_methods`), spare colours for the others
    in sorted order.

    The dict lists the known methods in legend order (:func:`known_methods`), then the others sorted: the order of
    legends and charts."""
    methods = set(methods)
    fixed = known_methods()[0]
    known = [method for method in fixed if method in methods]
    unknown = sorted(methods - set(known))
    return {
        **{method: fixed[method] for method in known},
        **{method: SPARE_COLORS[i % len(SPARE_COLORS)] for i, method in enumerate(unknown)},
    }


def method_label(method: str) -> str:
    """The readable name of a method: a known method's label (:func:`known_methods`); a name with an auxiliary
    loss's suffix (``trxl_recon``, ``gru_gt``: :data:`SUFFIX_LABELS`) adds it to its method's (``TrXL-PPO +
    recon.``); a derived name (``gru-stack4``, ``lstm-helm``) joins the labels of its parts (``GRU + 4-Stack``); any
    other name is shown as it is."""
    _, labels, part_labels = known_methods()
    if method in labels:
        return labels[method]
    base, _, suffix = method.rpartition("_")
    if base and suffix in SUFFIX_LABELS and method_label(base) != base:
        return f"{method_label(base)} + {SUFFIX_LABELS[suffix]}"
    parts = method.split("-")
    labels = []
    for part in parts:
        if part in part_labels:
            labels.append(part_labels[part])
        elif part.startswith("stack") and part[5:].isdigit():
            labels.append(f"{int(part[5:])}-Stack")
        else:
            return method
    return " + ".join(labels)


def task_title(env_id: str, options: Mapping[str, Any] | None, task: str = "") -> str:
    """A task's title: its environment id and non-default reset options (``MortarMayhem-Grid-v0, command_count=1``);
    with unknown options (None), the id and the task's name where it differs (``MortarMayhem-Grid-v0 (mm_grid_1)``)."""
    if options is None:
        return env_id if task in ("", env_id) else f"{env_id} ({task})"
    shown = []
    for key in sorted(options):
        value = options[key]
        if isinstance(value, list) and len(value) == 1:
            value = value[0]  # an option list with one entry is that value (command_count: [1])
        shown.append(f"{key}={json.dumps(value)}")
    return ", ".join([env_id, *shown])


def metric_range(
    env_id: str, column: str = "metric", spec: Mapping[str, Any] | None = None
) -> tuple[float | None, float | None]:
    """The (low, high) range of a column of the paper's metric (``metric``, ``metric_reference``) from the metric
    table, or from ``spec`` (the records' ``metric_spec``: a metric the table does not hold); (None, None) for other
    columns and ids without a metric."""
    if column == "metric" and spec:
        return spec["low"], spec["high"]
    if column in ("metric", "metric_reference") and env_id in METRICS:
        return METRICS[env_id].low, METRICS[env_id].high
    return None, None


def chance_level(env_id: str, options: Mapping[str, Any] | None, column: str = "metric") -> float | None:
    """The chance level of ``column`` for a task, from the metric table with the env's resolved options (``options``:
    the non-default ones, None if unknown); None for other columns (``metric_reference`` counts differently) and
    where it is unknown."""
    if column != "metric" or env_id not in METRICS:
        return None
    resolved = None
    if options is not None:
        from agents.config import resolved_options

        try:
            resolved = resolved_options(env_id, options)
        except ValueError:  # options of another version of the environment
            resolved = None
    return metric_of(env_id).chance_level(resolved)


def _complete(colors: dict[str, str] | None, methods: Iterable[str]) -> dict[str, str]:
    """The given colours, with :func:`method_colors` for any method they leave out."""
    defaults = method_colors(methods)
    if not colors:
        return defaults
    return {**colors, **{method: color for method, color in defaults.items() if method not in colors}}


def metric_label(env_id: str, column: str = "metric", spec: Mapping[str, Any] | None = None) -> str:
    """The axis label of a task's metric (from :data:`agents.analysis.metrics.METRICS`, or ``spec`` as in
    :func:`metric_range`); the column name for other columns."""
    if column == "metric" and spec:
        return spec["label"]
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


def _metric_specs(*tables: results.Records | None) -> dict[str, dict[str, Any]]:
    """task -> the ``metric_spec`` its records carry (tasks whose metric is in the table have none)."""
    found: dict[str, dict[str, Any]] = {}
    for table in tables:
        if table is not None and SPEC_COLUMN in table:
            for task, text in zip(table["task"].tolist(), table[SPEC_COLUMN].tolist(), strict=True):
                spec = read_metric_spec(text)
                if spec is not None:
                    found[task] = spec
    return found


def _titles(env_ids: Mapping[str, str], options: Mapping[str, Any]) -> dict[str, str]:
    """task -> title; tasks whose titles would coincide (the same options under two names) add their name."""
    titles = {task: task_title(env_id, options.get(task), task) for task, env_id in env_ids.items()}
    for task, title in titles.items():
        if list(titles.values()).count(title) > 1:
            titles[task] = f"{title} [{task}]"
    return titles


def _fix_range(axes: Axes, low: float | None, high: float | None, axis: str = "y") -> None:
    """Limit one axis to a metric's range, padded by :data:`RANGE_PAD` (an open end keeps the data's limit)."""
    get, set_ = (axes.get_ylim, axes.set_ylim) if axis == "y" else (axes.get_xlim, axes.set_xlim)
    if low is None and high is None:
        return
    current = get()
    bottom = current[0] if low is None else low
    top = current[1] if high is None else high
    pad = RANGE_PAD * ((top - bottom) or 1.0)
    set_(bottom - pad if low is not None else bottom, top + pad if high is not None else top)


def _decorate(
    axes: Axes, env_id: str, options: Any, column: str, zoom: bool, title: str, spec: Mapping[str, Any] | None = None
) -> bool:
    """Title, y label, the metric's range (unless ``zoom``) and the chance line of one curves panel; whether the
    chance line was drawn."""
    drawn = _draw_chance(axes, chance_level(env_id, options, column))
    if not zoom:
        _fix_range(axes, *metric_range(env_id, column, spec))
    axes.set_title(title, fontsize=10)
    axes.set_ylabel(metric_label(env_id, column, spec))
    return drawn


def _draw_chance(axes: Axes, chance: float | None, axis: str = "y") -> bool:
    if chance is None:
        return False
    line = axes.axhline(chance, **CHANCE_STYLE) if axis == "y" else axes.axvline(chance, **CHANCE_STYLE)
    line.set_label(CHANCE_LABEL)
    line.set_gid(CHANCE_LABEL)  # tests and scripts find the line by it
    return True


def _draw_curves(axes: Axes, rows: Sequence[dict[str, Any]], colors: dict[str, str]) -> set[str]:
    """IQM lines and interval bands per method; returns the methods drawn."""
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
    return present


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
    zoom: bool = False,
    options: Mapping[str, Mapping[str, Any] | None] | None = None,
) -> Figure:
    """Sample-efficiency curves, one row of panels per task: the training-seed ``training_column`` (left, when
    ``training`` is given; lightly smoothed, :func:`agents.analysis.scores.training_curves`) beside the novel-seed
    ``column`` (IQM and interval across runs at every checkpoint the runs share).

    A metric's axis spans its whole range unless ``zoom``; a dashed line marks the chance level where known.
    ``options``: task -> non-default env options (default: :func:`agents.analysis.results.task_options` of the records).
    The legend lists the methods drawn; methods drawn in no panel are named in a :class:`ResultsWarning`."""
    env_ids = _env_ids(episodes, training)
    specs = _metric_specs(episodes)
    tasks = sorted(env_ids)
    options = results.task_options(episodes) if options is None else options
    titles = _titles(env_ids, options)
    methods = set(episodes["method"].tolist()) | (set(training["method"].tolist()) if training is not None else set())
    colors = _complete(colors, methods)
    columns = 2 if training is not None else 1
    figure = _new_figure(4.6 * columns, 3.0 * len(tasks) + 0.6)
    panels = figure.subplots(len(tasks), columns, squeeze=False)
    drawn: set[str] = set()
    chance_drawn = False
    for row, task in enumerate(tasks):
        env_id = env_ids[task]
        title = textwrap.fill(titles[task], TITLE_WIDTH)
        novel = panels[row, -1]
        of_task = episodes.where(task=task)
        rows = (
            scores.aggregate(of_task, column, reps=reps, confidence=confidence, seed=seed, overall=False)
            if len(of_task)
            else []
        )
        drawn |= _draw_curves(novel, rows, colors)
        novel_title = f"{title}: novel seeds"
        chance_drawn |= _decorate(novel, env_id, options.get(task), column, zoom, novel_title, specs.get(task))
        if training is not None:
            left = panels[row, 0]
            curves = scores.training_curves(training.where(task=task), column=training_column, points=points)
            rows = [
                estimate
                for (_, curve_task), method_scores in curves.items()
                for estimate in scores.estimate(method_scores, curve_task, reps=reps, confidence=confidence, seed=seed)
            ]
            drawn |= _draw_curves(left, rows, colors)
            title_left = f"{title}: training seeds"
            chance_drawn |= _decorate(left, env_id, options.get(task), training_column, zoom, title_left)
        for axes in panels[row]:
            axes.set_xlabel(STEPS_LABEL if row == len(tasks) - 1 else "")
    missing = [method for method in colors if method in methods and method not in drawn]
    if missing:
        named = ", ".join(f"{method!r} ({method_label(method)})" for method in missing)
        warnings.warn(
            f"curves: method(s) {named} drawn in no panel (their runs share no checkpoint step, or their scores are "
            "empty): left out of the figure and its legend",
            results.ResultsWarning,
            stacklevel=2,
        )
    _legend(figure, {method: color for method, color in colors.items() if method in drawn}, confidence, chance_drawn)
    return figure


def _legend(figure: Figure, colors: dict[str, str], confidence: float = 0.95, chance: bool = False) -> None:
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=color, linewidth=2, label=method_label(method)) for method, color in colors.items()]
    if chance:
        handles.append(Line2D([], [], **CHANCE_STYLE, label=CHANCE_LABEL))
    figure.legend(
        handles=handles,
        loc="outside upper center",
        ncols=max(1, min(len(handles), int(figure.get_figwidth() // LEGEND_ENTRY_WIDTH))),
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
    zoom: bool = False,
    options: Mapping[str, Mapping[str, Any] | None] | None = None,
) -> Figure:
    """Final performance, one panel per task: per method, the IQM (black tick) and interval (bar) across runs at each
    run's last checkpoint. A metric's axis spans its whole range unless ``zoom`` (then it is fitted to the
    intervals); a dashed line marks the chance level where known (``options`` as in :func:`curves_figure`)."""
    env_ids = _env_ids(episodes)
    specs = _metric_specs(episodes)
    tasks = sorted(env_ids)
    options = results.task_options(episodes) if options is None else options
    titles = _titles(env_ids, options)
    colors = _complete(colors, episodes["method"].tolist())
    rows = scores.aggregate(episodes, column, steps="last", reps=reps, confidence=confidence, seed=seed, overall=False)
    columns = min(3, len(tasks))
    grid_rows = -(-len(tasks) // columns)
    present = {row["method"] for row in rows}
    methods = [method for method in colors if method in present]
    figure = _new_figure(4.2 * columns, 0.9 + (0.45 * len(methods) + 0.9) * grid_rows)
    panels = figure.subplots(grid_rows, columns, squeeze=False)
    for axes in panels.flat[len(tasks) :]:
        axes.set_visible(False)
    for axes, task in zip(panels.flat, tasks, strict=False):
        env_id = env_ids[task]
        mine = {row["method"]: row for row in rows if row["task"] == task}
        for y, method in enumerate(methods):
            if method not in mine:
                continue
            row = mine[method]
            width = max(row["high"] - row["low"], 1e-9)
            axes.barh(y, width, left=row["low"], height=0.6, color=colors[method], alpha=0.75)
            axes.vlines(row["iqm"], y - 0.3, y + 0.3, color="black", linewidth=2)
        axes.set_yticks(range(len(methods)), [method_label(method) for method in methods])
        chance = chance_level(env_id, options.get(task), column)
        _draw_chance(axes, chance, axis="x")
        if mine:  # bars pin the x limits at their ends (sticky edges), so margins would not show an interval at 0 or 1
            low = min(row["low"] for row in mine.values())
            high = max(row["high"] for row in mine.values())
            if chance is not None:
                low, high = min(low, chance), max(high, chance)
            pad = 0.08 * ((high - low) or max(abs(high), 1.0))
            axes.set_xlim(low - pad, high + pad)
        if not zoom:
            _fix_range(axes, *metric_range(env_id, column, specs.get(task)), axis="x")
        axes.set_ylim(-0.6, len(methods) - 0.4)
        axes.invert_yaxis()
        axes.set_xlabel(metric_label(env_id, column, specs.get(task)))
        steps = sorted({row["step"] for row in mine.values()})
        at = f"{steps[0] / 1e6:.3g}M steps" if len(steps) == 1 else "each run's last checkpoint"
        axes.set_title(textwrap.fill(f"{titles[task]} ({at})", FINAL_TITLE_WIDTH), fontsize=10)
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
    zoom: bool = False,
) -> list[Path]:
    """Read results directories and write ``curves.png/.pdf`` and ``final.png/.pdf`` into ``out``; returns the paths.

    Both figures share one colour per method. A metric's axis spans its whole range unless ``zoom``. The tasks'
    options (titles, chance levels) come from the records or, for older records, the runs' saved configs.
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
    options = results.task_options(loaded.episodes, directories)
    shared = {"reps": reps, "confidence": confidence, "seed": seed, "zoom": zoom, "options": options}
    out = Path(out)
    curves = curves_figure(loaded.episodes, loaded.training, column, training_column, colors, **shared)
    final = final_figure(loaded.episodes, column, colors, **shared)
    return save_figure(curves, out / "curves") + save_figure(final, out / "final")
