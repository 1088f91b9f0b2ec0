"""The paper's metric of every task, computed from an episode's final info.

Mortar Mayhem is scored by the fraction of commands executed, Mystery Path and the proof-of-memory task by the
success rate, Searing Spotlights by the task progress (coin 0.5, exit 1.0), and the endless tasks by the commands,
tiles or coins of an episode. Mortar Mayhem's own ``success`` and ``commands_completed`` keep a reference quirk (a
failed last check still counts as passed): ``metric`` counts only the checks actually passed (the environment's
``checks_passed``), while ``metric_reference`` keeps the figure the reference reports, for comparison with
published numbers.

Each metric also knows its range (plots fix their axis to it) and, where the task has one, its chance level: what a
policy without memory scores. The chance level may depend on the environment's reset options (all of them, the
defaults resolved); it is None where it is unknown, e.g. when the options are not known.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

Info = Mapping[str, Any]
Options = Mapping[str, Any]  # an environment's reset options, every one resolved (defaults included)


@dataclass(frozen=True)
class Metric:
    """A task's metric: its short ``name``, the axis ``label`` of plots, and how an episode's final info gives it
    (``value``: the paper's metric, corrected; ``reference``: as the reference reports it). ``low`` / ``high``: the
    range of its values (None: unbounded on that side); ``chance``: the chance level for the given options (None
    for unknown options), None where the task has no meaningful one."""

    name: str
    label: str
    value: Callable[[Info], float]
    reference: Callable[[Info], float]
    low: float | None = None
    high: float | None = None
    chance: Callable[[Options | None], float | None] | None = None

    def chance_level(self, options: Options | None) -> float | None:
        """The chance level of this metric with these resolved options; None where there is none or it is unknown."""
        return None if self.chance is None else self.chance(options)


def _key(name: str) -> Callable[[Info], float]:
    return lambda info: float(info[name])


def _commands_executed(info: Info) -> float:
    return info["checks_passed"] / info["command_count"]


def _task_progress(info: Info) -> float:
    """Searing Spotlights: 1.0 for leaving through the exit, else 0.5 per collected coin fraction (the paper's
    mapping: coin 0.5, exit 1.0)."""
    return 1.0 if info["success"] else 0.5 * float(info["coins_collected"])


def _guessed_commands(options: Options | None) -> float | None:
    """Mortar Mayhem with a clue phase: the expected fraction of commands executed by guessing every command
    uniformly among the ``allowed_commands`` (probability p = 1 / allowed), the episode ending at the first failed
    check: for n commands sum(p^k, k = 1..n) / n, averaged over the ``command_count`` entries (one is drawn per
    episode). One command out of the grid's five: 0.2. An agent without memory that reads its position off the frame
    can do slightly better at the arena's edge, where fewer commands are valid."""
    if options is None:
        return None
    p = 1.0 / options["allowed_commands"]
    counts = options["command_count"]
    return sum(sum(p**k for k in range(1, n + 1)) / n for n in counts) / len(counts)


SUCCESS = Metric("success", "Success Rate", _key("success"), _key("success"), low=0.0, high=1.0)
CUE_SUCCESS = dataclasses.replace(SUCCESS, chance=lambda options: 0.5)  # either side, whatever the options
COMMANDS = Metric(
    "commands_executed", "Commands Executed", _commands_executed, _key("commands_completed"), low=0.0, high=1.0
)
GUESSED_COMMANDS = dataclasses.replace(COMMANDS, chance=_guessed_commands)
ENDLESS_COMMANDS = Metric(
    "commands_executed", "Commands Executed", _key("checks_passed"), _key("commands_completed"), low=0.0
)
TILES = Metric("tiles_visited", "Tiles Visited", _key("tiles_visited"), _key("tiles_visited"), low=0.0)
PROGRESS = Metric("task_progress", "Task Progress", _task_progress, _task_progress, low=0.0, high=1.0)
COINS = Metric("coins_collected", "Coins Collected", _key("coins_collected"), _key("coins_collected"), low=0.0)

# Chance levels: the cue task's 0.5 and Mortar Mayhem's guessed commands (with a clue phase; the act-only B variants
# show the commands throughout in their vector observation, so guessing is no baseline there). Mystery Path,
# Searing Spotlights and the endless tasks have no closed-form chance level and draw none.
METRICS: dict[str, Metric] = {
    "ProofOfMemory-v0": CUE_SUCCESS,
    "MortarMayhem-v0": GUESSED_COMMANDS,
    "MortarMayhem-Grid-v0": GUESSED_COMMANDS,
    "MortarMayhemB-v0": COMMANDS,
    "MortarMayhemB-Grid-v0": COMMANDS,
    "Endless-MortarMayhem-v0": ENDLESS_COMMANDS,
    "MysteryPath-v0": SUCCESS,
    "MysteryPath-Grid-v0": SUCCESS,
    "Endless-MysteryPath-v0": TILES,
    "SearingSpotlights-v0": PROGRESS,
    "Endless-SearingSpotlights-v0": COINS,
}


RETURN = Metric("return", "Return", _key("reward"), _key("reward"))


def metric_of(env_id: str, custom: Any = None) -> Metric:
    """The metric of ``env_id``; an id without one in the table is scored by its return. ``custom``: the config's
    ``env.metric`` (``key``, ``label``, ``low``, ``high``); with a key, that entry of the final info is the metric."""
    if custom is not None and custom.key:
        value = _info_entry(custom.key, env_id)
        return Metric(custom.key, custom.label or custom.key, value, value, custom.low, custom.high)
    return METRICS.get(env_id, RETURN)


def _info_entry(name: str, env_id: str) -> Callable[[Info], float]:
    def value(info: Info) -> float:
        if name not in info:
            raise ValueError(
                f"env.metric.key={name!r} is not in the final info of {env_id}; its entries: {', '.join(sorted(info))}"
            )
        return float(info[name])

    return value


SPEC_COLUMN = "metric_spec"  # the records' column that describes a metric the table does not hold


def metric_spec(metric: Metric) -> str:
    """``metric``'s name, label and range as compact JSON: what the records of a task whose metric is not in
    :data:`METRICS` (a gymnasium environment's return, a config's ``env.metric``) carry in :data:`SPEC_COLUMN`, so
    that plots label and scale it as the run defined it."""
    fields = {"name": metric.name, "label": metric.label, "low": metric.low, "high": metric.high}
    return json.dumps(fields, separators=(",", ":"))


def read_metric_spec(text: str) -> dict[str, Any] | None:
    """The fields of :func:`metric_spec` (None for an empty cell: the table's metric)."""
    return json.loads(text) if text else None
