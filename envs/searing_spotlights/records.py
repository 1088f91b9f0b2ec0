"""Record layouts of a slot: its episode settings, its episode state and its spotlights (structured arrays, one
record per slot, bound to attribute views by :func:`envs.records.bind_fields`), and its map of touching positions."""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from envs.searing_spotlights.frames import ALPHA_STEPS
from envs.searing_spotlights.pictures import SCREEN

NEVER = np.iinfo(np.int64).max  # a step that never comes

# Per-episode settings of a slot, derived once per distinct set of options (see ``_episode_settings``).
SETTINGS = np.dtype(
    [
        ("end_t", np.int64),  # max_steps, or never
        ("pos_low", np.int64, (2,)),  # the agent centre is clamped into [low, high] (x, y)
        ("pos_high", np.int64, (2,)),
        ("vel", np.int64, (9, 2)),  # (dx, dy) per action code
        ("agent_radius", np.int64),
        ("agent_sprite0", np.int64),  # id of the heading-0 agent sprite in the core's SpriteScatter
        ("max_health", np.float64),
        ("spot_damage", np.float64),
        ("reward_inside", np.float64),
        ("reward_outside", np.float64),
        ("reward_death", np.float64),
        ("reward_coin", np.float64),
        ("reward_exit", np.float64),
        ("floor_kind", np.int64),
        ("red_feedback", bool),  # visual_feedback on a chessboard floor
        ("rings", bool),  # black_background: spotlights get a white outline
        ("alphas", np.int16, (ALPHA_STEPS,)),  # darkness alpha at step t (the last entry from then on)
        ("blend_until", np.int64),  # frames are blended before this step (partly transparent darkness, rings)
        ("spawn_interval", np.int64),
        ("hud_flags27", np.int64),  # 27 * (4 * endless + 2 * show_last_action + show_last_positive_reward)
        ("hud_next", np.int64),  # hud_flags27 + 1: the base of the next step's HUD code
        ("agent_hidden", bool),
        ("agent_key", np.int64),  # the hidden agent's part of the under key (see ``_update_under``), facing up
        ("heading_key", np.int64),  # what a heading step adds to it
        ("any_visible", bool),  # some entity is drawn above the darkness
        ("coins_visible", bool),
        ("coin_show_duration", np.int64),
        ("steps_per_coin", np.int64),
        ("use_exit", bool),
        ("coin_scale", np.float64),
        ("coin_sprite", np.int64),  # id of the coin sprite in the core's coin SpriteScatter
        ("coin_reach", np.int64),  # coin radius + agent radius
        ("exit_scale", np.float64),
        ("exit_reach", np.float64),  # exit radius + agent radius
    ],
    align=True,  # padded: every field aligned in every record (unaligned fields take slower numpy loops)
)

# The state of a slot's episode; a reset writes one start record per distinct option set (see ``_derive_settings``)
# and then the drawn level.
EPISODE = np.dtype(
    [
        ("t", np.int64),
        ("end_t_now", np.int64),  # the episode ends at this step (the endless coin clock moves it)
        ("heading", np.int64),
        ("pos", np.int64, (2,)),  # agent centre (x, y)
        ("health", np.float64),
        ("hud_red", np.int64),  # width of the red (lost health) part of the bar
        ("hit", bool),
        ("next_spawn", np.int64),
        ("spawns_left", np.int64),
        ("spot_count", np.int64),
        ("coins_collected", np.int64),
        ("coins_left", np.int64),
        ("num_coins", np.int64),
        ("coin_shown_until", np.int64),
        ("special_until", np.int64),  # entities are drawn above the darkness before this step
        ("success", np.int64),
        ("exit_x", np.int64),
        ("exit_y", np.int64),
        ("exit_open", bool),
        ("goal_without_exit", bool),  # no exit: the episode ends with the last coin
        ("next_hud", np.int64),
    ],
    align=True,  # padded: every field aligned in every record (unaligned fields take slower numpy loops)
)

# A slot's spotlights in list order. An unused position is never drawn (radius 0), never hits (negative reach),
# never moves (speed 0) and sits at the screen centre, inside the hole tables.
SPOTS = np.dtype(
    [
        ("radius", np.int64),
        ("base", np.intp),  # hole table offset of the radius
        ("reach", np.float64),  # hit distance: radius + agent radius
        ("speed", np.float64),
        ("tau", np.float64),
        ("start", np.complex128),
        ("target", np.complex128),
        ("offset", np.complex128),
        ("centre", np.complex128),  # where it was drawn in the last step
        ("done", bool),
        ("listed", bool),
        ("drawn", bool),
    ],
    align=True,  # padded: every field aligned in every record (unaligned fields take slower numpy loops)
)

# Bits of the per-slot item map: which coins (bits 0..9) and whether the exit (bit 14) touch an agent centred on a
# pixel; bit 15 asks for the exit to open at the next step (no coins at all).
EXIT_BIT, OPEN_EXIT_BIT = 1 << 14, 1 << 15


@cache
def touch_stamp(reach: float, bit: int) -> np.ndarray:
    """``bit`` on the offsets (-r..r in y and x) whose distance is at most ``reach``, computed like pygame's
    distance_to; 0 elsewhere."""
    r = int(math.floor(reach))
    offsets = np.arange(-r, r + 1)
    stamp = np.where(np.sqrt(offsets[None, :] ** 2 + offsets[:, None] ** 2) <= reach, bit, 0).astype(np.uint16)
    stamp.setflags(write=False)
    return stamp


def mark_touch(item_map: np.ndarray, x: int, y: int, reach: float, bit: int) -> None:
    """Set ``bit`` in the (84, 84) [y, x] map wherever an agent centre is within ``reach`` of (x, y)."""
    stamp = touch_stamp(float(reach), bit)
    r = stamp.shape[0] // 2
    top, left = y - r, x - r
    r0, c0 = max(top, 0), max(left, 0)
    r1, c1 = min(top + stamp.shape[0], SCREEN), min(left + stamp.shape[1], SCREEN)
    item_map[r0:r1, c0:c1] |= stamp[r0 - top : r1 - top, c0 - left : c1 - left]
