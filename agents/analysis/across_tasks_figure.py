"""The figure of a panel's aggregate across tasks (``summary.json``'s ``across_tasks``,
:func:`agents.analysis.across_tasks.across_tasks`), in the style of Agarwal et al. (2021): the IQM, mean and
optimality gap of the normalised final scores per method with their intervals; the probability of improvement of
each method over the reference method (GRU-PPO); and the run-score distributions (performance profiles) with their
bands. Method colours and labels are those of every other figure (:mod:`agents.analysis.plots`).
"""

from __future__ import annotations

import json
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agents.analysis.across_tasks import across_tasks
from agents.analysis.plots import _new_figure, method_colors, method_label, save_figure
from agents.analysis.results import read_episodes, task_options

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["across_tasks_figure", "plot_across_tasks"]

TITLE_CHARACTERS_PER_INCH = 12  # of figure width, at fontsize 10: erring narrow, so that a wrapped line fits
PANELS = (("iqm", "IQM"), ("mean", "Mean"), ("optimality_gap", "Optimality gap"))


def _intervals(axes: Axes, entries: Mapping[str, list[float]], colors: Mapping[str, str], title: str) -> None:
    """One row per method: the interval as a bar, the point estimate as a black tick."""
    methods = list(entries)
    for y, method in enumerate(methods):
        point, low, high = entries[method]
        axes.barh(y, max(high - low, 1e-9), left=low, height=0.6, color=colors[method], alpha=0.75)
        axes.vlines(point, y - 0.3, y + 0.3, color="black", linewidth=2)
    axes.set_yticks(range(len(methods)), [method_label(method) for method in methods])
    axes.set_ylim(-0.6, len(methods) - 0.4)
    axes.invert_yaxis()
    axes.set_title(title, fontsize=10)
    axes.grid(axis="x", alpha=0.3)


def across_tasks_figure(summary: Mapping[str, Any], colors: Mapping[str, str] | None = None) -> Figure:
    """The aggregate figure of ``summary`` (the ``across_tasks`` entry of a panel's summary.json)."""
    methods = summary["methods"]
    if not methods:
        raise ValueError("the summary across tasks holds no method (see its left_out and bounds)")
    colors = {**method_colors(methods), **(colors or {})}
    order = sorted(methods, key=lambda name: -methods[name]["iqm"][0])
    figure = _new_figure(12.0, 2.2 + 0.75 * len(order))
    panels = figure.subplot_mosaic([["iqm", "mean", "optimality_gap"], ["improvement", "profile", "profile"]])
    for key, title in PANELS:
        _intervals(panels[key], {m: methods[m][key] for m in order}, colors, title)
        panels[key].set_xlabel("normalised score")
    reference = summary["reference"]
    better = {
        m: methods[m][f"improvement_over_{reference}"] for m in order if f"improvement_over_{reference}" in methods[m]
    }
    axes = panels["improvement"]
    if better:
        _intervals(axes, better, colors, f"P(method > {method_label(reference)})")
        axes.axvline(0.5, color="grey", linestyle="--", linewidth=1)
        axes.set_xlim(0.0, 1.0)
    else:
        axes.set_visible(False)
    axes = panels["profile"]
    taus = summary["taus"]
    for method in order:
        profile = methods[method]["profile"]
        axes.plot(taus, profile["point"], color=colors[method], label=method_label(method), linewidth=1.8)
        axes.fill_between(taus, profile["low"], profile["high"], color=colors[method], alpha=0.2, linewidth=0)
    axes.set_xlabel(r"normalised score $\tau$")
    axes.set_ylabel(r"fraction of runs with score $> \tau$")
    axes.set_ylim(0.0, 1.0)
    axes.set_title("Performance profiles (run-score distributions)", fontsize=10)
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8, loc="upper right")
    tasks = ", ".join(summary["tasks"])
    waiting = summary.get("tasks_in_progress") or {}
    left = f"\n(left out while their runs train: {', '.join(sorted(waiting))})" if waiting else ""
    # Wrapped to the figure's width: a title wider than the figure is cut off at both sides, not shrunk.
    width = int(figure.get_figwidth() * TITLE_CHARACTERS_PER_INCH)
    lines = [f"Across {len(summary['tasks'])} tasks ({tasks}): final scores normalised per task", summary["interval"]]
    figure.suptitle("\n".join(textwrap.fill(line, width) for line in lines) + left, fontsize=10)
    return figure


def plot_across_tasks(
    directories: Sequence[str | Path], out: str | Path, column: str = "metric", reps: int = 2000, seed: int = 0
) -> list[Path]:
    """``across_tasks.png/.pdf`` in ``out`` for the records of ``directories`` when they hold two tasks or more and
    at least one method can be aggregated across them; otherwise nothing. The tasks a directory's ``summary.json``
    names in progress stay out, as in that summary. Returns the paths written."""
    episodes = read_episodes(*directories)
    in_progress = _tasks_in_progress(directories)
    summary = across_tasks(
        episodes, column, reps=reps, seed=seed, options=task_options(episodes, directories), in_progress=in_progress
    )
    if summary is None or not summary["methods"]:
        return []
    return save_figure(across_tasks_figure(summary), Path(out) / "across_tasks")


def _tasks_in_progress(directories: Sequence[str | Path]) -> dict[str, str]:
    """The ``across_tasks.tasks_in_progress`` of the directories' ``summary.json`` (a panel's results), merged."""
    found: dict[str, str] = {}
    for directory in directories:
        path = Path(directory) / "summary.json"
        if path.is_file():
            spanning = json.loads(path.read_text()).get("across_tasks") or {}
            found.update(spanning.get("tasks_in_progress") or {})
    return found
