"""Reset options of the Mortar Mayhem variants (names and defaults of memory-gym 1.0.2, with valid ranges)."""

from __future__ import annotations

from envs.mortar_mayhem.commands import MAX_VECTOR_COMMANDS
from envs.mortar_mayhem.pictures import AGENT_SCALE
from envs.options import Option

# Upper bounds the reference does not check: larger values overflowed the int64 episode records or allocated the
# clue stream (count x (shown + blank) frames per slot) beyond memory; these are far above any published setting.
MAX_COMMANDS, MAX_CLUE_FRAMES, MAX_PHASE_STEPS = 100, 100, 10_000


def option_specs(grid: bool, clue_phase: bool, vector_observation: bool, endless: bool) -> dict[str, Option]:
    """The reset options of one variant, with the reference's names and defaults."""
    delay, duration = ([6], [2]) if grid else ([18], [6])
    specs: dict[str, Option] = {}
    if endless:
        specs["max_steps"] = Option(-1, "int", doc="the episode ends when t == max_steps; <= 0: never")
    specs["agent_scale"] = Option(
        AGENT_SCALE, "float", 0.04, 1.0, doc="sprite and collision size" + (" (ignored on the grid)" if grid else "")
    )
    if not grid:
        specs["agent_speed"] = Option(12.0 * AGENT_SCALE, "float", 0.0, 42.0, doc="pixels per step")
    if not endless:
        specs["arena_size"] = Option(5, "int", 2, 6, doc="tiles per side")
    specs["allowed_commands"] = Option(5 if grid else 9, "int", 4, 9, doc="the first k commands of the fixed list")
    if endless:
        specs["initial_command_count"] = Option(1, "int", 1, MAX_COMMANDS, doc="commands of the first round")
    else:
        high = MAX_VECTOR_COMMANDS if vector_observation else MAX_COMMANDS
        specs["command_count"] = Option([10], "int_list", 1, high, doc="number of commands (one entry sampled)")
    if clue_phase:
        specs["command_show_duration"] = Option([3], "int_list", 1, MAX_CLUE_FRAMES, doc="frames each icon is shown")
        specs["command_show_delay"] = Option([1], "int_list", 0, MAX_CLUE_FRAMES, doc="blank frames after each icon")
    specs["explosion_duration"] = Option(duration, "int_list", 1, MAX_PHASE_STEPS, doc="lethal steps (E)")
    specs["explosion_delay"] = Option(delay, "int_list", 1, MAX_PHASE_STEPS, doc="steps to reach the next target (D)")
    specs["visual_feedback"] = Option(True, "bool", doc="lethal tiles turn red")
    specs["reward_command_failure"] = Option(0.0, "float")
    specs["reward_command_success"] = Option(0.1, "float")
    if not endless:
        specs["reward_episode_success"] = Option(0.0, "float")
    return specs


def variant_name(grid: bool, vector_observation: bool, endless: bool) -> str:
    if endless:
        return "Endless-MortarMayhem-v0"
    return "MortarMayhem" + ("B" if vector_observation else "") + ("-Grid" if grid else "") + "-v0"
