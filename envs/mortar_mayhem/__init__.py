"""The Mortar Mayhem family: ``MortarMayhem-v0``, ``MortarMayhem-Grid-v0``, ``MortarMayhemB-v0``,
``MortarMayhemB-Grid-v0`` and ``Endless-MortarMayhem-v0``, as one natively batched core.

The agent stands on an arena of 14-px tiles. A sequence of movement commands (right, down, ..., left_up) is shown one
icon at a time while the agent is frozen (the clue phase; the B variants give the commands as a vector instead).
Then, for each command in turn, the agent has ``explosion_delay`` (D) steps to reach the tile that the command leads
to from the previous target; at the check every other tile turns lethal for ``explosion_duration`` (E) steps. A check
passed pays ``reward_command_success``; standing elsewhere at a check or during the lethal phase ends the episode.
The check of command k happens at step ``t0 + D + (k - 1)(D + E)``, where t0 is the clue length (1 for the B
variants). The endless variant plays rounds on a 6x6 torus: each round replays the whole sequence plus one new
command, whose icon is shown before the lethal phase of the round's last check resumes.

The variants are parameters of :class:`MortarMayhemCore`: ``grid`` (Discrete(4) turn/forward control on tile
centres instead of MultiDiscrete([3, 3]) free movement), ``clue_phase``, ``vector_observation`` (the B variants' Dict
observation with the one-hot command vector), ``endless`` and ``spawn_jitter`` (a {-2..1} px spawn offset, drawn by
MMB and Endless MM only).

Quirks of memory-gym 1.0.2 that are kept because they change what an agent sees or what the metrics say:
failing the last check still reports ``success=1`` and ``commands_completed=1.0``; dying in a lethal phase reports
one command less than were rewarded; diagonal icons sit off-centre (rotated canvas, fixed corner); in the endless
variant a round's new command is appended even when its last check failed (``max_command_sequence`` +1), the tiles
stay red while the new icon is shown, and during a clue stream the agent keeps the sprite that was drawn last. Right
after a reset the reference's sprite drawn last is the previous episode's final one; here it is the new agent's, as on
a fresh instance, unless ``reference_carryover`` is set (the parity replays of traces recorded on reused instances).

Modules: ``core`` (the batched core: state, reset, step and drawing in one class), ``options`` (reset options),
``records`` (the record layout of a slot), ``commands`` (the command list and the walk that draws an episode's
commands), ``pictures`` (arena pictures, spawn frames, icons, agent sheets) and ``moves`` (the movement tables).
"""

from __future__ import annotations

from envs.mortar_mayhem.commands import (
    COMMAND_DELTAS,
    COMMAND_STEP,
    COMMANDS,
    ICON_ANGLE,
    MAX_VECTOR_COMMANDS,
    ONE_HOT,
    ONE_HOT_INDEX,
    command_walk,
    walk_commands,
)
from envs.mortar_mayhem.core import (
    CLUE_FPS,
    MortarMayhemCore,
)
from envs.mortar_mayhem.moves import (
    ACTIONS,
    CODE_WEIGHTS,
    COORD_MARGIN,
    COORD_SPAN,
    HEADING_SPRITE,
    FreeMoves,
    free_move_rows,
    grid_moves,
    wrap_torus,
)
from envs.mortar_mayhem.options import (
    option_specs,
    variant_name,
)
from envs.mortar_mayhem.pictures import (
    AGENT_SCALE,
    ENDLESS_ARENA,
    ICON_CORNER,
    RING_GREEN,
    TILE,
    TILE_BLUE,
    TILE_BLUE_BORDER,
    TILE_RED,
    TILE_RED_BORDER,
    SpawnFrames,
    agent_sheet,
    arena_left,
    arena_picture,
    backgrounds,
    icon_sheet,
    spawn_frames,
    target_ring,
)
from envs.mortar_mayhem.records import (
    AGENT_COLUMNS,
    SLOT_COLUMNS,
    SLOT_FIELDS,
    SLOT_LAYOUT,
    SLOT_WIDTH,
)

__all__ = [
    "ACTIONS",
    "AGENT_COLUMNS",
    "AGENT_SCALE",
    "CLUE_FPS",
    "CODE_WEIGHTS",
    "COMMANDS",
    "COMMAND_DELTAS",
    "COMMAND_STEP",
    "COORD_MARGIN",
    "COORD_SPAN",
    "ENDLESS_ARENA",
    "FreeMoves",
    "HEADING_SPRITE",
    "ICON_ANGLE",
    "ICON_CORNER",
    "MAX_VECTOR_COMMANDS",
    "MortarMayhemCore",
    "ONE_HOT",
    "ONE_HOT_INDEX",
    "RING_GREEN",
    "SLOT_COLUMNS",
    "SLOT_FIELDS",
    "SLOT_LAYOUT",
    "SLOT_WIDTH",
    "SpawnFrames",
    "TILE",
    "TILE_BLUE",
    "TILE_BLUE_BORDER",
    "TILE_RED",
    "TILE_RED_BORDER",
    "agent_sheet",
    "arena_left",
    "arena_picture",
    "backgrounds",
    "command_walk",
    "free_move_rows",
    "grid_moves",
    "icon_sheet",
    "option_specs",
    "spawn_frames",
    "target_ring",
    "variant_name",
    "walk_commands",
    "wrap_torus",
]
