"""The record layout of a Mortar Mayhem slot: its integer state as one row of a table (see :mod:`envs.records`)."""

from __future__ import annotations

from envs.records import Columns

# The integer state of a slot, in one row per slot so that a reset writes a slot's whole state in one assignment;
# each field is a view of its columns (pairs: x and y, or column and row). (name, columns, what it holds)
SLOT_FIELDS = (
    ("num_commands", 1, "commands of the episode (of the current round, endless)"),
    ("allowed", 1, "the first k commands of the fixed list may be drawn"),
    ("size", 1, "arena side in tiles"),
    ("left", 1, "arena left/top edge in px"),
    ("lethal_steps", 1, "E"),
    ("act_steps", 1, "D"),
    ("max_steps", 1, "endless: the episode ends when t == max_steps"),
    ("grid_key", 1, "grid movement state (see grid_moves)"),
    ("move_key", 2, "free movement keys, one per axis (see FreeMoves)"),
    ("target", 2, "the tile the current command leads to"),
    ("target_id", 1, "8 * column + row of the target, compared with the agent's tile id"),
    ("current", 1, "checks so far in this round"),
    ("timer", 1, "steps to the next check (safe tiles) or release (lethal tiles)"),
    ("success", 1, "the last check is over"),
    ("completed_total", 1, "checks passed in the episode (over all rounds, endless)"),
    ("t", 1, "steps so far (endless)"),
    ("clue_pos", 1, "frame of the clue stream on screen"),
    ("clue_left", 1, "clue frames still to come"),
    ("stream_period", 1, "frames per command in the clue stream"),
    ("stream_duration", 1, "frames per command that show its icon"),
    ("debug_lag", 1, "the debug icon runs one frame ahead in the streams between rounds"),
    ("background_id", 1, "the arena picture in its current colours (index into backgrounds())"),
    ("shown", 6, "what the frame shows: background id, agent x, y, sprite and sheet, icon (-1 none)"),
    ("pos", 2, "agent centre in px"),
    ("sprite", 1, "agent sprite index (heading // 45)"),
    ("sheet_id", 1, "agent sprite sheet (agent_scale)"),  # pos, sprite, sheet_id last: `drawn` copies them
)
SLOT_LAYOUT = Columns(SLOT_FIELDS)
SLOT_COLUMNS = SLOT_LAYOUT.start  # first column of each field
SLOT_WIDTH = SLOT_LAYOUT.width
AGENT_COLUMNS = slice(SLOT_COLUMNS["pos"], SLOT_WIDTH)  # (x, y, sprite, sheet)
