"""The results table of an evaluated panel: ``python scripts/results_table.py results/cpu/suite/results``.

Reads the panel's ``summary.json`` (written by ``sweep.py --evaluate``) and prints Markdown: one row per method, one
column per task with the IQM of the final novel-seed metric and its 95% stratified-bootstrap interval (the last
evaluated step of that method on that task; the runs counted where fewer than the panel's most), and for a panel of
several tasks the aggregate across the tasks whose runs have all finished (IQM of the normalised scores with its
interval, and the probability of improvement over the reference, GRU-PPO). A second table gives each run's wall
time from ``run_info.json``: start to finish, less the pauses of a run stopped and resumed (marked). A process that
was stopped ends at the time ``run_info.json`` records (``stopped``), else at the last event it wrote to the run's
TensorBoard files, else (neither is committed with a run made before the record existed) after its updates at the
pace of the run's timed processes (marked estimated). ``--out FILE`` also writes both tables.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from datetime import datetime
from itertools import pairwise
from pathlib import Path
from typing import Any, NamedTuple

from agents.analysis.metrics import metric_of
from agents.analysis.plots import method_colors, method_label
from agents.runtime.io import atomic_write_text


def _interval(point: float, low: float, high: float, digits: int) -> str:
    return f"{point:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def _method_order(methods: set[str]) -> list[str]:
    return list(method_colors(methods))  # the figures' legend order


def final_scores(summary: dict[str, Any]) -> dict[str, dict[str, dict[str, Any]]]:
    """task -> method -> the ``aggregate`` entry of the method's last evaluated step on the task (not the rows of
    task ``all``, which pool a method's tasks)."""
    finals: dict[str, dict[str, dict[str, Any]]] = defaultdict(dict)
    for entry in summary["aggregate"]:
        if entry["task"] == "all":
            continue
        known = finals[entry["task"]].get(entry["method"])
        if known is None or entry["step"] > known["step"]:
            finals[entry["task"]][entry["method"]] = entry
    return dict(finals)


def scores_table(summary: dict[str, Any], digits: int = 2) -> str:
    finals = final_scores(summary)
    tasks = sorted(finals)
    env_ids = {run["task"]: run["env_id"] for run in summary["runs"]}
    spanning = summary.get("across_tasks") or {}
    aggregates = spanning.get("methods") or {}
    reference = spanning.get("reference", "gru")
    methods = _method_order({method for found in finals.values() for method in found})
    most = max(entry["runs"] for found in finals.values() for entry in found.values())  # the panel's seeds, or more
    header = [f"{task} ({metric_of(env_ids[task]).name.replace('_', ' ')})" for task in tasks]
    if aggregates:
        # while a task's runs train it is out of the aggregate: the column names the tasks it covers
        across = f"across {', '.join(spanning['tasks'])}" if spanning.get("tasks_in_progress") else "across tasks"
        header += [f"{across}: IQM (normalised)", f"P(better than {method_label(reference)})"]
    lines = ["| method | " + " | ".join(header) + " |", "|---" * (len(header) + 1) + "|"]
    for method in methods:
        cells = []
        for task in tasks:
            entry = finals[task].get(method)
            if entry is None:
                cells.append("")
                continue
            cell = _interval(entry["iqm"], entry["low"], entry["high"], digits)
            if entry["runs"] < most:  # an interval over fewer runs (over one run, a point)
                cell += f" ({entry['runs']} run{'' if entry['runs'] == 1 else 's'})"
            cells.append(cell)
        if aggregates:
            found = aggregates.get(method)
            cells.append(_interval(*found["iqm"], digits) if found else "")
            improvement = found.get(f"improvement_over_{reference}") if found else None
            cells.append(_interval(*improvement, digits) if improvement else "")
        lines.append(f"| {method_label(method)} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


class RunTime(NamedTuple):
    """A finished run's minutes of training, whether it was resumed, and whether a process's end was estimated."""

    minutes: float
    resumed: bool
    estimated: bool = False


def run_minutes(run_dir: Path) -> RunTime | None:
    """The training time of a finished run, else None.

    A run's processes start at ``run_info.json``'s ``time`` and at each ``resumed`` time; the last ends at
    ``finished``, every earlier one at its ``stopped`` time, else at the last event it wrote to the run's TensorBoard
    files, so the hours between a stop and the resume are left out. A process with neither is counted at the pace
    (minutes per update) of the run's timed processes, from the updates it added (``resumed`` entries' ``update``),
    and the result is marked estimated; without those update counts it counts nothing."""
    info_path = run_dir / "run_info.json"
    if not info_path.is_file():
        return None
    info = json.loads(info_path.read_text())
    if not info.get("finished"):
        return None
    resumed = info.get("resumed", [])
    starts = [_seconds(info["time"])] + [_seconds(entry["time"]) for entry in resumed]
    stopped = [_seconds(entry["time"]) for entry in info.get("stopped", [])]
    logged = event_wall_times(run_dir) if len(starts) > 1 else []
    unclaimed = sorted(stopped)
    ends: list[float | None] = []
    for start, next_start in pairwise(starts):
        # The times are whole seconds: a process stopped in the second the next one started stopped before it, so
        # its stop may equal the next start. A process stops once: the first stop not yet taken in its span is its own.
        own = next((t for t in unclaimed if start <= t <= next_start), None)
        if own is not None:
            unclaimed.remove(own)
            ends.append(own)
            continue
        recorded = [t for t in logged if start <= t < next_start]
        ends.append(max(recorded) if recorded else None)
    ends.append(_seconds(info["finished"]["time"]))
    first_updates = [0] + [entry.get("update") for entry in resumed]
    last_updates = first_updates[1:] + [info["finished"].get("update")]
    spans = [
        None if first is None or last is None else last - first
        for first, last in zip(first_updates, last_updates, strict=True)
    ]
    timed = [(end - start, span) for start, end, span in zip(starts, ends, spans, strict=True) if end and span]
    pace = sum(seconds for seconds, _ in timed) / sum(span for _, span in timed) if timed else None
    seconds, estimated = 0.0, False
    for start, end, span in zip(starts, ends, spans, strict=True):
        if end is not None:
            seconds += end - start
        elif span and pace is not None:
            seconds += span * pace
            estimated = True
    return RunTime(seconds / 60, len(starts) > 1, estimated)


def _seconds(iso_time: str) -> float:
    return datetime.fromisoformat(iso_time).timestamp()


def event_wall_times(run_dir: Path) -> list[float]:
    """The wall times (Unix seconds) of every event in ``run_dir``'s TensorBoard files."""
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

    return [
        event.wall_time
        for path in sorted(run_dir.glob("events.out.tfevents.*"))
        for event in EventFileLoader(str(path)).Load()
    ]


def wall_time_table(summary: dict[str, Any], root: Path) -> str:
    """Per method and task: the fastest and slowest run's minutes and the number of runs."""
    times: dict[tuple[str, str], list[RunTime]] = defaultdict(list)
    named = {run["run"]: (run["method"], run["task"]) for run in summary["runs"]}  # one entry per run and step
    for name, key in named.items():
        found = run_minutes(root / name)
        if found is not None:
            times[key].append(found)
    tasks = sorted({task for _, task in times})
    lines = ["| method | " + " | ".join(tasks) + " |", "|---" * (len(tasks) + 1) + "|"]
    total = 0.0
    for method in _method_order({method for method, _ in times}):
        cells = []
        for task in tasks:
            found = times.get((method, task), [])
            total += sum(time.minutes for time in found)
            if not found:
                cells.append("")
                continue
            low, high = min(time.minutes for time in found), max(time.minutes for time in found)
            span = f"{low:.0f}" if round(low) == round(high) else f"{low:.0f}-{high:.0f}"
            resumed, estimated = sum(time.resumed for time in found), sum(time.estimated for time in found)
            cells.append(
                f"{span} ({len(found)})"
                + (f", {resumed} resumed" if resumed else "")
                + (f" ({estimated} estimated)" if estimated else "")
            )
        lines.append(f"| {method_label(method)} | " + " | ".join(cells) + " |")
    lines.append(
        f"\nMinutes per run, start to finish less the pauses of resumed runs (runs). All runs: {total / 60:.1f}"
        " run-hours."
    )
    if any(time.estimated for found in times.values() for time in found):
        lines.append(
            "Estimated: a resumed run one of whose processes left no stop time in the run's committed records (made"
            " before run_info.json recorded it), counted at the pace of its timed processes."
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", type=Path, help="a panel's results directory, e.g. results/cpu/suite/results")
    parser.add_argument("--digits", type=int, default=2, help="decimals of the scores (default 2)")
    parser.add_argument("--out", type=Path, help="also write the tables to this file")
    args = parser.parse_args(argv)
    path = args.results / "summary.json"
    if not path.is_file():
        print(f"error: {path} not found: evaluate the panel first (sweep.py CONFIG --evaluate)", file=sys.stderr)
        return 2
    summary = json.loads(path.read_text())
    root = args.results.resolve().parent.parent  # <root>/<panel>/results; the runs are named from <root>
    text = scores_table(summary, args.digits) + "\n" + wall_time_table(summary, root)
    print(text, end="")
    if args.out is not None:
        atomic_write_text(args.out, text)
    return 0
