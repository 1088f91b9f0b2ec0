"""``SearingSpotlights-v0`` and ``Endless-SearingSpotlights-v0``, natively batched.

A dark room: moving spotlights reveal pieces of a chessboard floor and hurt the agent. In ``SearingSpotlights-v0``
the agent collects the coin(s) and then reaches the exit; in the endless variant (``endless=True``) it collects one
coin after another, each within ``steps_per_coin`` steps. The agent, the coins and the exit are drawn under the
darkness by default, so they are seen only inside a spotlight (and in the first, still lit frames).

How a frame is drawn, array-native across slots (frames are kept as (84, 252) byte rows). Most frames (darkness
alpha 255, no spotlight rings) are "black everywhere, the picture under the darkness inside the spotlight holes",
so a frame is ``hole_mask & under`` where

* ``lit`` is kept per slot and changes only when a coin is taken or the exit opens: the floor plus the coins and
  the exit, in a blue and a red (hit) version;
* ``under`` is kept per slot too: the blue or red ``lit`` with the hidden agent on top. It is rebuilt when ``lit``
  or the floor colour changes; an agent that moved or turned is erased (its rows copied back from ``lit``) and
  pasted again, all slots in one scatter;
* ``hole_mask`` is gathered row by row, straight into the frames, from one table of 0/255 rows, one row per
  horizontal span ``[lo, hi]``: every filled disc of pygame is a stack of such spans, so each spotlight
  contributes one table row per screen row. A screen row crossed by several spotlights gets the last span written
  to it, and the other spans are OR-ed into the gathered row afterwards.

Frames with a partly transparent darkness (the first steps while the light dims, ``light_threshold`` below 255)
or with spotlight rings (``black_background``) blend ``under`` with the darkness using SDL's arithmetic,
``D + trunc((S - D) * A / 255)``. The HUD rows come from small row tables.

A frame is a function of the state (the spotlights keep where they were drawn), so ``observations()`` hands the
frame buffer itself to the caller and the core continues in a new one; the few frames it must read before drawing
them again (a partial step or a reset leaves the others as they were) are drawn again from the state.

Mechanics per step are array operations as well: settings that depend only on the episode's options (velocities,
bounds, the alpha of every step, draw orders) are derived once per distinct option set; whether the agent touches a
coin or the exit is one lookup in a per-slot map of touching positions; spotlights are records in list order, with
neutral values in unused positions so that the common step needs no masks. Only resets, spawns, pickups and the
rare removal of finished spotlights run per slot.

The mechanics follow memory-gym 1.0.2 (see docs/environment_notes.md, "Searing Spotlights", for the quirks that are
kept and the few deliberate deviations).

Modules: ``core`` (the batched core; its state, step, reset and drawing stay in one class, which is what makes them
fast), ``options`` (reset options), ``records`` (the record layouts of a slot, its map of touching positions),
``pictures`` (geometry, colours, floors, coin, exit, rings), ``holes`` (the hole tables), ``sampler`` (the spawn
sampler, the spotlight orbits) and ``frames`` (blending, HUD rows, draw order, the darkness alpha of every step).
"""

from __future__ import annotations

from envs.records import (
    as_bytes,
)
from envs.searing_spotlights.core import (
    ACTION_HEADING,
    ACTION_PAIRS,
    ACTION_WEIGHTS,
    NEXT_HEADING,
    UNDER_KEY_POSITION,
    SearingSpotlightsCore,
)
from envs.searing_spotlights.frames import (
    ALPHA_STEPS,
    alpha_schedule,
    darken,
    draw_order,
    hud_tables,
    lighten,
    paint_hud_row,
    paste_centred,
    reset_hud_row,
)
from envs.searing_spotlights.holes import (
    HoleTables,
    hole_tables,
    span_code,
    span_rows,
)
from envs.searing_spotlights.options import (
    ESS_OPTIONS,
    SS_OPTIONS,
)
from envs.searing_spotlights.pictures import (
    ACTION_COLOURS,
    BLACK,
    BLUE,
    CENTRE,
    COIN_FILL,
    COIN_RIM,
    EXIT_CLOSED,
    EXIT_OPEN,
    FLOOR_BLACK,
    FLOOR_CHESS,
    FLOOR_WHITE,
    GREEN,
    HUD_GREY,
    HUD_ROWS,
    RED,
    ROW,
    ROW_BYTES,
    SCREEN,
    SPOT_ORBIT,
    TILE,
    WHITE,
    YELLOW,
    coin_sprite,
    exit_sprite,
    floor_pair,
    floor_rows,
    ring_mask,
)
from envs.searing_spotlights.records import (
    EPISODE,
    EXIT_BIT,
    NEVER,
    OPEN_EXIT_BIT,
    SETTINGS,
    SPOTS,
    mark_touch,
    touch_stamp,
)
from envs.searing_spotlights.sampler import (
    AGENT_BLOCK,
    ITEM_BLOCK,
    ITEM_HIGH,
    ITEM_LOW,
    SCREEN_CENTRE,
    block_position,
    clamp_item,
    orbit_points,
    sample_position,
)

__all__ = [
    "ACTION_COLOURS",
    "ACTION_HEADING",
    "ACTION_PAIRS",
    "ACTION_WEIGHTS",
    "AGENT_BLOCK",
    "ALPHA_STEPS",
    "BLACK",
    "BLUE",
    "CENTRE",
    "COIN_FILL",
    "COIN_RIM",
    "EPISODE",
    "ESS_OPTIONS",
    "EXIT_BIT",
    "EXIT_CLOSED",
    "EXIT_OPEN",
    "FLOOR_BLACK",
    "FLOOR_CHESS",
    "FLOOR_WHITE",
    "GREEN",
    "HUD_GREY",
    "HUD_ROWS",
    "HoleTables",
    "ITEM_BLOCK",
    "ITEM_HIGH",
    "ITEM_LOW",
    "NEVER",
    "NEXT_HEADING",
    "OPEN_EXIT_BIT",
    "RED",
    "ROW",
    "ROW_BYTES",
    "SCREEN",
    "SCREEN_CENTRE",
    "SETTINGS",
    "SPOTS",
    "SPOT_ORBIT",
    "SS_OPTIONS",
    "SearingSpotlightsCore",
    "TILE",
    "UNDER_KEY_POSITION",
    "WHITE",
    "YELLOW",
    "alpha_schedule",
    "as_bytes",
    "block_position",
    "clamp_item",
    "coin_sprite",
    "darken",
    "draw_order",
    "exit_sprite",
    "floor_pair",
    "floor_rows",
    "hole_tables",
    "hud_tables",
    "lighten",
    "mark_touch",
    "orbit_points",
    "paint_hud_row",
    "paste_centred",
    "reset_hud_row",
    "ring_mask",
    "sample_position",
    "span_code",
    "span_rows",
    "touch_stamp",
]
