"""The Mystery Path family: ``MysteryPath-v0``, ``MysteryPath-Grid-v0`` and ``Endless-MysteryPath-v0``.

An invisible path of 12-px tiles leads across the screen. Stepping off it shows a red cross for one step, then the
agent is put back on the path's first tile (the action of that step is ignored). Each path tile pays
``reward_path_progress`` on its first visit.

* ``MysteryPath-v0`` / ``-Grid-v0`` (``endless=False``): one 7x7 level (:mod:`envs.mystery_path_generator`) from an
  origin on one border to a goal on the opposite one. Reaching the goal pays ``reward_goal`` and ends the episode;
  ``max_steps`` ends it too. The free variant moves 3 px per step (MultiDiscrete([3, 3])), the grid variant turns and
  steps one tile (Discrete(4)). The agent sees only itself (and, optionally, the origin and goal tiles).
* ``Endless-MysteryPath-v0`` (``endless=True``): 7x7 segments joined left to right by a transition tile, generated
  ahead of the agent. The camera follows the agent, which sees the path behind it but never ahead. Actions are
  Discrete(4): 0 none, 1 right, 2 up, 3 down. The episode ends after ``stamina_level`` steps without reaching a fresh
  tile, when the agent falls off behind its best column, or when it falls off twice at the same tile.

State lives in arrays with a leading slot axis; only level generation runs per slot. Frames are drawn into a padded
canvas (sprites near the edges need no clipping): the static Mystery Path background is copied and the sprites are
scattered in with one fancy assignment per sprite kind; the scrolling Endless view is built band by band (every tile
row of the screen consists of one "edge" pixel row pattern and one "middle" pattern).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import gymnasium as gym
import numpy as np

from envs.core import BatchedCore, Index
from envs.drawing import SCREEN, Sprite, agent_sprites, blend, pygame, round_half_away, surface_to_sprite
from envs.movement import clamp_centre, continuous_heading, continuous_velocity, grid_step
from envs.mystery_path_generator import generate_path
from envs.options import Option

GRID = 7  # tiles per side of a level (and of an endless segment)
TILE = SCREEN // GRID  # 12 px
SEGMENT_COLUMNS = GRID + 1  # an endless segment plus its transition tile
INITIAL_SEGMENTS = 3
GRID_AGENT_SCALE = 0.25  # the grid variant ignores agent_scale

ORIGIN_COLOUR = (0, 0, 255)
GOAL_COLOUR = (0, 255, 0)
PATH_COLOUR = (255, 255, 255)
WALL_COLOUR = (255, 0, 0)
CROSS_COLOUR = (255, 0, 0)
TILE_BORDER = (210, 210, 210)
ICE_COLOUR = (125, 177, 250)
DEBUG_PATH_ALPHA = 200
STAMINA_BAR_WIDTH = 4
STAMINA_GREEN, STAMINA_RED = (0, 255, 0), (255, 0, 0)

# Endless ground truth: the direction from the current tile to the next path tile.
DIRECTIONS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.int64)  # east, north, south
EAST, NORTH, SOUTH, WEST = 0, 1, 2, -1

# Column kinds of one band (tile row) of the endless view, and the colour of each kind in the band's edge rows
# (the first and last pixel row of a tile) and middle rows.
KIND_BLACK, KIND_BORDER, KIND_ICE, KIND_PATH = 0, 1, 2, 3
EDGE_ROW = np.array([(0, 0, 0), TILE_BORDER, TILE_BORDER, TILE_BORDER], dtype=np.uint8)
MIDDLE_ROW = np.array([(0, 0, 0), TILE_BORDER, ICE_COLOUR, PATH_COLOUR], dtype=np.uint8)
TILE_KINDS = np.array([KIND_BORDER] + [KIND_PATH] * (TILE - 2) + [KIND_BORDER], dtype=np.int8)
BAND_PAD = TILE  # band rows are padded by one tile on both sides so that tiles need no clipping

# Endless action -> (horizontal, vertical) of the free controller: no-op, right, up, down.
ENDLESS_ACTIONS = np.array([[0, 0], [2, 0], [0, 1], [0, 2]], dtype=np.int64)


def option_specs(grid: bool, endless: bool) -> dict[str, Option]:
    """The reference's reset parameters of one variant, with their defaults and valid ranges."""
    scale = Option(0.25, "float", 0.05, 1.0, doc="agent size (body radius int(25 * scale))")
    if grid:
        scale = Option(0.25, "float", 0.05, 1.0, doc="accepted but unused: the grid agent always has scale 0.25")
    speed = Option(3.0, "float", 0.0, None, doc="pixels per step (cut to an int per axis)")
    if endless:
        return {
            "max_steps": Option(-1, "int", doc="the episode ends when t == max_steps (<= 0: never)"),
            "agent_scale": scale,
            "agent_speed": speed,
            "show_origin": Option(False, "bool", doc="has no effect (as in memory-gym)"),
            "show_past_path": Option(True, "bool", doc="draw the path tiles behind the agent"),
            "show_background": Option(False, "bool", doc="scrolling ice tiles instead of black"),
            "show_stamina": Option(False, "bool", doc="stamina bar at the right edge"),
            "visual_feedback": Option(True, "bool", doc="red cross on the agent when it falls off"),
            "camera_offset_scale": Option(5.0, "float", 0.0, 5.5, doc="tiles visible behind the agent"),
            "stamina_level": Option(20, "int", 1, None, doc="steps allowed without reaching a fresh tile"),
            "reward_fall_off": Option(0.0, "float"),
            "reward_path_progress": Option(0.1, "float", doc="first visit of each path tile"),
            "reward_step": Option(0.0, "float"),
        }
    specs = {
        "max_steps": Option(128 if grid else 512, "int", doc="the episode ends when t == max_steps"),
        "agent_scale": scale,
        "agent_speed": speed,
        "cardinal_origin_choice": Option(
            [0, 1, 2, 3], "int_list", 0, 3, doc="origin side, sampled: 0 left, 1 right, 2 top, 3 bottom"
        ),
        "show_origin": Option(False, "bool", doc="draw the origin tile (blue)"),
        "show_goal": Option(False, "bool", doc="draw the goal tile (green)"),
        "visual_feedback": Option(True, "bool", doc="red cross on the agent while it is off the path"),
        "reward_goal": Option(1.0, "float"),
        "reward_fall_off": Option(0.0, "float"),
        "reward_path_progress": Option(0.0 if grid else 0.1, "float", doc="first visit of each inner path tile"),
        "reward_step": Option(0.0, "float"),
    }
    if grid:
        del specs["agent_speed"]
    return specs


# ------------------------------------------------------------------------------------------------------- sprites
@cache
def fall_off_cross() -> Sprite:
    """The red 10x10 cross (two 3-px diagonals) shown where the agent fell off."""
    size, width = int(40 * 0.25), int(12 * 0.25)
    surface = pygame.Surface((size, size))
    surface.fill((0, 0, 0))
    pygame.draw.line(surface, CROSS_COLOUR, (0, 0), (size - 1, size - 1), width)
    pygame.draw.line(surface, CROSS_COLOUR, (size - 1, 0), (0, size - 1), width)
    return surface_to_sprite(surface, (0, 0, 0))


@cache
def _ice_background(phase: int) -> np.ndarray:
    """The endless view's ice floor scrolled by ``phase`` px (0..11) to the left."""
    kinds = _BACKGROUND_KINDS[phase]
    band = np.where(_TILE_EDGE_ROWS[:, None, None], EDGE_ROW[kinds][None], MIDDLE_ROW[kinds][None])
    return np.ascontiguousarray(np.tile(band, (GRID, 1, 1)))


def _background_kinds() -> np.ndarray:
    """Column kinds of the endless background: rows 0..11 the ice floor at each scroll phase, row 12 black."""
    kinds = np.full((TILE + 1, SCREEN), KIND_BLACK, dtype=np.int8)
    for phase in range(TILE):
        local = (np.arange(SCREEN) + phase) % TILE
        kinds[phase] = np.where((local == 0) | (local == TILE - 1), KIND_BORDER, KIND_ICE)
    return kinds


_BACKGROUND_KINDS = _background_kinds()
_BLACK_BACKGROUND = TILE  # row of _BACKGROUND_KINDS
_TILE_EDGE_ROWS = np.isin(np.arange(TILE), (0, TILE - 1))


@cache
def _stamina_bars() -> np.ndarray:
    """The stamina bar for every red height 0..84: (85, 84, 4, 3)."""
    bars = np.empty((SCREEN + 1, SCREEN, STAMINA_BAR_WIDTH, 3), dtype=np.uint8)
    bars[:] = STAMINA_GREEN
    for height in range(SCREEN + 1):
        bars[height, :height] = STAMINA_RED
    return bars


# -------------------------------------------------------------------------------------------------- canvas
class _SpriteSheet:
    """Sprites of one role (agent headings, the cross) as padded byte-offset tables, for one-scatter pasting."""

    def __init__(self) -> None:
        self.sprites: list[Sprite] = []
        self.heights = np.zeros(0, dtype=np.int64)
        self.widths = np.zeros(0, dtype=np.int64)
        self.offsets = np.zeros((0, 0), dtype=np.int64)
        self.colours = np.zeros((0, 0), dtype=np.uint8)
        self._row_bytes = -1

    def add(self, sprites: tuple[Sprite, ...]) -> int:
        """Register ``sprites`` (consecutive ids) and return the id of the first; known sprites are reused."""
        for i in range(len(self.sprites) - len(sprites) + 1):
            if all(a is b for a, b in zip(self.sprites[i : i + len(sprites)], sprites, strict=False)):
                return i
        self.sprites.extend(sprites)
        self.heights = np.array([s.height for s in self.sprites], dtype=np.int64)
        self.widths = np.array([s.width for s in self.sprites], dtype=np.int64)
        self._row_bytes = -1
        return len(self.sprites) - len(sprites)

    def tables(self, row_bytes: int) -> tuple[np.ndarray, np.ndarray]:
        """Byte offsets (relative to the top-left pixel) and byte values of every opaque pixel, padded per sprite."""
        if row_bytes != self._row_bytes:
            pixels = [np.argwhere(s.mask) for s in self.sprites]
            most = max(len(p) for p in pixels)
            offsets = np.zeros((len(self.sprites), most * 3), dtype=np.int64)
            colours = np.zeros((len(self.sprites), most * 3), dtype=np.uint8)
            for i, (sprite, p) in enumerate(zip(self.sprites, pixels, strict=True)):
                p = np.concatenate([p, np.repeat(p[:1], most - len(p), axis=0)])  # repeats write the same value
                offsets[i] = ((p[:, 0] * row_bytes + p[:, 1] * 3)[:, None] + np.arange(3)).ravel()
                colours[i] = sprite.rgb[p[:, 0], p[:, 1]].ravel()
            self.offsets, self.colours, self._row_bytes = offsets, colours, row_bytes
        return self.offsets, self.colours


class _Canvas:
    """The frames of all slots, with a margin around each so that sprites can be pasted without clipping."""

    def __init__(self, num_envs: int, margin: int) -> None:
        self.num_envs = num_envs
        self._allocate(margin)

    def _allocate(self, margin: int) -> None:
        self.margin = margin
        side = SCREEN + 2 * margin
        self.buffer = np.zeros((self.num_envs, side, side, 3), dtype=np.uint8)
        self.flat = self.buffer.reshape(-1)
        self.view = self.buffer[:, margin : margin + SCREEN, margin : margin + SCREEN]
        # The same pixels split into tile bands: (slot, band, row in band, column, channel).
        self.bands = self.view.reshape(self.num_envs, GRID, TILE, SCREEN, 3)
        assert np.shares_memory(self.bands, self.buffer)
        self.row_bytes = side * 3
        self.slot_bytes = side * side * 3

    def fit(self, sheet: _SpriteSheet) -> None:
        """Grow the margin (keeping the frames) until every sprite of ``sheet`` fits into it."""
        need = int(max(sheet.heights.max(initial=0), sheet.widths.max(initial=0)))
        if need > self.margin:
            frames = self.view.copy()
            self._allocate(need)
            self.view[:] = frames

    def paste(self, sheet: _SpriteSheet, slots: np.ndarray, ids: np.ndarray, top: np.ndarray, left: np.ndarray) -> None:
        """Paste sprite ``ids[i]`` of ``sheet`` into slot ``slots[i]`` with its top-left at (top[i], left[i])."""
        if len(slots) == 0:
            return
        offsets, colours = sheet.tables(self.row_bytes)
        m = self.margin
        # A sprite entirely outside the screen is moved to the margin; partly visible ones are never moved.
        top = np.clip(top, -m, SCREEN + m - sheet.heights[ids])
        left = np.clip(left, -m, SCREEN + m - sheet.widths[ids])
        base = slots * self.slot_bytes + (top + m) * self.row_bytes + (left + m) * 3
        self.flat[base[:, None] + offsets[ids]] = colours[ids]


# ---------------------------------------------------------------------------------------------------- core
class MysteryPathCore(BatchedCore):
    """All three Mystery Path variants: ``grid`` selects grid movement, ``endless`` the side-scrolling endless path."""

    def __init__(
        self, num_envs: int = 1, options: dict[str, Any] | None = None, grid: bool = False, endless: bool = False
    ) -> None:
        if grid and endless:
            raise ValueError("Endless-MysteryPath has no grid variant (grid=True with endless=True)")
        self.grid, self.endless = bool(grid), bool(endless)
        self.env_name = "Endless-MysteryPath-v0" if endless else ("MysteryPath-Grid-v0" if grid else "MysteryPath-v0")
        self.option_specs = option_specs(self.grid, self.endless)
        self.single_observation_space = gym.spaces.Box(0, 255, (SCREEN, SCREEN, 3), np.uint8)
        self.single_action_space = gym.spaces.Discrete(4) if grid or endless else gym.spaces.MultiDiscrete([3, 3])
        self.base_render_fps = 3 if grid else 25
        if endless:
            self.has_ground_truth_info = True
            self.ground_truth_space = gym.spaces.Box(0.0, 1.0, (3,), np.float32)
        super().__init__(num_envs, options)
        n = self.num_envs
        self.all_slots = np.arange(n)
        # Agent: centre pixel (world coordinates in the endless variant), heading, where a fall-off returns it to.
        self.x = np.zeros(n, dtype=np.int64)
        self.y = np.zeros(n, dtype=np.int64)
        self.heading = np.zeros(n, dtype=np.int64)
        self.return_x = np.zeros(n, dtype=np.int64)
        self.return_y = np.zeros(n, dtype=np.int64)
        self.off_path = np.zeros(n, dtype=bool)
        self.cross_visible = np.zeros(n, dtype=bool)
        self.cross_x = np.zeros(n, dtype=np.int64)  # cross centre on the screen
        self.cross_y = np.zeros(n, dtype=np.int64)
        self.t = np.zeros(n, dtype=np.int64)
        self.num_fails = np.zeros(n, dtype=np.int64)
        # Per-episode options as arrays.
        self.max_steps = np.zeros(n, dtype=np.int64)
        self.speed = np.zeros(n, dtype=np.float64)
        self.radius = np.zeros(n, dtype=np.int64)
        self.visual_feedback = np.zeros(n, dtype=bool)
        self.reward_fall_off = np.zeros(n, dtype=np.float64)
        self.reward_path_progress = np.zeros(n, dtype=np.float64)
        self.reward_step = np.zeros(n, dtype=np.float64)
        # Drawing.
        self.agents = _SpriteSheet()
        self.crosses = _SpriteSheet()
        self.cross_id = self.crosses.add((fall_off_cross(),))
        self.agent_sprite0 = np.zeros(n, dtype=np.int64)  # sprite id of heading 0 for the slot's agent scale
        self.agent_half = np.zeros(n, dtype=np.int64)  # sprite side // 2 (top-left = centre - half)
        self.canvas = _Canvas(n, 0)
        self.canvas.fit(self.crosses)
        if endless:
            self._init_endless(n)
        else:
            self._init_level(n)

    # ------------------------------------------------------------------------------------------- state
    def _init_level(self, n: int) -> None:
        self.cell_x = np.zeros(n, dtype=np.int64)  # grid variant: the agent's tile
        self.cell_y = np.zeros(n, dtype=np.int64)
        self.on_path = np.zeros((n, GRID, GRID), dtype=bool)  # [slot, x, y]
        self.unrewarded = np.zeros((n, GRID, GRID), dtype=bool)  # path tiles that still pay progress
        self.goal_x = np.zeros(n, dtype=np.int64)
        self.goal_y = np.zeros(n, dtype=np.int64)
        self.reward_goal = np.zeros(n, dtype=np.float64)
        self.success = np.zeros(n, dtype=np.int64)
        self.background = np.zeros((n, SCREEN, SCREEN, 3), dtype=np.uint8)
        self.levels: list[Any] = [None] * n  # (origin, goal, layout) per slot, for the debug view

    def _init_endless(self, n: int) -> None:
        # The path as one chain of tiles (origin first), grown segment by segment; capacities grow on demand.
        self.chain_x = np.zeros((n, 64), dtype=np.int64)
        self.chain_y = np.zeros((n, 64), dtype=np.int64)
        self.direction = np.full((n, 64), WEST, dtype=np.int64)  # from chain tile i to tile i + 1
        self.unrewarded = np.zeros((n, 64), dtype=bool)
        self.refills_stamina = np.zeros((n, 64), dtype=bool)
        self.chain_length = np.zeros(n, dtype=np.int64)
        self.tile_node = np.full((n, INITIAL_SEGMENTS * SEGMENT_COLUMNS + SEGMENT_COLUMNS, GRID), -1, np.int64)
        self.num_segments = np.zeros(n, dtype=np.int64)
        self.last_goal_y = np.zeros(n, dtype=np.int64)
        self.current_node = np.zeros(n, dtype=np.int64)
        self.ground_truth = np.zeros(n, dtype=np.int64)  # index into DIRECTIONS
        self.stamina = np.zeros(n, dtype=np.int64)
        self.stamina_level = np.zeros(n, dtype=np.int64)
        self.max_x = np.zeros(n, dtype=np.int64)
        self.tiles_visited = np.zeros(n, dtype=np.int64)
        self.fall_off_tiles: list[set[tuple[int, int]]] = [set() for _ in range(n)]
        self.camera_x = np.zeros(n, dtype=np.float64)
        self.camera_offset = np.zeros(n, dtype=np.float64)
        self.bg_scroll = np.zeros(n, dtype=np.float64)
        self.agent_screen_left = np.zeros(n, dtype=np.int64)
        self.depth = np.zeros(n, dtype=np.int64)  # past-path walk: columns behind the agent
        self.show_past_path = np.zeros(n, dtype=bool)
        self.show_background = np.zeros(n, dtype=bool)
        self.show_stamina = np.zeros(n, dtype=bool)

    def _set_agent_scale(self, k: int, scale: float) -> None:
        first = self.agents.add(agent_sprites(scale))
        self.canvas.fit(self.agents)
        self.agent_sprite0[k] = first
        self.agent_half[k] = self.agents.sprites[first].width // 2
        self.radius[k] = int(25 * scale)

    def _reset_common(self, k: int, opts: dict[str, Any]) -> None:
        self.t[k] = 0
        self.max_steps[k] = opts["max_steps"]
        self.num_fails[k] = 0
        self.off_path[k] = False
        self.cross_visible[k] = False
        self.visual_feedback[k] = opts["visual_feedback"]
        self.reward_fall_off[k] = opts["reward_fall_off"]
        self.reward_path_progress[k] = opts["reward_path_progress"]
        self.reward_step[k] = opts["reward_step"]
        self.speed[k] = opts.get("agent_speed", 0.0)
        self._set_agent_scale(k, GRID_AGENT_SCALE if self.grid else opts["agent_scale"])

    def _reset_slot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        self._reset_common(k, opts)
        if self.endless:
            self._reset_endless(k, rng, opts)
        else:
            self._reset_level(k, rng, opts)
        self._draw(np.array([k]))

    def _reset_level(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        choice = opts["cardinal_origin_choice"]
        side = choice[int(rng.integers(0, len(choice)))]
        first, second = int(rng.integers(0, GRID)), int(rng.integers(0, GRID))
        last = GRID - 1
        origin, goal = {
            0: ((0, first), (last, second)),
            1: ((last, first), (0, second)),
            2: ((first, 0), (second, last)),
            3: ((first, last), (second, 0)),
        }[side]
        layout = generate_path(rng, GRID, GRID, origin, goal)
        self.levels[k] = (origin, goal, layout)
        self.on_path[k] = False
        self.unrewarded[k] = False
        for tile in layout.path:
            self.on_path[k][tile] = True
        for tile in layout.path[1:-1]:
            self.unrewarded[k][tile] = True
        self.goal_x[k], self.goal_y[k] = goal
        self.reward_goal[k] = opts["reward_goal"]
        self.success[k] = 0
        self.heading[k] = 0
        if self.grid:
            # The grid agent stands on tile centres; it returns to the origin's tile.
            self.cell_x[k], self.cell_y[k] = origin
            self.return_x[k], self.return_y[k] = origin
            self.x[k], self.y[k] = origin[0] * TILE + TILE // 2, origin[1] * TILE + TILE // 2
        else:
            # The free agent is placed `radius` px into the origin tile (its centre only with the default scale).
            self.return_x[k] = origin[0] * TILE + self.radius[k]
            self.return_y[k] = origin[1] * TILE + self.radius[k]
            self.x[k], self.y[k] = self.return_x[k], self.return_y[k]
        background = self.background[k]
        background[:] = 0
        if opts["show_origin"]:
            _fill_tile(background, origin, ORIGIN_COLOUR)
        if opts["show_goal"]:
            _fill_tile(background, goal, GOAL_COLOUR)

    def _reset_endless(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        self.chain_length[k] = 0
        self.num_segments[k] = 0
        self.tile_node[k] = -1
        self.unrewarded[k] = False
        for _ in range(INITIAL_SEGMENTS):
            self._add_segment(k, rng)
        self.unrewarded[k, 0] = False  # the very first tile pays nothing
        self.current_node[k] = 0
        self.ground_truth[k] = self.direction[k, 0]  # never west: the first tile is in column 0
        self.heading[k] = 270  # facing right
        self.return_x[k] = self.chain_x[k, 0] * TILE + self.radius[k]
        self.return_y[k] = self.chain_y[k, 0] * TILE + self.radius[k]
        self.x[k], self.y[k] = self.return_x[k], self.return_y[k]
        self.refills_stamina[k] = True
        self.stamina_level[k] = self.stamina[k] = opts["stamina_level"]
        self.max_x[k] = 0
        self.tiles_visited[k] = 0
        self.fall_off_tiles[k] = set()
        self.camera_offset[k] = -TILE * opts["camera_offset_scale"]
        self.camera_x[k] = self.camera_offset[k]
        self.bg_scroll[k] = 0.0
        self.depth[k] = int(opts["camera_offset_scale"])
        # The agent is always drawn at the same screen column: its start column minus the camera offset.
        self.agent_screen_left[k] = int(self.return_x[k] - self.agent_half[k] - self.camera_offset[k])
        self.show_past_path[k] = opts["show_past_path"]
        self.show_background[k] = opts["show_background"]
        self.show_stamina[k] = opts["show_stamina"]

    def _add_segment(self, k: int, rng: np.random.Generator) -> None:
        """Append one endless segment (a 7x7 level from column 0 to column 6) and its transition tile."""
        segment = int(self.num_segments[k])
        start_y = int(rng.integers(0, GRID)) if segment == 0 else int(self.last_goal_y[k])
        goal_y = int(rng.integers(0, GRID))
        layout = generate_path(rng, GRID, GRID, (0, start_y), (GRID - 1, goal_y))
        shift = segment * SEGMENT_COLUMNS
        tiles = [(x + shift, y) for x, y in layout.path] + [(shift + GRID, goal_y)]
        begin = int(self.chain_length[k])
        end = begin + len(tiles)
        self._reserve(end, (segment + 2) * SEGMENT_COLUMNS)
        xs = np.array([t[0] for t in tiles], dtype=np.int64)
        ys = np.array([t[1] for t in tiles], dtype=np.int64)
        self.chain_x[k, begin:end] = xs
        self.chain_y[k, begin:end] = ys
        # Direction from each tile to the next one (the new segment's last one gets its own when the next is added).
        first = max(begin - 1, 0)
        dx = np.diff(self.chain_x[k, first:end])
        dy = np.diff(self.chain_y[k, first:end])
        self.direction[k, first : end - 1] = np.select([dx == 1, dy == -1, dy == 1], [EAST, NORTH, SOUTH], WEST)
        self.direction[k, end - 1] = WEST
        self.unrewarded[k, begin:end] = True
        self.refills_stamina[k, begin:end] = True
        self.tile_node[k, xs, ys] = np.arange(begin, end)
        self.chain_length[k] = end
        self.num_segments[k] = segment + 1
        self.last_goal_y[k] = goal_y

    def _reserve(self, length: int, columns: int) -> None:
        """Grow the chain and tile arrays of all slots so that they hold ``length`` tiles and ``columns`` columns."""
        capacity = self.chain_x.shape[1]
        if length > capacity:
            extra = max(length, 2 * capacity) - capacity
            for name, fill in (
                ("chain_x", 0),
                ("chain_y", 0),
                ("direction", WEST),
                ("unrewarded", False),
                ("refills_stamina", False),
            ):
                old = getattr(self, name)
                setattr(self, name, np.concatenate([old, np.full((old.shape[0], extra), fill, old.dtype)], axis=1))
        if columns > self.tile_node.shape[1]:
            extra = max(columns, 2 * self.tile_node.shape[1]) - self.tile_node.shape[1]
            pad = np.full((self.num_envs, extra, GRID), -1, dtype=np.int64)
            self.tile_node = np.concatenate([self.tile_node, pad], axis=1)

    # -------------------------------------------------------------------------------------------- step
    def _slots_of(self, idx: Index) -> np.ndarray:
        return self.all_slots if isinstance(idx, slice) else idx

    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.endless:
            rewards, terminated = self._step_endless(idx, actions)
        else:
            rewards, terminated = self._step_level(idx, actions)
        self._draw(idx)
        return rewards, terminated

    def _move_free(self, idx: Index, moves: np.ndarray, back: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Free movement; slots in ``back`` are first put back on the path's first tile and do not move."""
        moves = np.where(back[:, None], 0, moves)
        vx, vy = continuous_velocity(moves, self.speed[idx])
        self.heading[idx] = continuous_heading(moves, self.heading[idx])
        x = np.where(back, self.return_x[idx], self.x[idx]) + vx.astype(np.int64)
        y = np.where(back, self.return_y[idx], self.y[idx]) + vy.astype(np.int64)
        return x, y

    def _step_level(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        slots = self._slots_of(idx)
        back = self.off_path[idx]
        if self.grid:
            moves = np.where(back, 0, actions.reshape(-1))
            tx = np.where(back, self.return_x[idx], self.cell_x[idx])
            ty = np.where(back, self.return_y[idx], self.cell_y[idx])
            tx, ty, self.heading[idx] = grid_step(moves, tx, ty, self.heading[idx], GRID)
            self.cell_x[idx], self.cell_y[idx] = tx, ty
            x, y = tx * TILE + TILE // 2, ty * TILE + TILE // 2
        else:
            x, y = self._move_free(idx, actions.reshape(-1, 2), back)
            radius = self.radius[idx]
            x = clamp_centre(x, radius, SCREEN - radius)
            y = clamp_centre(y, radius, SCREEN - radius)
            tx, ty = x // TILE, y // TILE
        self.x[idx], self.y[idx] = x, y
        goal = (tx == self.goal_x[idx]) & (ty == self.goal_y[idx])
        on_path = self.on_path[slots, tx, ty]
        progress = self.unrewarded[slots, tx, ty]  # never the origin or the goal
        self.unrewarded[slots, tx, ty] = False
        fell = ~(goal | on_path)
        rewards = np.where(
            goal,
            self.reward_goal[idx],
            np.where(progress, self.reward_path_progress[idx], np.where(fell, self.reward_fall_off[idx], 0.0)),
        )
        rewards = rewards + self.reward_step[idx]
        self.num_fails[idx] += fell
        self.off_path[idx] = fell
        self.cross_visible[idx] = fell & self.visual_feedback[idx]
        self.cross_x[idx], self.cross_y[idx] = x, y
        self.success[idx] = goal
        t = self.t[idx] + 1
        self.t[idx] = t
        return rewards, goal | (t == self.max_steps[idx])

    def _step_endless(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        slots = self._slots_of(idx)
        back = self.off_path[idx]
        x, y = self._move_free(idx, ENDLESS_ACTIONS[actions.reshape(-1)], back)
        vx = np.where(back, 0, x - self.x[idx])
        self.x[idx], self.y[idx] = x, y
        # The camera follows the agent horizontally; the background scrolls the other way and wraps.
        self.camera_x[idx] = np.where(back, self.camera_offset[idx], self.camera_x[idx] + vx)
        scroll = np.where(back, 0.0, self.bg_scroll[idx] - vx)
        wrap = np.abs(scroll) >= TILE
        if wrap.any():
            step = np.where(vx != 0, np.abs(vx), 1)
            scroll = np.where(wrap, np.abs(scroll) % step * np.sign(scroll), scroll)
        self.bg_scroll[idx] = scroll

        tx, ty = x // TILE, y // TILE
        segment = tx // SEGMENT_COLUMNS
        ahead = segment > self.num_segments[idx] - 2
        while ahead.any():  # one new segment when the agent enters the last one (more only at absurd speeds)
            for k in slots[ahead]:
                self._add_segment(int(k), self.rngs[int(k)])
            ahead = segment > self.num_segments[idx] - 2
        inside = (ty >= 0) & (ty < GRID)
        node = np.where(inside, self.tile_node[slots, tx, np.clip(ty, 0, GRID - 1)], -1)
        on_path = node >= 0
        node = np.where(on_path, node, self.current_node[idx])
        self.current_node[idx] = node
        progress = on_path & self.unrewarded[slots, node]
        self.unrewarded[slots, node] &= ~progress
        self.tiles_visited[idx] += progress
        refill = on_path & self.refills_stamina[slots, node]
        self.refills_stamina[slots, node] &= ~refill
        stamina = np.where(refill, self.stamina_level[idx], self.stamina[idx])
        fell = ~on_path
        rewards = np.where(progress, self.reward_path_progress[idx], 0.0)
        terminated = np.zeros(len(rewards), dtype=bool)
        if fell.any():
            rewards = rewards + np.where(fell, self.reward_fall_off[idx], 0.0)
            self.num_fails[idx] += fell
            # Falling off behind the best column, or twice at the same tile, ends the episode. (The fall-off tiles
            # are meant to be forgotten on reaching a new best column, but the reference never does.)
            max_x = self.max_x[idx]
            for i in np.flatnonzero(fell):
                tile = (int(tx[i]), int(ty[i]))
                seen = self.fall_off_tiles[int(slots[i])]
                if tile[0] < max_x[i] or tile in seen:
                    terminated[i] = True
                else:
                    seen.add(tile)
            fell_slots = slots[fell]
            self.refills_stamina[fell_slots] = True
            stamina = np.where(fell, self.stamina_level[idx], stamina)
        rewards = rewards + self.reward_step[idx]
        self.off_path[idx] = fell
        self.cross_visible[idx] = fell & self.visual_feedback[idx]
        self.cross_x[idx] = round_half_away(x - self.camera_x[idx])
        self.cross_y[idx] = y
        stamina = stamina - 1
        self.stamina[idx] = stamina
        t = self.t[idx] + 1
        self.t[idx] = t
        terminated |= (stamina == 0) | (t == self.max_steps[idx])
        direction = self.direction[slots, node]
        self.ground_truth[idx] = np.where(direction == WEST, self.ground_truth[idx], direction)
        self.max_x[idx] = np.where(on_path & (tx > self.max_x[idx]), tx, self.max_x[idx])
        return rewards, terminated

    # ------------------------------------------------------------------------------------------- drawing
    def _draw(self, idx: Index) -> None:
        slots = self._slots_of(idx)
        if self.endless:
            self._draw_endless_floor(idx, slots)
            top = self.y[idx] - self.agent_half[idx]
            left = self.agent_screen_left[idx]
        else:
            self.canvas.view[idx] = self.background[idx]
            top = self.y[idx] - self.agent_half[idx]
            left = self.x[idx] - self.agent_half[idx]
        sprite = self.agent_sprite0[idx] + self.heading[idx] // 45
        self.canvas.paste(self.agents, slots, sprite, top, left)
        if self.endless:
            bar = self.show_stamina[idx]
            if bar.any():
                with_bar = slots[bar]
                self.canvas.view[with_bar, :, SCREEN - STAMINA_BAR_WIDTH :] = _stamina_bars()[
                    self._stamina_bar_heights(with_bar)
                ]
        cross = self.cross_visible[idx]
        if cross.any():
            with_cross = slots[cross]
            half = self.crosses.sprites[self.cross_id].width // 2
            ids = np.full(len(with_cross), self.cross_id)
            self.canvas.paste(
                self.crosses, with_cross, ids, self.cross_y[with_cross] - half, self.cross_x[with_cross] - half
            )

    def _stamina_bar_heights(self, slots: np.ndarray) -> np.ndarray:
        level = self.stamina_level[slots]
        return (SCREEN * (1 - np.minimum(self.stamina[slots], level) / level)).astype(np.int64)

    def _past_path_tiles(self, idx: Index, slots: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The path tiles drawn behind the agent: (slot row in ``slots``, tile row, screen x of the tile's left).

        Walking back from the tile before the current one, the walk stops after the first tile whose column is at
        most ``max(0, agent column - 1 - depth)`` (or at the path's first tile); nothing is drawn in column 0.
        """
        column = self.x[idx] // TILE - 1
        active = self.show_past_path[idx] & (column >= 0)
        last = np.maximum(column - self.depth[idx], 0)
        before = self.current_node[idx] - 1  # chain index of the first tile drawn
        window = 32
        while True:
            chain = before[:, None] - np.arange(window)
            valid = chain >= 0
            chain = np.maximum(chain, 0)
            xs = self.chain_x[slots[:, None], chain]
            stop = valid & ((xs <= last[:, None]) | (chain == 0))
            found = stop.any(axis=1) | ~valid[:, -1]
            if found[active].all():
                break
            window *= 2
        drawn = valid & (np.arange(window) <= np.argmax(stop, axis=1)[:, None]) & active[:, None]
        rows, cols = np.nonzero(drawn)
        chain = chain[rows, cols]
        ys = self.chain_y[slots[rows], chain]
        left = np.trunc(xs[rows, cols] * TILE - self.camera_x[idx][rows]).astype(np.int64)
        return rows, ys, left

    def _draw_endless_floor(self, idx: Index, slots: np.ndarray) -> None:
        """Background (black or ice) and the past path, written band by band."""
        m = len(slots)
        phase = np.where(self.show_background[idx], (-self.bg_scroll[idx]).astype(np.int64) % TILE, _BLACK_BACKGROUND)
        width = SCREEN + 2 * BAND_PAD
        kinds = np.empty((m, GRID, width), dtype=np.int8)
        kinds[:, :, BAND_PAD : BAND_PAD + SCREEN] = _BACKGROUND_KINDS[phase][:, None, :]
        rows, ys, left = self._past_path_tiles(idx, slots)
        if len(rows):
            left = np.clip(left, -BAND_PAD, SCREEN) + BAND_PAD
            start = (rows * GRID + ys) * width + left
            kinds.reshape(-1)[start[:, None] + np.arange(TILE)] = TILE_KINDS
        kinds = kinds[:, :, BAND_PAD : BAND_PAD + SCREEN]
        edge, middle = EDGE_ROW[kinds], MIDDLE_ROW[kinds]
        if isinstance(idx, slice):
            bands = self.canvas.bands
        else:
            bands = np.empty((m, GRID, TILE, SCREEN, 3), dtype=np.uint8)
        bands[:, :, 0] = edge
        bands[:, :, TILE - 1] = edge
        bands[:, :, 1 : TILE - 1] = middle[:, :, None]
        if not isinstance(idx, slice):
            self.canvas.view[idx] = bands.reshape(m, SCREEN, SCREEN, 3)

    # ------------------------------------------------------------------------------------------ outputs
    def _observation(self, idx: Index) -> np.ndarray:
        return self.canvas.view[idx]

    def _final_info(self, k: int) -> dict[str, Any]:
        if self.endless:
            return {
                "num_fails": int(self.num_fails[k]),
                "max_x": int(self.max_x[k]),
                "tiles_visited": int(self.tiles_visited[k]),
            }
        return {"success": int(self.success[k]), "num_fails": int(self.num_fails[k])}

    def _step_info(self, k: int) -> dict[str, Any]:
        if self.endless:
            return {"ground_truth": DIRECTIONS[self.ground_truth[k]].copy()}
        return {}

    def _debug_frame(self, k: int) -> np.ndarray:
        """Ground truth: the whole level (path white, origin blue, goal green, walls red) or, in the endless
        variant, every generated path tile at alpha 200 and the stamina bar; plus the agent and the cross."""
        frame = np.zeros((SCREEN, SCREEN, 3), dtype=np.uint8)
        if self.endless:
            if self.show_background[k]:
                frame[:] = _ice_background(int(-self.bg_scroll[k]) % TILE)
            shift = int(-self.camera_x[k])  # the whole path picture is placed once, so it is truncated once
            length = int(self.chain_length[k])
            for tx, ty in zip(self.chain_x[k, :length].tolist(), self.chain_y[k, :length].tolist(), strict=True):
                left = tx * TILE + shift
                if -TILE < left < SCREEN:
                    area = frame[ty * TILE : (ty + 1) * TILE, max(left, 0) : left + TILE]
                    area[:] = blend(area, np.array(PATH_COLOUR), DEBUG_PATH_ALPHA)
            top, left = int(self.y[k] - self.agent_half[k]), int(self.agent_screen_left[k])
        else:
            origin, goal, layout = self.levels[k]
            for tile in layout.path[1:-1]:
                _fill_tile(frame, tile, PATH_COLOUR)
            _fill_tile(frame, origin, ORIGIN_COLOUR)
            _fill_tile(frame, goal, GOAL_COLOUR)
            for tile in layout.walls:
                _fill_tile(frame, tile, WALL_COLOUR)
            top, left = int(self.y[k] - self.agent_half[k]), int(self.x[k] - self.agent_half[k])
        self.agents.sprites[int(self.agent_sprite0[k] + self.heading[k] // 45)].paste(frame, top, left)
        if self.cross_visible[k]:
            cross = self.crosses.sprites[self.cross_id]
            cross.paste(frame, int(self.cross_y[k]) - cross.height // 2, int(self.cross_x[k]) - cross.width // 2)
        if self.endless:
            frame[:, SCREEN - STAMINA_BAR_WIDTH :] = _stamina_bars()[self._stamina_bar_heights(np.array([k]))[0]]
        return frame


def _fill_tile(frame: np.ndarray, tile: tuple[int, int], colour: tuple[int, int, int]) -> None:
    x, y = tile
    frame[y * TILE : (y + 1) * TILE, x * TILE : (x + 1) * TILE] = colour
