"""The paper's metric per environment id: its name and the axis label the figures use.

Minimal version for the plots; the evaluation's version extends this file (keeping ``METRICS[id].name`` and
``METRICS[id].label``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Metric:
    """A task's metric: ``name`` (short, for tables and files) and ``label`` (for a figure's axis)."""

    name: str
    label: str


_COMMANDS = Metric("commands_executed", "Commands Executed")  # Mortar Mayhem: fraction of the commands executed
_SUCCESS = Metric("success", "Success Rate")
_PROGRESS = Metric("task_progress", "Task Progress")  # Searing Spotlights: coin 0.5, exit 1.0

METRICS: dict[str, Metric] = {
    "ProofOfMemory-v0": _SUCCESS,
    "MortarMayhem-v0": _COMMANDS,
    "MortarMayhem-Grid-v0": _COMMANDS,
    "MortarMayhemB-v0": _COMMANDS,
    "MortarMayhemB-Grid-v0": _COMMANDS,
    "Endless-MortarMayhem-v0": Metric("commands", "Commands Executed"),
    "MysteryPath-v0": _SUCCESS,
    "MysteryPath-Grid-v0": _SUCCESS,
    "Endless-MysteryPath-v0": Metric("tiles", "Tiles Visited"),
    "SearingSpotlights-v0": _PROGRESS,
    "Endless-SearingSpotlights-v0": Metric("coins", "Coins Collected"),
}
