"""``SearingSpotlights-v0`` and ``Endless-SearingSpotlights-v0``, natively batched.

A dark room: moving spotlights reveal pieces of a chessboard floor and hurt the agent. In ``SearingSpotlights-v0``
the agent collects the coin(s) and then reaches the exit; in the endless variant (``endless=True``) it collects one
coin after another, each within ``steps_per_coin`` steps. The agent, the coins and the exit are drawn under the
darkness by default, so they are seen only inside a spotlight (and in the first, still lit frames).

How a frame is drawn, array-native across slots. Most frames (darkness alpha 255, no spotlight rings) are
"black everywhere, the lit picture inside the spotlight holes", so a frame is ``hole_mask & lit`` where

* ``lit`` is kept per slot and changes only when a coin is taken or the exit opens: the floor plus the coins and
  the exit, in a blue and a red (hit) version;
* ``hole_mask`` is gathered row by row from one table of 0/255 rows, one row per horizontal span ``[lo, hi]``:
  every filled disc of pygame is a stack of such spans, so each spotlight contributes one table row per screen row,
  and rows crossed by two or more spotlights are OR-ed in a few extra passes.

The agent (drawn under the darkness too) is pasted, masked by the holes, only in the slots where it is near a hole.
Frames with a partly transparent darkness (the first steps while the light dims, ``light_threshold`` below 255) or
with spotlight rings (``black_background``) blend the lit picture with the darkness using SDL's arithmetic,
``D + trunc((S - D) * A / 255)``. The HUD rows come from small precomputed row tables.

The mechanics follow memory-gym 1.0.2 (see docs/environment_notes.md, "Searing Spotlights", for the quirks that are
kept and the few deliberate deviations).
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import gymnasium as gym
import numpy as np

from envs.core import BatchedCore, Index
from envs.drawing import KEY_BLUE, Sprite, agent_sprites, disc_mask, pygame, surface_to_sprite
from envs.movement import clamp_centre, continuous_heading, continuous_velocity
from envs.options import Option

SCREEN = 84
ROW_BYTES = SCREEN * 3
HUD_ROWS = 4  # the top bar; the walkable area starts below it
TILE = 12  # chessboard square (int(50 * 0.25))
CENTRE = SCREEN // 2
SPOT_ORBIT = math.sqrt(SCREEN**2 + SCREEN**2) / 2  # spotlights start and end this far (+ radius) from the centre
AGENT_BLOCK, ITEM_BLOCK = 28, 21  # spawn sampler blocking radii (the endless coin uses 28)
ITEM_LOW, ITEM_HIGH = 7, SCREEN - 7  # coins and the exit are clamped into [7, 77]

WHITE, BLACK = (255, 255, 255), (0, 0, 0)
BLUE, RED, GREEN, YELLOW = (0, 0, 255), (255, 0, 0), (0, 255, 0), (255, 255, 0)
HUD_GREY = (50, 50, 50)
ACTION_COLOURS = ((120, 120, 120), (116, 1, 113), (255, 94, 14))
COIN_FILL, COIN_RIM = (255, 255, 0), (255, 165, 0)
EXIT_CLOSED, EXIT_OPEN = (55, 55, 55), (48, 141, 70)

FLOOR_CHESS, FLOOR_WHITE, FLOOR_BLACK = 0, 1, 2


def _common_options(endless: bool) -> dict[str, Option]:
    return {
        "max_steps": Option(-1 if endless else 256, "int", -1, None, doc="episode length cap; <= 0: no cap"),
        "initial_spawns": Option(3 if endless else 4, "int", 0, 256, doc="spotlights created at reset"),
        "spot_min_radius": Option(7.5, "float", 1, 42, doc="radius = integers(min, max + 1): an int in 7..13"),
        "spot_max_radius": Option(13.75, "float", 1, 42),
        "spot_min_speed": Option(0.0025, "float", 0, 1, doc="curve parameter advance per step"),
        "spot_max_speed": Option(0.0075, "float", 0, 1),
        "spot_damage": Option(1.0, "float", 0, None, doc="health lost per step while a spotlight touches the agent"),
        "visual_feedback": Option(True, "bool", doc="red chessboard on the steps the agent is hit"),
        "black_background": Option(False, "bool", doc="black floor; spotlights get a white 1-px ring"),
        "hide_chessboard": Option(False, "bool", doc="white floor"),
        "light_dim_off_duration": Option(6, "int", 0, None, doc="steps until full darkness; 0: dark at once"),
        "light_threshold": Option(255, "int", 0, 255, doc="darkness alpha stops at the first step above this"),
        "coin_scale": Option(0.375, "float", 0.1, 4.0, doc="coin radius int(10 * scale)"),
        "coins_visible": Option(False, "bool", doc="draw coins above the darkness"),
        "agent_speed": Option(3.0, "float", 0, 84),
        "agent_health": Option(10 if endless else 5, "int", 1, None),
        "agent_scale": Option(0.25, "float", 0.04, 1.0, doc="agent radius int(25 * scale)"),
        "agent_visible": Option(False, "bool", doc="draw the agent above the darkness"),
        "sample_agent_position": Option(True, "bool", doc="False: the agent starts at the centre (42, 42)"),
        "show_last_action": Option(True, "bool", doc="HUD blocks with the previous action"),
        "show_last_positive_reward": Option(True, "bool", doc="HUD block: was the previous reward positive"),
        "reward_inside_spotlight": Option(0.0, "float", doc="per step while hit"),
        "reward_outside_spotlight": Option(0.0, "float", doc="per step while not hit"),
        "reward_death": Option(0.0, "float", doc="when health reaches 0"),
        "reward_coin": Option(0.25, "float", doc="per coin"),
    }


SS_OPTIONS: dict[str, Option] = {
    **_common_options(endless=False),
    "num_spawns": Option(30, "int", 0, 100000, doc="spotlights spawned after reset, at most"),
    "initial_spawn_interval": Option(30, "float", 0, None, doc="spawn interval = int(this + threshold) = 40"),
    "spawn_interval_threshold": Option(10, "float", 0, None),
    "spawn_interval_decay": Option(0.95, "float", 0, 1, doc="accepted; never applied (as in memory-gym)"),
    "num_coins": Option([1], "int_list", 0, 10, allow_empty=True, doc="coin count, drawn from the list"),
    "use_exit": Option(True, "bool", doc="after the coins, the exit must be reached"),
    "exit_scale": Option(0.5, "float", 0.1, 4.0, doc="exit size 20 * scale"),
    "exit_visible": Option(False, "bool", doc="draw the exit above the darkness"),
    "reward_exit": Option(1.0, "float"),
    "reward_max_steps": Option(0.0, "float", doc="accepted; unused (as in memory-gym)"),
}
ESS_OPTIONS: dict[str, Option] = {
    **_common_options(endless=True),
    "steps_per_coin": Option(160, "int", -1, None, doc="steps allowed per coin; <= 0: no limit"),
    "spawn_interval": Option(50, "int", 1, None, doc="a spotlight spawns every this many steps"),
    "coin_show_duration": Option(6, "int", 0, None, doc="a new coin is drawn above the darkness this long"),
}


# ------------------------------------------------------------------------------------------------ pictures
def _rows(image: np.ndarray) -> np.ndarray:
    """(84, 84, 3) image -> (84, 252) rows, the layout frames are kept in."""
    return np.ascontiguousarray(image.reshape(image.shape[0], -1))


@cache
def floor_rows(kind: int, hit: bool) -> np.ndarray:
    """The floor as (84, 252) rows: the chessboard (blue squares, red on a hit step), white or black."""
    image = np.zeros((SCREEN, SCREEN, 3), dtype=np.uint8)
    if kind == FLOOR_WHITE:
        image[:] = WHITE
    elif kind == FLOOR_CHESS:
        squares = (np.arange(SCREEN) // TILE)[:, None] + (np.arange(SCREEN) // TILE)[None, :]
        image[:] = RED if hit else BLUE
        image[squares % 2 == 0] = WHITE
    rows = _rows(image)
    rows.setflags(write=False)
    return rows


class Planes:
    """A sprite as (h, 3w) colour rows and 0/255 mask rows, for masked pasting into (84, 252) frame rows."""

    __slots__ = ("rgb", "mask", "height", "width", "half_h", "half_w")

    def __init__(self, sprite: Sprite, centre: tuple[int, int]) -> None:
        self.rgb = _rows(sprite.rgb)
        self.mask = _rows(np.repeat(sprite.mask[:, :, None], 3, axis=2).astype(np.uint8) * 255)
        self.height, self.width = sprite.height, sprite.width
        self.half_h, self.half_w = centre  # the sprite's anchor (its centre pixel) inside the canvas

    def paste(self, rows: np.ndarray, x: int, y: int, where: np.ndarray | None = None) -> None:
        """Paste with the anchor at pixel (x, y), clipped; ``where`` (84, 252 of 0/255) restricts the pixels."""
        top, left = int(y) - self.half_h, int(x) - self.half_w
        r0, c0 = max(top, 0), max(left, 0)
        r1, c1 = min(top + self.height, SCREEN), min(left + self.width, SCREEN)
        if r0 >= r1 or c0 >= c1:
            return
        target = rows[r0:r1, 3 * c0 : 3 * c1]
        sr, sc = slice(r0 - top, r1 - top), slice(3 * (c0 - left), 3 * (c1 - left))
        mask = self.mask[sr, sc]
        if where is not None:
            mask = mask & where[r0:r1, 3 * c0 : 3 * c1]
        target ^= (target ^ self.rgb[sr, sc]) & mask


@cache
def agent_planes(scale: float) -> tuple[Planes, ...]:
    """The agent's eight heading sprites (index heading // 45), anchored at the canvas centre."""
    return tuple(Planes(s, (s.height // 2, s.width // 2)) for s in agent_sprites(scale))


@cache
def coin_planes(scale: float) -> Planes:
    """A coin: a yellow disc with an orange rim of width int(2 * scale); width 0 makes pygame fill it orange."""
    radius = int(10 * scale)
    size = 2 * radius + 2
    surface = pygame.Surface((size, size))
    surface.fill(KEY_BLUE)
    pygame.draw.circle(surface, COIN_FILL, (radius, radius), radius)
    pygame.draw.circle(surface, COIN_RIM, (radius, radius), radius, int(2 * scale))
    return Planes(surface_to_sprite(surface, KEY_BLUE), (radius, radius))


@cache
def exit_planes(scale: float, is_open: bool) -> Planes:
    """The exit door: rounded top corners, a 1-px black outline, grey while closed and green once open."""
    surface = pygame.Surface((20 * scale, 20 * scale))
    surface.fill(KEY_BLUE)
    rect = surface.get_rect()
    corners = (int(10 * scale), int(10 * scale), 0, 0)
    pygame.draw.rect(surface, EXIT_OPEN if is_open else EXIT_CLOSED, rect, 0, 0, *corners)
    pygame.draw.rect(surface, BLACK, rect, int(2 * scale), 0, *corners)
    return Planes(surface_to_sprite(surface, KEY_BLUE), (rect.height // 2, rect.width // 2))


@cache
def ring_mask(radius: int) -> np.ndarray:
    """Pixels of pygame's 1-px circle outline of ``radius`` (same frame as :func:`envs.drawing.disc_mask`)."""
    size = 2 * radius + 2
    surface = pygame.Surface((size, size))
    surface.fill(BLACK)
    pygame.draw.circle(surface, WHITE, (radius, radius), radius, 1)
    mask = pygame.surfarray.array3d(surface)[:, :, 0].T == 255
    mask.setflags(write=False)
    return mask


# ------------------------------------------------------------------------- spotlight holes as row spans
def span_code(lo: np.ndarray | int, hi: np.ndarray | int) -> np.ndarray | int:
    """Index of the span [lo, hi] (0 <= lo <= hi <= 83) in :func:`span_rows`; 0 is the empty span."""
    return lo * (2 * SCREEN - 1 - lo) // 2 + hi + 1


@cache
def span_rows() -> np.ndarray:
    """One 0/255 row of 252 bytes per span code: 255 on the three channels of the pixels lo..hi."""
    lo, hi = np.triu_indices(SCREEN)
    codes = span_code(lo, hi)
    table = np.zeros((int(codes.max()) + 1, ROW_BYTES), dtype=np.uint8)
    column = np.arange(ROW_BYTES) // 3
    table[codes] = np.where((column >= lo[:, None]) & (column <= hi[:, None]), 255, 0)
    table.setflags(write=False)
    return table


@cache
def disc_span_tables(max_radius: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Per radius, the rows of a filled disc as span codes, for every (clamped) centre column.

    Returns ``codes[r, cx + max_radius + 1, j]`` (the span code of disc row j, 0 when it is empty or off-screen),
    ``row_offset[r, j]`` (that row's offset from the centre row; far off-screen for j >= 2r) and the column
    clamp bound: centres further left or right than that are entirely off-screen, as are their clamped copies.
    """
    rows = 2 * max_radius
    columns = np.arange(-max_radius - 1, SCREEN + max_radius + 1)
    codes = np.zeros((max_radius + 1, columns.size, rows), dtype=np.intp)
    row_offset = np.full((max_radius + 1, rows), -(10**6), dtype=np.intp)
    for radius in range(1, max_radius + 1):
        mask, offset = disc_mask(radius)
        for j in range(2 * radius):
            filled = np.flatnonzero(mask[j])
            lo = columns + filled[0] + offset
            hi = columns + filled[-1] + offset
            visible = (hi >= 0) & (lo < SCREEN)
            lo, hi = np.clip(lo, 0, SCREEN - 1), np.clip(hi, 0, SCREEN - 1)
            codes[radius, :, j] = np.where(visible, span_code(lo, hi), 0)
            row_offset[radius, j] = j + offset
    return codes, row_offset, max_radius + 1


# ------------------------------------------------------------------------------------------------ blending
def darken(rows: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """SDL's blend of a black overlay with per-surface ``alpha``: ``D - floor(D * A / 255)`` (exact, uint16)."""
    product = rows.astype(np.uint16) * alpha.astype(np.uint16)
    return (rows - ((product + 1 + (product >> 8)) >> 8)).astype(np.uint8)


def lighten(rows: np.ndarray, alpha: int) -> np.ndarray:
    """SDL's blend of a white overlay (the spotlight rings): ``D + floor((255 - D) * A / 255)``."""
    return 255 - darken(255 - rows, np.asarray(alpha))


# ------------------------------------------------------------------------------------------------ HUD rows
def paint_hud_row(
    endless: bool, show_action: bool, show_reward: bool, action: tuple[int, int], reward_state: int, red: int
) -> np.ndarray:
    """One row of the 4-row top bar, painted in the reference's order (all four rows are equal).

    ``action`` is the previous action, ``reward_state`` 0 before the first step, then 1 (previous reward not
    positive) or 2 (positive), ``red`` the width of the red (lost health) part.
    """
    row = np.zeros((SCREEN, 3), dtype=np.uint8)
    row[:] = BLACK if endless else HUD_GREY
    row[: SCREEN // 2] = GREEN
    if show_action:
        row[42:63] = ACTION_COLOURS[action[0]]
        row[63:84] = ACTION_COLOURS[action[1]]
    if red > 0:
        row[:red] = RED
    if show_reward and reward_state:
        block = slice(57, 67) if show_action else slice(42, 84)
        row[block] = YELLOW if reward_state == 2 else HUD_GREY
    return row.reshape(-1)


@cache
def hud_tables() -> tuple[np.ndarray, np.ndarray]:
    """Left halves by red width (0..42) and right halves by ``flags * 27 + a0 * 9 + a1 * 3 + reward_state``."""
    half = ROW_BYTES // 2
    left = np.stack([paint_hud_row(False, False, False, (0, 0), 0, red)[:half] for red in range(SCREEN // 2 + 1)])
    right = []
    for flags in range(8):
        endless, show_action, show_reward = bool(flags & 4), bool(flags & 2), bool(flags & 1)
        for code in range(27):
            action, reward_state = (code // 9, code // 3 % 3), code % 3
            right.append(paint_hud_row(endless, show_action, show_reward, action, reward_state, 0)[half:])
    return left, np.stack(right)


# ------------------------------------------------------------------------------------------------ sampler
@cache
def _block_disc(radius: int) -> np.ndarray:
    """Pixels at squared distance < radius^2 from the centre, as a (2r-1, 2r-1) mask."""
    offsets = np.arange(-radius + 1, radius)
    return offsets[:, None] ** 2 + offsets[None, :] ** 2 < radius * radius


def block_position(mask: np.ndarray, x: int, y: int, radius: int) -> None:
    """Mark the pixels within ``radius`` (exclusive) of (x, y) as taken in the (84, 84) [y, x] spawn mask."""
    disc = _block_disc(radius)
    top, left = y - radius + 1, x - radius + 1
    r0, c0 = max(top, 0), max(left, 0)
    r1, c1 = min(top + disc.shape[0], SCREEN), min(left + disc.shape[1], SCREEN)
    if r0 < r1 and c0 < c1:
        mask[r0:r1, c0:c1] |= disc[r0 - top : r1 - top, c0 - left : c1 - left]


def sample_position(mask: np.ndarray, rng: np.random.Generator, radius: int) -> tuple[int, int]:
    """A uniformly drawn free pixel (row-major order of the free ones), which is then blocked with ``radius``."""
    free = np.flatnonzero(~mask)
    if free.size == 0:
        raise RuntimeError("no free spawn position left: too many coins for the arena (reduce num_coins)")
    y, x = divmod(int(free[rng.integers(0, free.size)]), SCREEN)
    block_position(mask, x, y, radius)
    return x, y


def _clamp_item(value: int) -> int:
    return min(max(value, ITEM_LOW), ITEM_HIGH)


# ------------------------------------------------------------------------------------------------ the core
def draw_order(entities: list[tuple[str, int, bool]]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Which visible entities go above the darkness, and which (a quirk) above the HUD, in drawing order.

    The reference builds its list ``[floor, darkness, hud]`` and inserts each entity (coins, exit, agent in this
    order) at the darkness position if it is hidden (shifting the darkness back), else at ``darkness + offset``
    with a fixed offset per entity (coins 1, exit 2, agent 3), so some visible entities end up after the HUD.
    Hidden entities are always drawn under the darkness in the order coins, exit, agent.
    """
    layers = ["floor", "darkness", "hud"]
    darkness = 1
    for name, offset, visible in entities:
        if visible:
            layers.insert(darkness + offset, name)
        else:
            layers.insert(darkness, name)
            darkness += 1
    hud = layers.index("hud")
    return tuple(layers[darkness + 1 : hud]), tuple(layers[hud + 1 :])


class SearingSpotlightsCore(BatchedCore):
    """Both Searing Spotlights variants; ``endless=True`` gives ``Endless-SearingSpotlights-v0``."""

    base_render_fps = 25
    single_observation_space = gym.spaces.Box(0, 255, (SCREEN, SCREEN, 3), np.uint8)
    single_action_space = gym.spaces.MultiDiscrete([3, 3])

    def __init__(self, num_envs: int = 1, options: dict[str, Any] | None = None, endless: bool = False) -> None:
        self.endless = bool(endless)
        self.env_name = "Endless-SearingSpotlights-v0" if self.endless else "SearingSpotlights-v0"
        self.option_specs = ESS_OPTIONS if self.endless else SS_OPTIONS
        self.has_ground_truth_info = self.endless
        self.ground_truth_space = (
            gym.spaces.Box(np.zeros(4, np.float32), np.ones(4, np.float32), (4,), np.float32) if self.endless else None
        )
        super().__init__(num_envs, options)
        self.resolve(None)  # cross-checks of the constructor options
        n = self.num_envs
        f64, i64 = np.float64, np.int64
        # episode settings (from the options of each slot's current episode)
        self.max_steps = np.zeros(n, i64)
        self.agent_speed = np.zeros(n, f64)
        self.agent_radius = np.zeros(n, i64)
        self.agent_reach = np.zeros(n, i64)
        self.any_visible = np.zeros(n, bool)  # some entity is drawn above the darkness (or the HUD)
        self.agent_scale = np.zeros(n, f64)
        self.max_health = np.ones(n, f64)
        self.spot_damage = np.zeros(n, f64)
        self.reward_inside = np.zeros(n, f64)
        self.reward_outside = np.zeros(n, f64)
        self.reward_death = np.zeros(n, f64)
        self.reward_coin = np.zeros(n, f64)
        self.reward_exit = np.zeros(n, f64)
        self.red_feedback = np.zeros(n, bool)  # visual_feedback on a chessboard floor
        self.floor_kind = np.zeros(n, i64)
        self.rings = np.zeros(n, bool)  # black_background: spotlights get a white outline
        self.dim_step = np.zeros(n, i64)  # alpha increase per step (0: jump to the threshold)
        self.light_threshold = np.zeros(n, i64)
        self.spawn_interval = np.zeros(n, i64)
        self.spawns_left = np.zeros(n, i64)  # Searing Spotlights: later spawns still allowed
        self.hud_flags = np.zeros(n, i64)  # 4 * endless + 2 * show_action + show_reward
        self.agent_hidden = np.ones(n, bool)
        self.coins_visible = np.zeros(n, bool)
        self.coin_show_duration = np.zeros(n, i64)
        self.steps_per_coin = np.zeros(n, i64)
        self.use_exit = np.zeros(n, bool)
        self.coin_scale = np.zeros(n, f64)
        self.coin_radius = np.zeros(n, i64)
        self.exit_scale = np.zeros(n, f64)
        self.exit_reach = np.zeros(n, f64)  # exit radius + agent radius
        self.num_coins = np.zeros(n, i64)
        self.orders: list[dict[bool, tuple[tuple[str, ...], tuple[str, ...]]]] = [{} for _ in range(n)]
        # episode state
        self.t = np.zeros(n, i64)
        self.alpha = np.zeros(n, i64)
        self.x = np.zeros(n, i64)
        self.y = np.zeros(n, i64)
        self.heading = np.zeros(n, i64)
        self.sprite_heading = np.zeros(n, i64)  # 0 (facing up) in the reset frame, then the heading
        self.health = np.zeros(n, f64)
        # The HUD lags one step: it shows the previous action and whether the previous reward was positive.
        self.hud_action = np.zeros((n, 2), i64)  # shown in the current frame
        self.hud_reward = np.zeros(n, i64)  # shown now: 0 none yet (reset frame), 1 not positive, 2 positive
        self.last_action = np.zeros((n, 2), i64)  # shown from the next step on
        self.last_reward = np.zeros(n, i64)
        self.hit = np.zeros(n, bool)
        self.spawn_timer = np.zeros(n, i64)
        self.coins_collected = np.zeros(n, i64)
        self.coin_t = np.zeros(n, i64)
        self.success = np.zeros(n, i64)
        self.exit_open = np.zeros(n, bool)
        self.exit_x = np.zeros(n, i64)
        self.exit_y = np.zeros(n, i64)
        self.coin_x = np.zeros((n, 1), i64)
        self.coin_y = np.zeros((n, 1), i64)
        self.coin_alive = np.zeros((n, 1), bool)
        # spotlights, in list order per slot (capacity grows on demand)
        self.spot_count = np.zeros(n, i64)
        self._allocate_spots(8)
        # pictures
        self.frames = np.zeros((n, SCREEN, ROW_BYTES), np.uint8)
        self.lit = np.zeros((2, n, SCREEN, ROW_BYTES), np.uint8)  # floor + coins + exit, blue and red floor
        self.holes = np.zeros((n * SCREEN, ROW_BYTES), np.uint8)  # 0/255 hole masks of the last drawn slots
        self.span_index = np.zeros(n * SCREEN + 1, np.intp)  # per frame row: a span code; the last is a dump
        self.max_radius = 13

    # ------------------------------------------------------------------------------------------- options
    def resolve(self, options: dict[str, Any] | None) -> dict[str, Any]:
        opts = super().resolve(options)
        for low, high in (("spot_min_radius", "spot_max_radius"), ("spot_min_speed", "spot_max_speed")):
            if opts[low] > opts[high]:
                raise ValueError(f"option {low!r}={opts[low]!r} is invalid: expected a value <= {high}={opts[high]!r}")
        return opts

    def _allocate_spots(self, capacity: int) -> None:
        n, old = self.num_envs, getattr(self, "spot_radius", None)
        fields = {
            "spot_radius": np.int64,
            "spot_speed": np.float64,
            "spot_tau": np.float64,
            "spot_done": bool,
            "spot_start": np.complex128,
            "spot_target": np.complex128,
            "spot_offset": np.complex128,
            "spot_cx": np.int64,  # where the hole was drawn in the last step (for the debug view)
            "spot_cy": np.int64,
            "spot_drawn": bool,
        }
        for name, dtype in fields.items():
            array = np.zeros((n, capacity), dtype)
            if old is not None:
                previous = getattr(self, name)
                array[:, : previous.shape[1]] = previous
            setattr(self, name, array)
        self.spot_capacity = capacity
        self.spot_slots = np.arange(capacity)

    # --------------------------------------------------------------------------------------------- reset
    def _reset_slot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        self._apply_options(k, opts)
        self.t[k] = 0
        self.alpha[k] = 0 if opts["light_dim_off_duration"] > 0 else opts["light_threshold"]
        self.hit[k] = False
        self.hud_action[k] = 0
        self.hud_reward[k] = 0
        self.last_action[k] = 0
        self.last_reward[k] = 1  # the reference starts from a last reward of 0.0
        self.spawn_timer[k] = 0
        self.coins_collected[k] = 0
        self.coin_t[k] = 0
        self.success[k] = 0
        self.exit_open[k] = False
        mask = np.zeros((SCREEN, SCREEN), bool)
        self.heading[k] = 45 * int(rng.integers(0, 8))  # rng.choice over the 8 headings draws exactly this
        self.sprite_heading[k] = 0
        if opts["sample_agent_position"]:
            x, y = sample_position(mask, rng, AGENT_BLOCK)
            x, y = x + int(rng.integers(2, 4)), y + int(rng.integers(2, 4))  # not clamped (kept quirk)
        else:
            x, y = CENTRE, CENTRE
            block_position(mask, x, y, ITEM_BLOCK)
        self.x[k], self.y[k] = x, y
        self.health[k] = opts["agent_health"]
        self.spot_count[k] = 0
        self.spot_done[k] = False
        self.spot_drawn[k] = False
        for _ in range(opts["initial_spawns"]):
            self._spawn_spot(k, rng, opts)
        if self.endless:
            self._ensure_coin_capacity(1)
            self.coin_alive[k] = False
            self.num_coins[k] = 1
            self._spawn_endless_coin(k, rng, previous=None)
        else:
            counts = opts["num_coins"]
            num_coins = int(counts[rng.integers(0, len(counts))]) if counts else 0  # == rng.choice(counts)
            self.num_coins[k] = num_coins
            self._ensure_coin_capacity(num_coins)
            self.coin_alive[k] = False
            for j in range(num_coins):
                cx, cy = sample_position(mask, rng, ITEM_BLOCK)
                cx, cy = cx + int(rng.integers(2, 4)), cy + int(rng.integers(2, 4))
                self.coin_x[k, j], self.coin_y[k, j] = _clamp_item(cx), _clamp_item(cy)
                self.coin_alive[k, j] = True
            if opts["use_exit"]:
                ex, ey = sample_position(mask, rng, ITEM_BLOCK)
                ex, ey = ex + int(rng.integers(2, 4)), ey + int(rng.integers(2, 4))
                self.exit_x[k], self.exit_y[k] = _clamp_item(ex), _clamp_item(ey)
        self._build_lit(k)
        self._draw_reset_frame(k)

    def _apply_options(self, k: int, opts: dict[str, Any]) -> None:
        endless = self.endless
        self.max_steps[k] = opts["max_steps"]
        self.agent_speed[k] = opts["agent_speed"]
        self.agent_scale[k] = opts["agent_scale"]
        self.agent_radius[k] = int(25 * opts["agent_scale"])
        sprite = agent_planes(float(opts["agent_scale"]))[0]
        self.agent_reach[k] = max(sprite.height, sprite.width) // 2 + 1  # how far the sprite reaches
        self.max_health[k] = opts["agent_health"]
        self.spot_damage[k] = opts["spot_damage"]
        self.reward_inside[k] = opts["reward_inside_spotlight"]
        self.reward_outside[k] = opts["reward_outside_spotlight"]
        self.reward_death[k] = opts["reward_death"]
        self.reward_coin[k] = opts["reward_coin"]
        self.reward_exit[k] = 0.0 if endless else opts["reward_exit"]
        if opts["black_background"]:
            self.floor_kind[k] = FLOOR_BLACK
        elif opts["hide_chessboard"]:
            self.floor_kind[k] = FLOOR_WHITE
        else:
            self.floor_kind[k] = FLOOR_CHESS
        self.red_feedback[k] = opts["visual_feedback"] and self.floor_kind[k] == FLOOR_CHESS
        self.rings[k] = opts["black_background"]
        duration = opts["light_dim_off_duration"]
        self.dim_step[k] = int(255 / duration) if duration > 0 else 0
        self.light_threshold[k] = opts["light_threshold"]
        if endless:
            self.spawn_interval[k] = opts["spawn_interval"]
            self.steps_per_coin[k] = opts["steps_per_coin"]
            self.coin_show_duration[k] = opts["coin_show_duration"]
            self.use_exit[k] = False
            show_action = opts["show_last_action"]
        else:
            # The reference reads the first entry of its interval list and pops the last: a constant interval.
            self.spawn_interval[k] = int(opts["initial_spawn_interval"] + opts["spawn_interval_threshold"])
            self.spawns_left[k] = opts["num_spawns"]
            self.use_exit[k] = opts["use_exit"]
            self.exit_scale[k] = opts["exit_scale"]
            self.exit_reach[k] = 20 / 2 * opts["exit_scale"] + self.agent_radius[k]
            show_action = opts["show_last_action"]
        self.hud_flags[k] = 4 * endless + 2 * show_action + opts["show_last_positive_reward"]
        self.agent_hidden[k] = not opts["agent_visible"]
        self.coins_visible[k] = opts["coins_visible"]
        self.coin_scale[k] = opts["coin_scale"]
        self.coin_radius[k] = int(10 * opts["coin_scale"])
        self.any_visible[k] = opts["agent_visible"] or opts["coins_visible"] or opts.get("exit_visible", False)
        self.max_radius = max(self.max_radius, int(opts["spot_max_radius"]))
        # draw orders, keyed by "coin drawn above the darkness" (it changes during an endless episode)
        agent = ("agent", 3, opts["agent_visible"])
        if endless:
            self.orders[k] = {v: draw_order([("coins", 1, v), agent]) for v in (False, True)}
        else:
            entities = [("coins", 1, opts["coins_visible"]), ("exit", 2, opts["exit_visible"]), agent]
            if not opts["use_exit"]:
                entities.pop(1)  # no exit is drawn at all (the reference would draw a stale or missing one)
            order = draw_order(entities)
            self.orders[k] = {False: order, True: order}

    def _ensure_coin_capacity(self, count: int) -> None:
        if count > self.coin_x.shape[1]:
            grow = count - self.coin_x.shape[1]
            self.coin_x = np.pad(self.coin_x, ((0, 0), (0, grow)))
            self.coin_y = np.pad(self.coin_y, ((0, 0), (0, grow)))
            self.coin_alive = np.pad(self.coin_alive, ((0, 0), (0, grow)))

    def _spawn_spot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        """Append a spotlight to slot k's list: radius, speed, then the three angles (the reference's 5 draws)."""
        radius = rng.integers(opts["spot_min_radius"], opts["spot_max_radius"] + 1)
        speed = rng.uniform(opts["spot_min_speed"], opts["spot_max_speed"])
        start = rng.integers(0, 360)
        target = start + 180 + rng.integers(-45, 45)
        offset = target + rng.integers(-135, 135)
        orbit = SPOT_ORBIT + radius
        j = int(self.spot_count[k])
        if j == self.spot_capacity:
            self._allocate_spots(2 * self.spot_capacity)
        points = []
        for angle in (start, target, offset):  # pygame's rotation, for the reference's exact floats
            p = pygame.math.Vector2(CENTRE, CENTRE) + pygame.math.Vector2(orbit, 0).rotate(float(angle))
            points.append(complex(p.x, p.y))
        self.spot_radius[k, j] = radius
        self.spot_speed[k, j] = speed
        self.spot_tau[k, j] = 0.0
        self.spot_done[k, j] = False
        self.spot_drawn[k, j] = False
        self.spot_start[k, j], self.spot_target[k, j], self.spot_offset[k, j] = points
        self.spot_count[k] = j + 1

    def _spawn_endless_coin(self, k: int, rng: np.random.Generator, previous: tuple[int, int] | None) -> None:
        """A new coin: the sampler is cleared, the old coin's place blocked, then a draw (the reference's order)."""
        mask = np.zeros((SCREEN, SCREEN), bool)
        if previous is not None:
            block_position(mask, previous[0], previous[1], AGENT_BLOCK)
        cx, cy = sample_position(mask, rng, AGENT_BLOCK)
        cx, cy = cx + int(rng.integers(2, 4)), cy + int(rng.integers(2, 4))
        self.coin_x[k, 0], self.coin_y[k, 0] = _clamp_item(cx), _clamp_item(cy)
        self.coin_alive[k, 0] = True

    # ------------------------------------------------------------------------------------------- pictures
    def _build_lit(self, k: int) -> None:
        """Slot k's lit pictures (blue and red floor) with its coins and exit, drawn in the reference's order."""
        coin = coin_planes(float(self.coin_scale[k]))
        alive = np.flatnonzero(self.coin_alive[k])
        for hit in (False, True):
            rows = self.lit[int(hit), k]
            rows[:] = floor_rows(int(self.floor_kind[k]), hit and bool(self.red_feedback[k]))
            for j in alive:
                coin.paste(rows, self.coin_x[k, j], self.coin_y[k, j])
            if self.use_exit[k]:
                planes = exit_planes(float(self.exit_scale[k]), bool(self.exit_open[k]))
                planes.paste(rows, self.exit_x[k], self.exit_y[k])

    def _agent_planes(self, k: int) -> Planes:
        return agent_planes(float(self.agent_scale[k]))[int(self.sprite_heading[k]) // 45]

    def _paste_entity(self, rows: np.ndarray, k: int, name: str) -> None:
        if name == "agent":
            self._agent_planes(k).paste(rows, self.x[k], self.y[k])
        elif name == "coins":
            coin = coin_planes(float(self.coin_scale[k]))
            for j in np.flatnonzero(self.coin_alive[k]):
                coin.paste(rows, self.coin_x[k, j], self.coin_y[k, j])
        else:
            exit_planes(float(self.exit_scale[k]), bool(self.exit_open[k])).paste(rows, self.exit_x[k], self.exit_y[k])

    def _coin_above(self, k: int) -> bool:
        """Whether slot k's coin is drawn above the darkness now (endless: also while it is new)."""
        return bool(self.coins_visible[k]) or (self.endless and self.coin_t[k] < self.coin_show_duration[k])

    def _hud_rows(self, idx: Index) -> np.ndarray:
        """The top-bar row (252 bytes) of each selected slot."""
        left, right = hud_tables()
        red = np.trunc(SCREEN // 2 * (1 - self.health[idx] / self.max_health[idx])).astype(np.int64)
        action, reward_state = self.hud_action[idx], self.hud_reward[idx]
        code = self.hud_flags[idx] * 27 + action[:, 0] * 9 + action[:, 1] * 3 + reward_state
        rows = np.concatenate([left[np.clip(red, 0, SCREEN // 2)], right[code]], axis=1)
        for i in np.flatnonzero(red > SCREEN // 2):  # health below 0: the red part reaches into the right half
            k = int(self.slots(idx)[i])
            flags = int(self.hud_flags[k])
            rows[i] = paint_hud_row(
                bool(flags & 4), bool(flags & 2), bool(flags & 1), tuple(action[i]), int(reward_state[i]), int(red[i])
            )
        return rows

    def _finish_frames(self, idx: Index, out: np.ndarray) -> None:
        """Entities above the darkness, the HUD, then the entities that the reference draws after the HUD."""
        slots = self.slots(idx)
        special = self.any_visible[idx]
        if self.endless:
            special = special | (self.coin_t[idx] < self.coin_show_duration[idx])
        special = np.flatnonzero(special)
        for i in special:
            k = int(slots[i])
            for name in self.orders[k][self._coin_above(k)][0]:
                self._paste_entity(out[i], k, name)
        out[:, :HUD_ROWS, :] = self._hud_rows(idx)[:, None, :]
        for i in special:
            k = int(slots[i])
            for name in self.orders[k][self._coin_above(k)][1]:
                self._paste_entity(out[i], k, name)

    def _blend_slots(self, slots: np.ndarray, local: np.ndarray, holes: np.ndarray, out: np.ndarray) -> None:
        """Frames with a partly transparent darkness or with spotlight rings: lit inside holes, blended outside.

        ``slots`` are slot numbers, ``local`` their rows in ``holes`` (n, 84, 252 of 0/255) and ``out``.
        """
        lit = self.lit[(self.hit[slots] & self.red_feedback[slots]).astype(np.intp), slots]
        for i, k in enumerate(slots):
            if self.agent_hidden[k]:
                self._agent_planes(int(k)).paste(lit[i], self.x[k], self.y[k])
        alpha = np.minimum(self.alpha[slots], 255)[:, None, None]
        dark = darken(lit, alpha)
        mask = holes[local]
        blended = dark ^ ((dark ^ lit) & mask)
        for i, k in enumerate(slots):
            if self.rings[k]:
                self._draw_rings(int(k), lit[i], blended[i])
        out[local] = blended

    def _draw_rings(self, k: int, lit: np.ndarray, frame: np.ndarray) -> None:
        """Spotlights drawn with rings: holes and white outlines are painted in list order (later ones on top)."""
        state = np.zeros((SCREEN, SCREEN), np.int8)  # 0 darkness, 1 hole, 2 white ring
        for j in np.flatnonzero(self.spot_drawn[k, : self.spot_count[k]]):
            radius, cx, cy = int(self.spot_radius[k, j]), int(self.spot_cx[k, j]), int(self.spot_cy[k, j])
            disc, offset = disc_mask(radius)
            ring = ring_mask(radius)
            top, left = cy + offset, cx + offset
            r0, c0 = max(top, 0), max(left, 0)
            r1, c1 = min(top + disc.shape[0], SCREEN), min(left + disc.shape[1], SCREEN)
            if r0 >= r1 or c0 >= c1:
                continue
            window = state[r0:r1, c0:c1]
            window[disc[r0 - top : r1 - top, c0 - left : c1 - left]] = 1
            window[ring[r0 - top : r1 - top, c0 - left : c1 - left]] = 2
        white = np.repeat(state == 2, 3, axis=1)
        frame[white] = lighten(lit, int(min(self.alpha[k], 255)))[white]

    def _draw_reset_frame(self, k: int) -> None:
        """The reset picture: no holes yet (alpha 0 shows everything lit; alpha > 0 darkens it all)."""
        slots = np.array([k])
        self.holes[:SCREEN] = 0
        out = self.frames[k : k + 1]
        self._blend_slots(slots, np.array([0]), self.holes[:SCREEN].reshape(1, SCREEN, ROW_BYTES), out)
        self._finish_frames(slots, out)

    # ---------------------------------------------------------------------------------------------- step
    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        actions = actions.reshape(-1, 2).astype(np.int64)
        n = actions.shape[0]
        slots = self.slots(idx)
        # 1. move (clamped into the walkable area below the HUD)
        radius = self.agent_radius[idx]
        vx, vy = continuous_velocity(actions, self.agent_speed[idx])
        x = clamp_centre(self.x[idx] + vx.astype(np.int64), radius, SCREEN - radius)
        y = clamp_centre(self.y[idx] + vy.astype(np.int64), HUD_ROWS + radius, SCREEN - radius)
        self.x[idx], self.y[idx] = x, y
        heading = continuous_heading(actions, self.heading[idx])
        self.heading[idx] = heading
        self.sprite_heading[idx] = heading
        # 2. the HUD shows the previous action
        self.hud_action[idx] = self.last_action[idx]
        self.last_action[idx] = actions
        # 3. dimming
        alpha = self.alpha[idx]
        dim = alpha <= self.light_threshold[idx]
        step = self.dim_step[idx]
        stepped = np.where(step > 0, np.minimum(alpha + step, 255), self.light_threshold[idx])
        alpha = np.where(dim, stepped, alpha)
        self.alpha[idx] = alpha
        # 4. spotlights: maybe spawn, then process the list
        timer = self.spawn_timer[idx] + 1
        spawn = timer >= self.spawn_interval[idx]
        if not self.endless:
            spawn &= self.spawns_left[idx] > 0
        for i in np.flatnonzero(spawn):
            k = int(slots[i])
            self._spawn_spot(k, self.rngs[k], self.slot_options[k])
            self.spawns_left[k] -= 1
        self.spawn_timer[idx] = np.where(spawn, 0, timer)
        hit = self._process_spotlights(idx, slots, x, y, radius)
        health = self.health[idx] - np.where(hit, self.spot_damage[idx], 0.0)
        self.health[idx] = health
        self.hit[idx] = hit
        dead = health <= 0
        rewards = np.where(hit, self.reward_inside[idx], self.reward_outside[idx])
        rewards = rewards + np.where(dead, self.reward_death[idx], 0.0)
        # 5.-7. coins, exit, termination
        t = self.t[idx] + 1
        self.t[idx] = t
        if self.endless:
            rewards = rewards + self._endless_coin_phase(idx, slots, x, y, radius)
            coin_t = self.coin_t[idx] + 1
            self.coin_t[idx] = coin_t
            terminated = dead | (coin_t == self.steps_per_coin[idx])
        else:
            coin_rewards, coins_done = self._coin_phase(idx, slots, x, y, radius)
            rewards = rewards + coin_rewards
            exit_rewards, reached = self._exit_phase(idx, slots, x, y, coins_done)
            rewards = rewards + exit_rewards
            goal = coins_done & np.where(self.use_exit[idx], reached, self.num_coins[idx] > 0)
            self.success[idx] = ~dead & goal
            terminated = dead | goal
        terminated = terminated | (t == self.max_steps[idx])
        # 8. the HUD shows whether the previous reward was positive
        self.hud_reward[idx] = self.last_reward[idx]
        self.last_reward[idx] = 1 + (rewards > 0)
        self._draw(idx, slots, n)
        return rewards, terminated

    def _process_spotlights(
        self, idx: Index, slots: np.ndarray, x: np.ndarray, y: np.ndarray, agent_radius: np.ndarray
    ) -> np.ndarray:
        """Draw (record), move and hit-test every spotlight; finished ones are removed (with the skip quirk)."""
        count = self.spot_count[idx]
        listed = self.spot_slots[None, :] < count[:, None]
        done = self.spot_done[idx] & listed
        if done.any():
            # The reference removes finished spotlights while iterating its list, so the one right after a
            # removed spotlight is not visited in that step (not drawn, not moved, cannot hit).
            visited = np.ones_like(listed)
            for j in range(1, int(count.max())):
                visited[:, j] = ~(visited[:, j - 1] & done[:, j - 1])
            removed = visited & done
            processed = visited & listed & ~done
        else:
            removed = None
            processed = listed
        tau = self.spot_tau[idx]
        rest = 1.0 - tau
        curve = self.spot_target[idx] * rest + self.spot_offset[idx] * tau
        centre = self.spot_start[idx] * rest + curve * tau  # pygame's lerp: a * (1 - t) + b * t
        radius = self.spot_radius[idx]
        delta = centre - (x + 1j * y)[:, None]
        distance = np.sqrt(delta.real * delta.real + delta.imag * delta.imag)
        hits = processed & (distance <= (radius + agent_radius[:, None]))
        tau = np.where(processed, tau + self.spot_speed[idx], tau)
        finished = tau >= 1.0
        self.spot_tau[idx] = np.where(finished, 1.0, tau)
        self.spot_done[idx] = done | (processed & finished)
        self.spot_cx[idx] = np.trunc(centre.real).astype(np.int64)
        self.spot_cy[idx] = np.trunc(centre.imag).astype(np.int64)
        self.spot_drawn[idx] = processed
        if removed is not None and removed.any():
            self._remove_spots(idx, listed & ~removed)
        return hits.any(axis=1)

    def _remove_spots(self, idx: Index, keep: np.ndarray) -> None:
        """Compact the spotlight lists, keeping the order of the remaining ones."""
        order = np.argsort(~keep, axis=1, kind="stable")
        for name in (
            "spot_radius",
            "spot_speed",
            "spot_tau",
            "spot_done",
            "spot_start",
            "spot_target",
            "spot_offset",
            "spot_cx",
            "spot_cy",
            "spot_drawn",
        ):
            array = getattr(self, name)
            array[idx] = np.take_along_axis(array[idx], order, axis=1)
        kept = keep.sum(axis=1)
        self.spot_count[idx] = kept
        stale = self.spot_slots[None, :] >= kept[:, None]
        self.spot_done[idx] = self.spot_done[idx] & ~stale
        self.spot_drawn[idx] = self.spot_drawn[idx] & ~stale

    def _coin_phase(
        self, idx: Index, slots: np.ndarray, x: np.ndarray, y: np.ndarray, agent_radius: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Collect the coins the agent touches (the coin after a collected one is tested a step later)."""
        alive = self.coin_alive[idx]
        reach = (self.coin_radius[idx] + agent_radius)[:, None]
        dx, dy = self.coin_x[idx] - x[:, None], self.coin_y[idx] - y[:, None]
        inside = alive & (np.sqrt(dx * dx + dy * dy) <= reach)
        rewards = np.zeros(len(slots))
        if inside.any():
            removed_before = np.zeros(len(slots), bool)
            taken = np.zeros_like(alive)
            coin_reward = self.reward_coin[idx]
            for j in range(alive.shape[1]):
                got = inside[:, j] & ~removed_before
                taken[:, j] = got
                rewards = np.where(got, rewards + coin_reward, rewards)
                removed_before = np.where(alive[:, j], got, removed_before)
            alive = alive & ~taken
            self.coin_alive[idx] = alive
            self.coins_collected[idx] = self.coins_collected[idx] + taken.sum(axis=1)
            for i in np.flatnonzero(taken.any(axis=1)):
                self._build_lit(int(slots[i]))
        coins_done = (self.num_coins[idx] == 0) | ~alive.any(axis=1)
        return rewards, coins_done

    def _exit_phase(
        self, idx: Index, slots: np.ndarray, x: np.ndarray, y: np.ndarray, coins_done: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Once the coins are done the exit opens; reaching it pays ``reward_exit``."""
        active = self.use_exit[idx] & coins_done
        opening = active & ~self.exit_open[idx]
        if opening.any():
            for i in np.flatnonzero(opening):
                k = int(slots[i])
                self.exit_open[k] = True
                self._build_lit(k)
        dx, dy = self.exit_x[idx] - x, self.exit_y[idx] - y
        reached = active & (np.sqrt(dx * dx + dy * dy) <= self.exit_reach[idx])
        return np.where(reached, self.reward_exit[idx], 0.0), reached

    def _endless_coin_phase(
        self, idx: Index, slots: np.ndarray, x: np.ndarray, y: np.ndarray, agent_radius: np.ndarray
    ) -> np.ndarray:
        """The one coin: touching it pays ``reward_coin`` and a new coin spawns at once."""
        dx, dy = self.coin_x[idx, 0] - x, self.coin_y[idx, 0] - y
        inside = np.sqrt(dx * dx + dy * dy) <= self.coin_radius[idx] + agent_radius
        if inside.any():
            for i in np.flatnonzero(inside):
                k = int(slots[i])
                self.coins_collected[k] += 1
                self.coin_t[k] = 0
                previous = (int(self.coin_x[k, 0]), int(self.coin_y[k, 0]))
                self._spawn_endless_coin(k, self.rngs[k], previous)
                self._build_lit(k)
        return np.where(inside, self.reward_coin[idx], 0.0)

    # ---------------------------------------------------------------------------------------------- draw
    def _draw(self, idx: Index, slots: np.ndarray, n: int) -> None:
        """Compose the frames of the stepped slots (see the module docstring)."""
        holes = self._hole_masks(idx, n)
        out = self.frames[idx] if isinstance(idx, slice) else np.empty((n, SCREEN, ROW_BYTES), np.uint8)
        blend = (self.alpha[idx] < 255) | self.rings[idx]
        hit_floor = self.hit[idx] & self.red_feedback[idx]
        np.bitwise_and(holes, self.lit[0][idx], out=out)
        red = np.flatnonzero(hit_floor & ~blend)
        if red.size:
            out[red] = holes[red] & self.lit[1][slots[red]]
        # the hidden agent shows where it overlaps a hole
        near = self.agent_hidden[idx] & ~blend
        if near.any():
            reach = self.spot_radius[idx] + self.agent_reach[idx][:, None]
            close = (
                self.spot_drawn[idx]
                & (np.abs(self.spot_cx[idx] - self.x[idx][:, None]) <= reach)
                & (np.abs(self.spot_cy[idx] - self.y[idx][:, None]) <= reach)
            )
            for i in np.flatnonzero(near & close.any(axis=1)):
                k = int(slots[i])
                self._agent_planes(k).paste(out[i], self.x[k], self.y[k], where=holes[i])
        if blend.any():
            local = np.flatnonzero(blend)
            self._blend_slots(slots[local], local, holes, out)
        self._finish_frames(idx, out)
        if not isinstance(idx, slice):
            self.frames[idx] = out

    def _hole_masks(self, idx: Index, n: int) -> np.ndarray:
        """(n, 84, 252) 0/255 masks of the spotlight holes drawn in this step (rows 0-3 are left empty)."""
        codes_table, row_offset, bound = disc_span_tables(self.max_radius)
        drawn = self.spot_drawn[idx]
        cx, cy, radius = self.spot_cx[idx], self.spot_cy[idx], self.spot_radius[idx]
        drawn = drawn & (cx + radius > 0) & (cx - radius < SCREEN) & (cy + radius > HUD_ROWS) & (cy - radius < SCREEN)
        local, j = np.nonzero(drawn)
        radius = radius[local, j]
        codes = codes_table[radius, np.clip(cx[local, j], -bound, SCREEN + bound - 1) + bound]
        rows = cy[local, j][:, None] + row_offset[radius]
        valid = (rows >= HUD_ROWS) & (rows < SCREEN)
        dump = n * SCREEN
        keys = np.where(valid, local[:, None] * SCREEN + rows, dump).ravel()
        codes = (codes * valid).ravel()
        index = self.span_index[: dump + 1]
        index[:] = 0
        index[keys] = codes
        table = span_rows()
        holes = self.holes[:dump]
        np.take(table, index[:dump], axis=0, out=holes, mode="clip")
        # rows crossed by several spotlights: OR the other spans in, one layer at a time
        pending = index[keys] != codes
        keys, codes = keys[pending], codes[pending]
        while keys.size:
            index[keys] = codes
            first = index[keys] == codes
            k1, c1 = keys[first], codes[first]
            holes[k1] = holes[k1] | table[c1]
            keys, codes = keys[~first], codes[~first]
        return holes.reshape(n, SCREEN, ROW_BYTES)

    # ------------------------------------------------------------------------------------------ faces
    def _observation(self, idx: Index) -> np.ndarray:
        return self.frames[idx].reshape(-1, SCREEN, SCREEN, 3)

    def _final_info(self, k: int) -> dict[str, Any]:
        info: dict[str, Any] = {"agent_health": float(self.health[k] / self.max_health[k])}
        if self.endless:
            info["coins_collected"] = int(self.coins_collected[k])
        else:
            num = int(self.num_coins[k])
            info["coins_collected"] = self.coins_collected[k] / num if num else float("nan")
            info["success"] = int(self.success[k])
        return info

    def _step_info(self, k: int) -> dict[str, Any]:
        if not self.endless:
            return {}
        position = np.array([self.x[k], self.y[k], self.coin_x[k, 0], self.coin_y[k, 0]], dtype=np.float64)
        return {"ground_truth": position / SCREEN}

    def _debug_frame(self, k: int) -> np.ndarray:
        """Floor, darkness with the last step's holes, then exit, coins, agent and HUD all above it."""
        slots = np.array([k])
        floor = floor_rows(int(self.floor_kind[k]), bool(self.hit[k] and self.red_feedback[k]))
        rows = np.array(floor)
        alpha = np.array(min(int(self.alpha[k]), 255))
        dark = darken(rows, alpha)
        holes = np.zeros((SCREEN, ROW_BYTES), np.uint8)
        for j in np.flatnonzero(self.spot_drawn[k, : self.spot_count[k]]):
            disc, offset = disc_mask(int(self.spot_radius[k, j]))
            pixels = np.zeros((SCREEN, SCREEN), bool)
            top, left = int(self.spot_cy[k, j]) + offset, int(self.spot_cx[k, j]) + offset
            r0, c0 = max(top, 0), max(left, 0)
            r1, c1 = min(top + disc.shape[0], SCREEN), min(left + disc.shape[1], SCREEN)
            if r0 < r1 and c0 < c1:
                pixels[r0:r1, c0:c1] = disc[r0 - top : r1 - top, c0 - left : c1 - left]
                holes |= np.repeat(pixels, 3, axis=1).astype(np.uint8) * 255
        frame = dark ^ ((dark ^ rows) & holes)
        if self.rings[k]:
            self._draw_rings(k, rows, frame)
        names = ("coins", "agent") if self.endless else ("exit", "coins", "agent")
        for name in names:
            if name != "exit" or self.use_exit[k]:
                self._paste_entity(frame, k, name)
        frame[:HUD_ROWS] = self._hud_rows(slots)[0]
        return frame.reshape(SCREEN, SCREEN, 3)
