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
stay red while the new icon is shown, and during a clue stream the agent keeps the sprite that was drawn last, which
right after a reset is the previous episode's final sprite.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import gymnasium as gym
import numpy as np
import pygame

from envs.core import BatchedCore, Index
from envs.drawing import SCREEN, Sprite, SpriteSheet, agent_sprites, round_half_away, surface_to_sprite
from envs.movement import clamp_centre, continuous_heading, continuous_velocity, grid_step
from envs.options import Option
from envs.rng import BoundedDraws

# The fixed command list (generation order), its tile offsets, and where each command sits in the one-hot vector.
COMMANDS = ("right", "down", "left", "up", "stay", "right_down", "right_up", "left_down", "left_up")
COMMAND_DELTAS = ((1, 0), (0, 1), (-1, 0), (0, -1), (0, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))
COMMAND_STEP = np.array(COMMAND_DELTAS, dtype=np.int64)
ONE_HOT_INDEX = (1, 4, 2, 3, 0, 5, 6, 7, 8)
ONE_HOT = np.eye(9, dtype=np.float32)[list(ONE_HOT_INDEX)]  # the 9-entry block of each command in the vector
ICON_ANGLE = (0, 270, 180, 90, None, 315, 45, 225, 135)  # rotation of the right arrow; None = the "stay" sign
MAX_VECTOR_COMMANDS = 20

TILE = 14
TILE_BLUE, TILE_BLUE_BORDER = (21, 43, 77), (29, 60, 107)
TILE_RED, TILE_RED_BORDER = (81, 18, 26), (112, 24, 36)
RING_GREEN = (0, 255, 0)
ICON_CORNER = 31  # every icon canvas is blitted with its top-left here, whatever its size after rotation
ENDLESS_ARENA = 6
AGENT_SCALE = 0.25
CLUE_FPS = 3  # the human window slows down while commands are shown


# ------------------------------------------------------------------------------------------------------ pictures
def _tile(fill: tuple[int, int, int], border: tuple[int, int, int]) -> np.ndarray:
    tile = np.empty((TILE, TILE, 3), dtype=np.uint8)
    tile[:] = fill
    tile[0, :] = tile[-1, :] = tile[:, 0] = tile[:, -1] = border  # a 1-px border on the tile's own edge
    return tile


def arena_picture(size: int, lethal_except: tuple[int, int] | None = None) -> np.ndarray:
    """The black screen with the arena centred on it: all tiles blue, or all red but the ``lethal_except`` tile."""
    frame = np.zeros((SCREEN, SCREEN, 3), dtype=np.uint8)
    left = arena_left(size)
    blue = _tile(TILE_BLUE, TILE_BLUE_BORDER)
    tile = blue if lethal_except is None else _tile(TILE_RED, TILE_RED_BORDER)
    frame[left : left + TILE * size, left : left + TILE * size] = np.tile(tile, (size, size, 1))
    if lethal_except is not None:
        x, y = lethal_except
        frame[left + TILE * y : left + TILE * (y + 1), left + TILE * x : left + TILE * (x + 1)] = blue
    return frame


@cache
def backgrounds() -> tuple[np.ndarray, np.ndarray]:
    """Every arena picture, stacked, and the index of each: ``[size, 0, x, y]`` all blue (for any x, y),
    ``[size, 1, x, y]`` all red but tile (x, y). Painting the backgrounds of many slots is then one gather."""
    pictures = []
    index = np.full((ENDLESS_ARENA + 1, 2, ENDLESS_ARENA, ENDLESS_ARENA), -1, dtype=np.int64)
    for size in range(2, ENDLESS_ARENA + 1):
        index[size, 0] = len(pictures)
        pictures.append(arena_picture(size))
        for x in range(size):
            for y in range(size):
                index[size, 1, x, y] = len(pictures)
                pictures.append(arena_picture(size, (x, y)))
    stack = np.stack(pictures)
    stack.setflags(write=False)
    index.setflags(write=False)
    return stack, index


class SpawnFrames:
    """Frames of a freshly spawned agent (facing up) on the all-blue arena, drawn once each and then copied.

    A reset frame depends only on the arena, the spawn pixel and the sprite scale (a few hundred frames for the
    default options), so a batch of resets gathers its frames in one copy instead of pasting sprites. Past
    ``LIMIT`` frames the store starts over, which keeps its memory bounded for any mix of options.
    """

    LIMIT = 1024  # frames kept (about 22 MB)

    def __init__(self) -> None:
        self.index: dict[tuple[int, int, int, float], int] = {}
        self.stack = np.zeros((0, SCREEN, SCREEN, 3), dtype=np.uint8)

    def ids(self, keys: list[tuple[int, int, int, float]]) -> list[int]:
        """Rows of ``stack`` holding the frames of ``keys`` = (background id, x, y, agent scale), drawn if new."""
        index = self.index
        if len(index) + len(keys) > self.LIMIT:
            index.clear()
        found = [index.get(key) for key in keys]
        if None in found:
            found = [self._draw(key) if row is None else row for key, row in zip(keys, found, strict=True)]
        return found

    def _draw(self, key: tuple[int, int, int, float]) -> int:
        row = self.index.get(key)  # a key met twice in one batch is drawn once
        if row is not None:
            return row
        row = self.index[key] = len(self.index)
        if row >= len(self.stack):
            grown = np.zeros((max(2 * len(self.stack), 64), SCREEN, SCREEN, 3), dtype=np.uint8)
            grown[: len(self.stack)] = self.stack
            self.stack = grown
        background, x, y, scale = key
        frame = self.stack[row]
        frame[:] = backgrounds()[0][background]
        agent_sheet(scale).paste_one(frame.reshape(SCREEN, SCREEN * 3), y, x, 0)
        return row


@cache
def spawn_frames() -> SpawnFrames:
    return SpawnFrames()


def arena_left(size: int) -> int:
    """Pixel of the arena's left (and top) edge: the arena is centred on the 84-px screen."""
    return SCREEN // 2 - TILE * size // 2


def _icon_surface(command: int) -> pygame.Surface:
    """The command's icon canvas: white 2-px strokes on a black key, rotated like the reference rotates it."""
    dim = 88 * AGENT_SCALE  # 22 px; coordinates are the design values times the scale, floats as pygame gets them
    width = int(8 * AGENT_SCALE)
    surface = pygame.Surface((dim, dim))
    surface.fill((0, 0, 0))
    white = (255, 255, 255)
    angle = ICON_ANGLE[command]
    if angle is None:  # "stay": a ring with a horizontal bar through it
        radius = dim // 2 - 4 * AGENT_SCALE
        bar_y = dim // 2 - 8 * AGENT_SCALE
        pygame.draw.circle(surface, white, (radius, radius), radius=radius, width=width)
        pygame.draw.line(surface, white, (0, bar_y), (dim - 12 * AGENT_SCALE, bar_y), width=width)
        return surface
    tail, head, mid = 2 * AGENT_SCALE, 80 * AGENT_SCALE, 40 * AGENT_SCALE  # the right-pointing arrow
    pygame.draw.line(surface, white, (tail, mid), (head, mid), width)
    pygame.draw.line(surface, white, (head, mid), (mid, 0), width)
    pygame.draw.line(surface, white, (head, mid), (mid, head), width)
    return pygame.transform.rotate(surface, angle)


@cache
def icon_sheet() -> SpriteSheet:
    """The nine icons on a common canvas anchored at their top-left corner (diagonals are larger after rotation)."""
    surfaces = [_icon_surface(c) for c in range(len(COMMANDS))]
    size = max(max(s.get_size()) for s in surfaces)
    sprites = []
    for surface in surfaces:
        canvas = pygame.Surface((size, size))
        canvas.fill((0, 0, 0))
        canvas.blit(surface, (0, 0))
        sprites.append(surface_to_sprite(canvas, (0, 0, 0)))
    return SpriteSheet(sprites, 0, 0)


@cache
def agent_sheet(scale: float) -> SpriteSheet:
    sprites = agent_sprites(scale)
    return SpriteSheet(sprites, sprites[0].height // 2, sprites[0].width // 2)


@cache
def target_ring() -> tuple[Sprite, int]:
    """The debug view's green ring (radius 7, width 2) around a tile centre, and its offset from that centre."""
    surface = pygame.Surface((2 * TILE + 2, 2 * TILE + 2))
    surface.fill((0, 0, 0))
    pygame.draw.circle(surface, RING_GREEN, (TILE, TILE), TILE / 2, int(8 * AGENT_SCALE))
    return surface_to_sprite(surface, (0, 0, 0)), -TILE


@cache
def command_walk(size: int, allowed: int, torus: bool = False) -> tuple[tuple[tuple[int, int], ...], ...]:
    """For every tile ``x * size + y``: (command, tile it leads to) for each of the first ``allowed`` commands, in
    list order, that keeps the walk inside the arena (all of them on the endless variant's torus, which wraps)."""
    steps = []
    for x in range(size):
        for y in range(size):
            moves = []
            for c, (dx, dy) in enumerate(COMMAND_DELTAS[:allowed]):
                nx, ny = x + dx, y + dy
                if torus:
                    nx, ny = nx % size, ny % size
                if 0 <= nx < size and 0 <= ny < size:
                    moves.append((c, nx * size + ny))
            steps.append(tuple(moves))
    return tuple(steps)


def walk_commands(draws: BoundedDraws, walk: tuple, tile: int, count: int) -> list[int]:
    """``count`` commands of a walk from ``tile`` (``walk = command_walk(...)``), each drawn as ``rng.choice`` of the
    commands valid there.

    The hot loop of a reset, so Lemire's method runs inline on the drawn words: a product whose low 32 bits are at
    least n is never rejected (almost always, for n <= 9); the first other word ends the fast loop, and the rest of
    the walk goes through ``draws.below``, which decides exactly (and draws another word when numpy would).
    """
    words, used, walked = draws.words, draws.used, []
    for word in words[used : used + count]:  # the words reserved for the walk
        moves = walk[tile]
        n = len(moves)
        product = word * n
        if product & 0xFFFFFFFF < n:
            break
        command, tile = moves[product >> 32]
        walked.append(command)
    draws.used = used + len(walked)
    for _ in range(count - len(walked)):
        moves = walk[tile]
        command, tile = moves[draws.below(len(moves))]
        walked.append(command)
    return walked


# ------------------------------------------------------------------------------------------------- movement
# Movement runs through transition tables built once per configuration from the shared movement rules, so a step
# is a few gathers for any number of slots. Free movement: a key per slot and axis encodes (config, coordinate,
# axis); MOVE[key + 2 * action_code] is the next key, COORD[key] its coordinate and TILE[key] its tile part
# (8 * tile column on the x axis, tile row on the y axis, so that their sum identifies the tile).
COORD_MARGIN = 16  # coordinates seen before a move: [-13, 97] on the torus (half a radius <= 12.5 past the edges)
COORD_SPAN = SCREEN + 2 * COORD_MARGIN
ACTIONS = np.array([(h, v) for h in range(3) for v in range(3)], dtype=np.int64)  # action code = 3 * h + v
CODE_WEIGHTS = np.array([3, 1], dtype=np.int64)
# sprite index (heading // 45) set by each action code; -1 keeps the heading (no input)
HEADING_SPRITE = continuous_heading(ACTIONS, np.full(len(ACTIONS), -45, dtype=np.int64)) // 45


def wrap_torus(v: np.ndarray, radius: int) -> np.ndarray:
    """Endless arena: past half a radius beyond an edge the centre jumps to the opposite side.

    Both tests see the unrounded jump target (-3.5 is not < -3.5); the integer rect rounds it afterwards.
    """
    margin = radius * 0.5
    v = np.where(v > SCREEN + margin, -margin, v)
    return round_half_away(np.where(v < -margin, SCREEN + margin, v))


def free_move_rows(speed: float, radius: int, left: int, right: int, endless: bool) -> tuple[np.ndarray, np.ndarray]:
    """Next coordinate and tile part for every (coordinate, action code, axis) of one configuration."""
    coords = np.arange(-COORD_MARGIN, SCREEN + COORD_MARGIN)
    vx, vy = continuous_velocity(ACTIONS, np.full(len(ACTIONS), speed), truncate=not endless)
    nxt = np.empty((COORD_SPAN, len(ACTIONS), 2), dtype=np.int64)
    for axis, v in enumerate((vx, vy)):
        moved = coords[:, None] + v[None, :]
        if endless:  # float moves, rounded by the integer rect, then wrapped around the torus
            nxt[:, :, axis] = wrap_torus(round_half_away(moved), radius)
        else:
            nxt[:, :, axis] = clamp_centre(moved.astype(np.int64), left + radius, right - radius)
    tile = (coords - left) // TILE
    return nxt, np.stack([8 * tile, tile], axis=1)


class FreeMoves:
    """Transition tables of free movement, one block per configuration (speed, radius, arena, torus or not)."""

    def __init__(self) -> None:
        self.configs: dict[tuple, int] = {}
        self.move = np.zeros(0, dtype=np.int64)
        self.coord = np.zeros(0, dtype=np.int64)
        self.tile = np.zeros(0, dtype=np.int64)

    def key(self, config: tuple, x: int, y: int) -> tuple[int, int]:
        """Keys of the point (x, y) under ``config`` (its tables are built on first use)."""
        base = self.configs.get(config)
        if base is None:
            base = self.configs[config] = len(self.move)
            nxt, tile = free_move_rows(*config)
            axis = np.arange(2)
            keys = base + (nxt + COORD_MARGIN) * 2 * len(ACTIONS) + axis  # next key for (coord, code, axis)
            self.move = np.concatenate([self.move, keys.reshape(-1)])
            coords = np.arange(-COORD_MARGIN, SCREEN + COORD_MARGIN)
            self.coord = np.concatenate([self.coord, np.repeat(coords, 2 * len(ACTIONS))])
            self.tile = np.concatenate([self.tile, np.repeat(tile, len(ACTIONS), axis=0).reshape(-1)])
        stride = 2 * len(ACTIONS)
        return base + (x + COORD_MARGIN) * stride, base + (y + COORD_MARGIN) * stride + 1


@cache
def grid_moves() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[int, int]]:
    """Grid movement over (arena size, tile, heading): next state per action, pixel centre, sprite and tile id.

    State = base[size] + (column * size + row) * 4 + heading // 90; next state = MOVE[4 * state + action].
    """
    base, moves, pixels, sprites, tiles = {}, [], [], [], []
    for size in range(2, ENDLESS_ARENA + 1):
        base[size] = len(pixels)
        left = arena_left(size)
        cells = np.array([(c, r, h) for c in range(size) for r in range(size) for h in range(4)], dtype=np.int64)
        block = []
        for action in range(4):
            cx, cy, heading = grid_step(np.full(len(cells), action), cells[:, 0], cells[:, 1], 90 * cells[:, 2], size)
            block.append(base[size] + (cx * size + cy) * 4 + heading // 90)
        moves.append(np.stack(block, axis=1).reshape(-1))  # [4 * state + action]
        pixels += [(left + TILE * c + TILE // 2, left + TILE * r + TILE // 2) for c, r, _ in cells]
        sprites += [2 * h for _, _, h in cells]
        tiles += [8 * c + r for c, r, _ in cells]
    return np.concatenate(moves), np.array(pixels, dtype=np.int64), np.array(sprites), np.array(tiles), base


# ------------------------------------------------------------------------------------------------------- options
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
        specs["initial_command_count"] = Option(1, "int", 1, None, doc="commands of the first round")
    else:
        high = MAX_VECTOR_COMMANDS if vector_observation else None
        specs["command_count"] = Option([10], "int_list", 1, high, doc="number of commands (one entry sampled)")
    if clue_phase:
        specs["command_show_duration"] = Option([3], "int_list", 1, None, doc="frames each icon is shown")
        specs["command_show_delay"] = Option([1], "int_list", 0, None, doc="blank frames after each icon")
    specs["explosion_duration"] = Option(duration, "int_list", 1, None, doc="steps the tiles stay lethal (E)")
    specs["explosion_delay"] = Option(delay, "int_list", 1, None, doc="steps to reach the next target (D)")
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


# ---------------------------------------------------------------------------------------------------------- core
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
    ("completed_total", 1, "passed checks over all rounds (endless)"),
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
SLOT_COLUMNS = {name: sum(width for _, width, _ in SLOT_FIELDS[:i]) for i, (name, _, _) in enumerate(SLOT_FIELDS)}
SLOT_WIDTH = sum(width for _, width, _ in SLOT_FIELDS)
AGENT_COLUMNS = slice(SLOT_COLUMNS["pos"], SLOT_WIDTH)  # (x, y, sprite, sheet)


class MortarMayhemCore(BatchedCore):
    """All Mortar Mayhem variants, batched over ``num_envs`` slots.

    The act phase of the reference counts up two counters (to D while the tiles are safe, to E while they are
    lethal); here one countdown per slot, ``timer``, holds the steps left until the next event: a check (safe
    phase) or the release (lethal phase). A step with ``timer == 0`` is that event, every other act step counts
    down, and every step of the lethal phase that is not the release checks the agent's tile.
    """

    def __init__(
        self,
        num_envs: int = 1,
        options: dict[str, Any] | None = None,
        *,
        grid: bool = False,
        clue_phase: bool = True,
        vector_observation: bool = False,
        endless: bool = False,
        spawn_jitter: bool = False,
    ) -> None:
        if endless and (grid or not clue_phase or vector_observation):
            raise ValueError("the endless variant has free movement, a clue phase and image observations only")
        self.grid, self.clue_phase, self.endless = grid, clue_phase, endless
        self.vector_observation, self.spawn_jitter = vector_observation, spawn_jitter
        self.env_name = variant_name(grid, vector_observation, endless)
        self.option_specs = option_specs(grid, clue_phase, vector_observation, endless)
        self.single_action_space = gym.spaces.Discrete(4) if grid else gym.spaces.MultiDiscrete([3, 3])
        image = gym.spaces.Box(0, 255, (SCREEN, SCREEN, 3), np.uint8)
        if vector_observation:
            vector = gym.spaces.Box(0.0, 1.0, (MAX_VECTOR_COMMANDS * 9,), np.float32)
            self.single_observation_space = gym.spaces.Dict({"visual_observation": image, "vector_observation": vector})
        else:
            self.single_observation_space = image
        self.base_render_fps = 6 if grid else 25
        if endless:
            self.has_ground_truth_info = True
            self.ground_truth_space = gym.spaces.Box(0.0, 1.0, (2,), np.float32)
        super().__init__(num_envs, options)
        self._allocate(self.num_envs)

    def _allocate(self, n: int) -> None:
        self.frames = np.zeros((n, SCREEN, SCREEN, 3), dtype=np.uint8)
        self.frames_rows = self.frames.reshape(n, SCREEN, SCREEN * 3)  # a sprite row is one contiguous byte run
        self.vector = np.zeros((n, MAX_VECTOR_COMMANDS * 9), dtype=np.float32)
        self.backgrounds, self.background_index = backgrounds()
        self.slot_state = np.zeros((n, SLOT_WIDTH), dtype=np.int64)
        for name, width, _ in SLOT_FIELDS:
            start = SLOT_COLUMNS[name]
            setattr(self, name, self.slot_state[:, start] if width == 1 else self.slot_state[:, start : start + width])
        self.shown[:] = -1  # nothing drawn yet
        self.commands = np.zeros((n, 16), np.int64)
        self.slot_rewards = np.zeros((n, 3))  # one row per slot, so that a reset writes it in one assignment
        self.reward_failure, self.reward_success, self.reward_episode = self.slot_rewards.T
        self.visual_feedback = np.ones(n, bool)
        self.tiles_on = np.zeros(n, bool)
        # clue stream: the icon (command, or -1 for a blank frame) of every frame; `clue_pos` is the frame on screen
        self.stream = np.full((n, 64), -1, np.int64)
        # The reference caches the sprite (and rect) it drew last, and after a reset still shows it in the debug
        # view and, in the endless variant, during the first clue stream. ``stale``: the slot shows that sprite
        # (``drawn``: x, y, sprite, sheet; valid once anything was drawn) instead of its agent. It is set at reset
        # and cleared by the first step that draws the agent.
        self.drawn = np.zeros((n, 4), np.int64)
        self.drawn_valid = np.zeros(n, bool)
        self.stale = np.zeros(n, bool)
        self._rng_seen: list[np.random.Generator | None] = [None] * n  # the generator of each slot's last reset
        self._sheets: list[SpriteSheet] = [agent_sheet(AGENT_SCALE)]
        self._sheet_scales: list[float] = [AGENT_SCALE]
        self._free_moves = FreeMoves()
        self._grid_moves = grid_moves()
        self._all = np.arange(n)

    # test and tooling views of the agent state
    @property
    def x(self) -> np.ndarray:
        return self.pos[:, 0]

    @property
    def y(self) -> np.ndarray:
        return self.pos[:, 1]

    @property
    def heading(self) -> np.ndarray:
        return 45 * self.sprite

    @property
    def target_x(self) -> np.ndarray:
        return self.target[:, 0]

    @property
    def target_y(self) -> np.ndarray:
        return self.target[:, 1]

    # ------------------------------------------------------------------------------------------------ reset
    def _reset_slots(self, slots: list[int], rngs: list[np.random.Generator], opts: dict[str, Any]) -> None:
        """Build the levels of ``slots`` and draw their first frames. Each slot's draws run in the reference's
        order and its state is gathered into one row; then all the rows, commands and frames are written at once."""
        if len(set(slots)) < len(slots):  # a slot reset twice in one call: only its last level may remain
            for k, rng in zip(slots, rngs, strict=True):
                self._reset_slots([k], [rng], opts)
            return
        size = ENDLESS_ARENA if self.endless else opts["arena_size"]
        left = arena_left(size)
        allowed = opts["allowed_commands"]
        max_steps = opts.get("max_steps", -1)
        count_list = opts.get("command_count", [opts.get("initial_command_count")])
        lists = [opts["explosion_duration"], opts["explosion_delay"]]
        if self.clue_phase:
            lists = [opts["command_show_duration"], opts["command_show_delay"], *lists]
        choices = sum(len(values) > 1 for values in lists)
        # Each draw below with a range > 1 uses one word (a list of valid commands holds >= 2 entries), so all
        # words can be drawn at once when the command count is fixed; else the count is drawn first.
        words = 1 + 2 * self.spawn_jitter + (len(count_list) > 1)
        if len(count_list) == 1:
            count = int(count_list[0])
            words += count + choices
        picks = [int(values[0]) for values in lists]  # drawn per slot only when a list offers a choice
        walk = command_walk(size, allowed, torus=self.endless)  # endless: any allowed command, the targets wrap
        sheet = self._sheet_for(AGENT_SCALE if self.grid else opts["agent_scale"])
        grid_base = self._grid_moves[4][size]
        if not self.grid:
            radius = int(25 * self._sheet_scales[sheet])
            config = (opts["agent_speed"], radius, 0 if self.endless else left, left + TILE * size, self.endless)
        background = int(self.background_index[size, 0, 0, 0])
        scale = self._sheet_scales[sheet]
        rows, commands, streams, spawns = [], [], [], []
        seen, cells, jitter = self._rng_seen, size * size, self.spawn_jitter
        for k, rng in zip(slots, rngs, strict=True):
            draws = BoundedDraws(rng, words, fresh=rng is not seen[k])  # a new generator has drawn nothing
            seen[k] = rng
            tile = draws.below(cells)
            start_x, start_y = divmod(tile, size)  # the spawn tile (the jitter keeps the centre inside it)
            x, y = left + TILE * start_x + TILE // 2, left + TILE * start_y + TILE // 2
            if jitter:
                x, y = x + draws.below(4) - 2, y + draws.below(4) - 2
            if len(count_list) > 1:
                count = int(count_list[draws.below(len(count_list))])
                draws.reserve(count + choices)
            walked = walk_commands(draws, walk, tile, count)
            if choices:
                picks = [int(values[draws.below(len(values))]) for values in lists]
            draws.close()
            duration, delay = picks[:2] if self.clue_phase else (0, 0)
            lethal_steps, act_steps = picks[-2:]

            dx, dy = COMMAND_DELTAS[walked[0]]
            tx, ty = start_x + dx, start_y + dy
            if self.endless:
                tx, ty = tx % size, ty % size
            move = (0, 0) if self.grid else self._free_moves.key(config, x, y)
            period = duration + delay
            length = count * period
            icon = walked[0] if duration else -1
            # the fields of SLOT_FIELDS, in order; the first act step is not a check (the reference's step counter
            # starts at 0), and the reset frame shows the clue stream's first frame
            rows.append(
                [count, allowed, size, left, lethal_steps, act_steps, max_steps]
                + [grid_base + (start_x * size + start_y) * 4, *move, tx, ty, 8 * tx + ty]
                + [0, act_steps, 0, 0, 0, 0, max(length - 1, 0), max(period, 1), duration, 0]
                + [background, background, x, y, 0, sheet, icon, x, y, 0, sheet]
            )
            commands.append(walked)
            spawns.append((background, x, y, scale))
            if self.clue_phase:
                streams.append([c for command in walked for c in [command] * duration + [-1] * delay])

        ks = np.array(slots, dtype=np.int64)
        stale = self.stale[ks]  # else the sprite drawn last is this slot's agent: keep it (see the module doc)
        drawing = ks[~stale] if stale.any() else ks
        self.drawn[drawing] = self.slot_state[drawing, AGENT_COLUMNS]
        self.stale[ks] = True
        self.slot_state[ks] = rows
        width = max(len(walked) for walked in commands)
        self._ensure_commands(width)
        padded = any(len(walked) < width for walked in commands)
        if padded:  # commands past a slot's count are never read
            commands = [walked + [0] * (width - len(walked)) for walked in commands]
        commands = np.array(commands, dtype=np.int64)
        self.commands[ks, :width] = commands
        self.slot_rewards[ks] = (
            opts["reward_command_failure"],
            opts["reward_command_success"],
            opts.get("reward_episode_success", 0.0),
        )
        self.visual_feedback[ks] = opts["visual_feedback"]
        self.tiles_on[ks] = False
        if self.clue_phase:
            self._ensure_stream(max(len(stream) for stream in streams))
            for k, stream in zip(slots, streams, strict=True):
                self.stream[k, : len(stream)] = stream
        if self.vector_observation:  # one one-hot block of 9 per command, zeros past the count
            one_hot = ONE_HOT[commands]
            if padded:
                one_hot[np.arange(width) >= self.num_commands[ks, None]] = 0.0
            self.vector[ks, : 9 * width] = one_hot.reshape(len(ks), 9 * width)
            if width < MAX_VECTOR_COMMANDS:
                self.vector[ks, 9 * width :] = 0.0
        store = spawn_frames()
        spawn_ids = store.ids(spawns)  # first: drawing new frames may replace the stack
        self.frames[ks] = store.stack[spawn_ids]
        if self.clue_phase:  # the clue stream's first frame shows the first command's icon
            icons = self.shown[ks, 5]
            corner = np.full(len(ks), ICON_CORNER)
            icon_sheet().paste(self.frames_rows, ks, corner, corner, icons)

    def _ensure_commands(self, count: int) -> None:
        if count > self.commands.shape[1]:
            self.commands = _grown(self.commands, count, 0)

    def _ensure_stream(self, length: int) -> None:
        if length > self.stream.shape[1]:
            self.stream = _grown(self.stream, length, -1)

    def _sheet_for(self, scale: float) -> int:
        if scale not in self._sheet_scales:
            self._sheet_scales.append(scale)
            self._sheets.append(agent_sheet(scale))
        return self._sheet_scales.index(scale)

    # ------------------------------------------------------------------------------------------------- step
    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        slots = self._all[idx]
        stale = self.stale[idx]
        if stale.any():
            self._first_step(slots[stale])
        clue_slots = slots[:0]
        icons = None  # the icon of every stepped slot (-1: none); None: no icon anywhere
        if self.clue_phase:
            clue = self.clue_left[idx] > 0
            if clue.any():
                clue_slots = slots if clue.all() else slots[clue]
                # the next frame of the command stream; the agent is frozen and the action ignored
                clue_pos = self.clue_pos[clue_slots] + 1
                self.clue_pos[clue_slots] = clue_pos
                self.clue_left[clue_slots] -= 1
                icons = np.full(len(slots), -1)
                icons[clue] = self.stream[clue_slots, clue_pos]
        if not len(clue_slots):
            rewards, terminated = self._act(idx, actions)
        else:
            rewards, terminated = np.zeros(len(slots)), np.zeros(len(slots), dtype=bool)
            if len(clue_slots) < len(slots):
                act_at = np.flatnonzero(~clue)
                rewards[act_at], terminated[act_at] = self._act(slots[act_at], actions[act_at])
        if self.endless:
            self.t[idx] += 1
            terminated |= self.t[idx] == self.max_steps[idx]
        drawn = slice(None) if isinstance(idx, slice) else slots
        agents = self.slot_state[drawn, AGENT_COLUMNS]  # x, y, sprite, sheet (a view when `drawn` is a slice)
        stale = self.stale[drawn] if self.endless else None  # only the endless clue keeps a stale sprite on screen
        if stale is not None and stale.any():  # the stream after a reset shows the sprite of an earlier episode
            agents = agents.copy()
            agents[stale] = self.drawn[slots[stale]]
        self._compose(drawn, slots, agents, icons)
        return rewards, terminated

    def _first_step(self, ks: np.ndarray) -> None:
        """The first step after a reset draws this episode's agent (facing up during a clue), except in the endless
        variant's clue stream: the sprite drawn last (the previous episode's) stays there until the agent acts."""
        if self.endless:
            ks = ks[(self.clue_left[ks] == 0) | ~self.drawn_valid[ks]]
        self.stale[ks] = False
        self.drawn_valid[ks] = True

    def _act(self, sel: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Move, then run the act phase. ``sel`` are slots outside the clue phase."""
        if self.grid:
            key = self._grid_moves[0][4 * self.grid_key[sel] + actions.reshape(-1)]
            self.grid_key[sel] = key
            pos, sprite, tile_id = self._grid_moves[1][key], self._grid_moves[2][key], self._grid_moves[3][key]
        else:
            code = actions.reshape(-1, 2) @ CODE_WEIGHTS
            moves = self._free_moves
            key = moves.move[self.move_key[sel] + 2 * code[:, None]]
            self.move_key[sel] = key
            pos = moves.coord[key]
            turn = HEADING_SPRITE[code]
            sprite = np.where(turn < 0, self.sprite[sel], turn)
            tile_id = None
        self.pos[sel], self.sprite[sel] = pos, sprite

        timer = self.timer[sel]
        event = timer == 0
        self.timer[sel] = timer - 1  # events set their own timer below
        lethal = self.tiles_on[sel]  # a view when `sel` is a slice: every mask derived from it is taken below
        watched = lethal | event
        rewards = np.zeros(len(pos))
        terminated = np.zeros(len(pos), dtype=bool)
        if not watched.any():
            return rewards, terminated
        if tile_id is None:
            tile_id = self._free_moves.tile[key].sum(axis=1)
        on_target = tile_id == self.target_id[sel]
        dies = lethal & ~event & ~on_target  # a lethal step that is not the release
        if dies.any():
            rewards[dies] = self.reward_failure[self._all[sel][dies]]
            terminated |= dies
        if event.any():
            slots = self._all[sel]
            releases, checks = event & lethal, event & ~lethal  # both before the handlers change `lethal` (a view)
            if releases.any():
                self._release(slots[releases])
            if checks.any():
                rewards[checks], terminated[checks] = self._check(slots[checks], on_target[checks])
        return rewards, terminated

    def _check(self, ks: np.ndarray, on_target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Command checks: all tiles but the target turn lethal; pass or end the episode."""
        current = self.current[ks] + 1
        self.current[ks] = current
        self.completed_total[ks] += on_target
        failure = self.reward_failure[ks]
        rewards = np.where(on_target, self.reward_success[ks], failure)
        terminated = ~on_target
        round_over = current >= self.num_commands[ks]
        if not self.endless:  # the last check ends the episode as a success, whatever its outcome
            self.success[ks] = round_over
            rewards = rewards + np.where(round_over, self.reward_episode[ks], 0.0)
            terminated |= round_over
        # the same step is the first of the lethal phase: standing elsewhere is failure (assigned, not added)
        rewards = np.where(on_target, rewards, failure)
        self.tiles_on[ks] = True
        self.timer[ks] = self.lethal_steps[ks] - 1
        self._paint(ks)
        if self.endless:
            for k in ks[round_over].tolist():
                self._next_round(k)
        return rewards, terminated

    def _release(self, ks: np.ndarray) -> None:
        """The lethal phase is over: tiles back to blue, and the target moves on by the next command."""
        self.tiles_on[ks] = False
        self.timer[ks] = self.act_steps[ks] - 1
        current = self.current[ks]
        more = current < self.num_commands[ks]
        command = self.commands[ks, np.minimum(current, self.commands.shape[1] - 1)]
        target = self.target[ks] + COMMAND_STEP[command] * more[:, None]
        if self.endless:
            target %= ENDLESS_ARENA
        self.target[ks] = target
        self.target_id[ks] = 8 * target[:, 0] + target[:, 1]
        self._paint(ks)

    def _next_round(self, k: int) -> None:
        """Endless: after a round's last check, append one command and show only its icon; the tiles stay lethal."""
        count = int(self.num_commands[k])
        self._ensure_commands(count + 1)
        command = int(self.rngs[k].integers(0, int(self.allowed[k])))  # one draw: numpy's own call is cheapest
        self.commands[k, count] = command
        self.num_commands[k] = count + 1
        self.current[k] = 0
        period, duration = int(self.stream_period[k]), int(self.stream_duration[k])
        self.stream[k, :period] = [command] * duration + [-1] * (period - duration)
        self.clue_pos[k] = -1  # the stream starts on the next step
        self.clue_left[k] = period
        self.debug_lag[k] = 1

    # ---------------------------------------------------------------------------------------------- drawing
    def _paint(self, ks: np.ndarray) -> None:
        """Backgrounds of slots whose tiles changed colour: all red but the target, or all blue."""
        red = self.tiles_on[ks] & self.visual_feedback[ks]
        target = self.target[ks]
        self.background_id[ks] = self.background_index[self.size[ks], red.view(np.uint8), target[:, 0], target[:, 1]]

    def _compose(self, sel: Index, slots: np.ndarray, agents: np.ndarray, icons: np.ndarray | None) -> None:
        """Frames of ``slots`` (= ``sel`` as an index): background, the agent sprite (``agents``: x, y, sprite, sheet)
        and the icon (``icons``, -1 for none). Only frames whose picture changed are drawn again."""
        shown = np.empty((len(slots), 6), dtype=np.int64)
        shown[:, 0] = self.background_id[sel]
        shown[:, 1:5] = agents
        shown[:, 5] = -1 if icons is None else icons
        changed = (shown != self.shown[sel]).any(axis=1)
        if not changed.any():
            return
        if not changed.all():
            slots, shown = slots[changed], shown[changed]
        self.shown[slots] = shown
        self.frames[slots] = self.backgrounds[shown[:, 0]]
        x, y, sprite, sheet_ids = shown[:, 1], shown[:, 2], shown[:, 3], shown[:, 4]
        if len(self._sheets) == 1:
            self._sheets[0].paste(self.frames_rows, slots, y, x, sprite)
        else:
            for s in np.unique(sheet_ids):
                mine = sheet_ids == s
                self._sheets[s].paste(self.frames_rows, slots[mine], y[mine], x[mine], sprite[mine])
        icon = shown[:, 5] >= 0
        if icon.any():
            ks = slots[icon]
            corner = np.full(len(ks), ICON_CORNER)
            icon_sheet().paste(self.frames_rows, ks, corner, corner, shown[icon, 5])

    def _debug_frame(self, k: int) -> np.ndarray:
        frame = self.backgrounds[self.background_id[k]].copy()
        rows = frame.reshape(1, SCREEN, SCREEN * 3)
        zero = np.zeros(1, dtype=np.int64)
        if self.stale[k] and self.drawn_valid[k]:
            x, y, sprite, sheet = self.drawn[k]
        else:
            x, y, sprite, sheet = self.slot_state[k, AGENT_COLUMNS]
        self._sheets[sheet].paste(rows, zero, zero + y, zero + x, zero + sprite)
        if self.clue_left[k] > 0:  # the reference's render keeps its own copy of the stream (see the module doc)
            command = self.stream[k, self.clue_pos[k] + self.debug_lag[k]]
            if command >= 0:
                icon_sheet().paste(rows, zero, zero + ICON_CORNER, zero + ICON_CORNER, zero + command)
        ring, offset = target_ring()
        centre = int(self.left[k]) + TILE // 2
        ring.paste(
            frame, centre + TILE * int(self.target[k, 1]) + offset, centre + TILE * int(self.target[k, 0]) + offset
        )
        return frame

    # ------------------------------------------------------------------------------------------ observation
    def _observation(self, idx: Index) -> np.ndarray | dict[str, np.ndarray]:
        if self.vector_observation:
            return {"visual_observation": self.frames[idx], "vector_observation": self.vector[idx]}
        return self.frames[idx]

    def _final_infos(self, slots: list[int]) -> list[dict[str, Any]]:
        counts = self.num_commands[slots].tolist()
        if self.endless:
            return [
                {"commands_completed": completed, "max_command_sequence": count - 1 if count > 1 else 0}
                for completed, count in zip(self.completed_total[slots].tolist(), counts, strict=True)
            ]
        return [
            {"success": success, "commands_completed": (current - 1 + success) / count}
            for success, current, count in zip(
                self.success[slots].tolist(), self.current[slots].tolist(), counts, strict=True
            )
        ]

    def _step_info(self, k: int) -> dict[str, Any]:
        if self.endless:
            return {"ground_truth": self.target[k] / 5.0}
        return {}

    def render_fps(self, k: int) -> int:
        return CLUE_FPS if self.clue_left[k] > 0 else self.base_render_fps


def _grown(array: np.ndarray, needed: int, fill: int) -> np.ndarray:
    grown = np.full((array.shape[0], max(needed, 2 * array.shape[1])), fill, dtype=array.dtype)
    grown[:, : array.shape[1]] = array
    return grown
