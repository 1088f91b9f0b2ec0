"""The paper's metric of every task, computed from an episode's final info.

Mortar Mayhem is scored by the fraction of commands executed, Mystery Path and the proof-of-memory task by the
success rate, Searing Spotlights by the task progress (coin 0.5, exit 1.0), and the endless tasks by the commands,
tiles or coins of an episode. Mortar Mayhem's own ``success`` and ``commands_completed`` keep a reference quirk (a
failed last check still counts as passed): ``metric`` counts only the checks actually passed (the environment's
``checks_passed``), while ``metric_reference`` keeps the figure the reference reports, for comparison with
published numbers.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

Info = Mapping[str, Any]


@dataclass(frozen=True)
class Metric:
    """A task's metric: its short ``name``, the axis ``label`` of plots, and how an episode's final info gives it
    (``value``: the paper's metric, corrected; ``reference``: as the reference reports it)."""

    name: str
    label: str
    value: Callable[[Info], float]
    reference: Callable[[Info], float]


def _key(name: str) -> Callable[[Info], float]:
    return lambda info: float(info[name])


def _commands_executed(info: Info) -> float:
    return info["checks_passed"] / info["command_count"]


def _task_progress(info: Info) -> float:
    """Searing Spotlights: 1.0 for leaving through the exit, else 0.5 per collected coin fraction (the paper's
    mapping: coin 0.5, exit 1.0)."""
    return 1.0 if info["success"] else 0.5 * float(info["coins_collected"])


SUCCESS = Metric("success", "Success Rate", _key("success"), _key("success"))
COMMANDS = Metric("commands_executed", "Commands Executed", _commands_executed, _key("commands_completed"))
ENDLESS_COMMANDS = Metric("commands_executed", "Commands Executed", _key("checks_passed"), _key("commands_completed"))
TILES = Metric("tiles_visited", "Tiles Visited", _key("tiles_visited"), _key("tiles_visited"))
PROGRESS = Metric("task_progress", "Task Progress", _task_progress, _task_progress)
COINS = Metric("coins_collected", "Coins Collected", _key("coins_collected"), _key("coins_collected"))

METRICS: dict[str, Metric] = {
    "ProofOfMemory-v0": SUCCESS,
    "MortarMayhem-v0": COMMANDS,
    "MortarMayhem-Grid-v0": COMMANDS,
    "MortarMayhemB-v0": COMMANDS,
    "MortarMayhemB-Grid-v0": COMMANDS,
    "Endless-MortarMayhem-v0": ENDLESS_COMMANDS,
    "MysteryPath-v0": SUCCESS,
    "MysteryPath-Grid-v0": SUCCESS,
    "Endless-MysteryPath-v0": TILES,
    "SearingSpotlights-v0": PROGRESS,
    "Endless-SearingSpotlights-v0": COINS,
}


def metric_of(env_id: str) -> Metric:
    """The metric of ``env_id``; an id without one in the table is scored by its return."""
    return METRICS.get(env_id, Metric("return", "Return", _key("reward"), _key("reward")))
