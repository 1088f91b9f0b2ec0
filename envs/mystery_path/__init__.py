"""The Mystery Path family: ``MysteryPath-v0``, ``MysteryPath-Grid-v0`` and ``Endless-MysteryPath-v0``.

An invisible path of 12-px tiles leads across the screen. Stepping off it shows a red cross for one step, then the
agent is put back on the path's first tile (the action of that step is ignored). Each path tile pays
``reward_path_progress`` on its first visit.

* ``MysteryPath-v0`` / ``-Grid-v0`` (``endless=False``): one 7x7 level (:mod:`envs.mystery_path.generator`) from an
  origin on one border to a goal on the opposite one. Reaching the goal pays ``reward_goal`` and ends the episode;
  ``max_steps`` ends it too. The free variant moves 3 px per step (MultiDiscrete([3, 3])), the grid variant turns and
  steps one tile (Discrete(4)). The agent sees only itself (and, optionally, the origin and goal tiles).
* ``Endless-MysteryPath-v0`` (``endless=True``): 7x7 segments joined left to right by a transition tile, generated
  ahead of the agent. The camera follows the agent, which sees the path behind it but never ahead. Actions are
  Discrete(4): 0 none, 1 right, 2 up, 3 down. The episode ends after ``stamina_level`` steps without reaching a fresh
  tile, when the agent falls off behind its best column, or when it falls off twice at the same tile.

State lives in arrays with a leading slot axis, and the rules read per-episode tables built at reset (rewards by
tile kind, velocities by action, grid moves by state). Many slots are stepped with array operations; one or two
slots (the single-environment face) with the same rules one slot at a time, because a numpy call costs microseconds
whatever its size (tests keep both ways identical). Frames are drawn into a padded canvas (sprites near the edges
need no clipping): the static Mystery Path background is copied and the sprites are scattered in with one fancy
assignment per sprite kind; the scrolling Endless view is built band by band (every tile row of the screen consists
of one "edge" pixel row pattern and one "middle" pattern). Endless segments are generated from the reference's
random stream in the reference's order, but only when first needed (see ``MysteryPathCore._enter_segment``).

Modules: ``core`` (the batched core: state, reset, step and drawing in one class), ``options`` (reset options),
``level`` (grid, tiles, colours, controller tables), ``endless`` (segments, directions, the scrolling floor, stamina,
the past path behind the camera), ``canvas`` (the padded frames, the fall-off cross) and ``generator`` (the levels).
"""

from __future__ import annotations

from envs.mystery_path.canvas import (
    Canvas,
    fall_off_cross,
)
from envs.mystery_path.core import (
    SCALAR_SLOTS,
    MysteryPathCore,
)
from envs.mystery_path.endless import (
    BACKGROUND_EDGE,
    BACKGROUND_MIDDLE,
    BAND_PAD,
    BAND_WIDTH,
    BLACK_FLOOR,
    DEBUG_PATH_ALPHA,
    DIRECTION_OF_STEP,
    DIRECTIONS,
    EAST,
    ICE_COLOUR,
    INITIAL_SEGMENTS,
    NEW_TILE,
    NORTH,
    PATH_TILE,
    REFILL,
    SEGMENT_COLUMNS,
    SOUTH,
    STAMINA_BAR_WIDTH,
    STAMINA_BARS,
    STAMINA_GREEN,
    STAMINA_RED,
    TILE_BYTE_OFFSETS,
    TILE_EDGE_BYTES,
    TILE_MIDDLE_BYTES,
    WEST,
    ice_background,
    walk_start,
    walk_starts,
)
from envs.mystery_path.generator import (
    MysteryPathLayout,
    draw_level,
    draw_path,
    generate_path,
    level_grid,
    skip_level,
    skip_path,
)
from envs.mystery_path.level import (
    AFTER_VISIT,
    CROSS_COLOUR,
    ENDLESS_ACTIONS,
    ENDLESS_HEADINGS,
    FREE_ACTIONS,
    FREE_HEADINGS,
    GOAL,
    GOAL_COLOUR,
    GRID,
    GRID_AGENT_SCALE,
    GRID_NEXT,
    NEW,
    OFF,
    ORIGIN_COLOUR,
    PATH,
    PATH_COLOUR,
    TILE,
    TILE_BORDER,
    TILE_CENTRES,
    TILE_OF_PIXEL,
    WALL_COLOUR,
    fill_tile,
    velocities,
)
from envs.mystery_path.options import (
    option_specs,
)

__all__ = [
    "AFTER_VISIT",
    "BACKGROUND_EDGE",
    "BACKGROUND_MIDDLE",
    "BAND_PAD",
    "BAND_WIDTH",
    "BLACK_FLOOR",
    "CROSS_COLOUR",
    "Canvas",
    "DEBUG_PATH_ALPHA",
    "DIRECTION_OF_STEP",
    "DIRECTIONS",
    "EAST",
    "ENDLESS_ACTIONS",
    "ENDLESS_HEADINGS",
    "FREE_ACTIONS",
    "FREE_HEADINGS",
    "GOAL",
    "GOAL_COLOUR",
    "GRID",
    "GRID_AGENT_SCALE",
    "GRID_NEXT",
    "ICE_COLOUR",
    "INITIAL_SEGMENTS",
    "MysteryPathCore",
    "MysteryPathLayout",
    "NEW",
    "NEW_TILE",
    "NORTH",
    "OFF",
    "ORIGIN_COLOUR",
    "PATH",
    "PATH_COLOUR",
    "PATH_TILE",
    "REFILL",
    "SCALAR_SLOTS",
    "SEGMENT_COLUMNS",
    "SOUTH",
    "STAMINA_BARS",
    "STAMINA_BAR_WIDTH",
    "STAMINA_GREEN",
    "STAMINA_RED",
    "TILE",
    "TILE_BORDER",
    "TILE_BYTE_OFFSETS",
    "TILE_CENTRES",
    "TILE_EDGE_BYTES",
    "TILE_MIDDLE_BYTES",
    "TILE_OF_PIXEL",
    "WALL_COLOUR",
    "WEST",
    "draw_level",
    "draw_path",
    "fall_off_cross",
    "fill_tile",
    "generate_path",
    "ice_background",
    "level_grid",
    "option_specs",
    "skip_level",
    "skip_path",
    "velocities",
    "walk_start",
    "walk_starts",
]
