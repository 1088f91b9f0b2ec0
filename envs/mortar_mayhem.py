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
COMMAND_DX = np.array([dx for dx, _ in COMMAND_DELTAS], dtype=np.int64)
COMMAND_DY = np.array([dy for _, dy in COMMAND_DELTAS], dtype=np.int64)
ONE_HOT_INDEX = (1, 4, 2, 3, 0, 5, 6, 7, 8)
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
    """Every arena picture, stacked, and the index of each: ``[size, 0, 0]`` all blue, ``[size, 1 + x, y]`` all red
    but tile (x, y). Painting the backgrounds of many slots is then one gather."""
    pictures = []
    index = np.full((ENDLESS_ARENA + 1, ENDLESS_ARENA + 1, ENDLESS_ARENA), -1, dtype=np.int64)
    for size in range(2, ENDLESS_ARENA + 1):
        index[size, 0, 0] = len(pictures)
        pictures.append(arena_picture(size))
        for x in range(size):
            for y in range(size):
                index[size, 1 + x, y] = len(pictures)
                pictures.append(arena_picture(size, (x, y)))
    stack = np.stack(pictures)
    stack.setflags(write=False)
    return stack, index


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
def command_walk(size: int, allowed: int) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]:
    """For every tile ``x * size + y``: the allowed commands, in list order, that keep the walk inside the arena,
    and the tile each of them leads to."""
    steps = []
    for x in range(size):
        for y in range(size):
            valid = [
                c for c, (dx, dy) in enumerate(COMMAND_DELTAS[:allowed]) if 0 <= x + dx < size and 0 <= y + dy < size
            ]
            steps.append(
                (tuple(valid), tuple((x + COMMAND_DELTAS[c][0]) * size + y + COMMAND_DELTAS[c][1] for c in valid))
            )
    return tuple(steps)


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
        i64 = np.int64
        self.frames = np.zeros((n, SCREEN, SCREEN, 3), dtype=np.uint8)
        self.frames_rows = self.frames.reshape(n, SCREEN, SCREEN * 3)  # a sprite row is one contiguous byte run
        self.vector = np.zeros((n, MAX_VECTOR_COMMANDS * 9), dtype=np.float32)
        self.backgrounds, self.background_index = backgrounds()
        # black screen + arena in its current colours (a per-slot copy: copying it is cheaper than gathering)
        self.background = np.zeros_like(self.frames)
        # level and parameters of each slot's episode
        self.size = np.zeros(n, i64)
        self.left = np.zeros(n, i64)  # arena left/top edge in px
        self.sheet_id = np.zeros(n, i64)  # agent sprite sheet (agent_scale) of the slot
        self.commands = np.zeros((n, 16), i64)
        self.num_commands = np.zeros(n, i64)
        self.allowed = np.zeros(n, i64)
        self.lethal_steps = np.ones(n, i64)  # E
        self.act_steps = np.ones(n, i64)  # D
        self.max_steps = np.zeros(n, i64)
        self.reward_failure = np.zeros(n)
        self.reward_success = np.zeros(n)
        self.reward_episode = np.zeros(n)
        self.visual_feedback = np.ones(n, bool)
        # agent: movement keys (free: one per axis; grid: one state), centre in px and sprite index (heading // 45)
        self.move_key = np.zeros((n, 2), i64)
        self.grid_key = np.zeros(n, i64)
        self.pos = np.zeros((n, 2), i64)
        self.sprite = np.zeros(n, i64)
        # the act phase
        self.target = np.zeros((n, 2), i64)
        self.target_id = np.zeros(n, i64)  # 8 * column + row, compared with the agent's tile id
        self.current = np.zeros(n, i64)  # checks so far in this round
        self.timer = np.zeros(n, i64)  # steps to the next check (safe tiles) or release (lethal tiles)
        self.tiles_on = np.zeros(n, bool)
        self.success = np.zeros(n, i64)
        self.completed_total = np.zeros(n, i64)  # passed checks over all rounds (endless)
        self.t = np.zeros(n, i64)
        # clue stream: the icon (command, or -1 for a blank frame) of every frame; `clue_pos` is the frame on screen
        self.stream = np.full((n, 64), -1, i64)
        self.clue_pos = np.zeros(n, i64)
        self.clue_left = np.zeros(n, i64)  # frames still to come
        self.stream_period = np.ones(n, i64)
        self.stream_duration = np.zeros(n, i64)
        self.debug_lag = np.zeros(n, i64)  # the debug icon runs one frame ahead in the streams between rounds
        # The reference caches the sprite (and rect) it drew last, and after a reset still shows it in the debug
        # view and, in the endless variant, during the first clue stream. ``stale``: the slot shows that sprite
        # (`drawn_*`, valid once anything was drawn) instead of its agent. It is set at reset and cleared by the
        # first step that draws the agent.
        self.drawn_pos = np.zeros((n, 2), i64)
        self.drawn_sprite = np.zeros(n, i64)
        self.drawn_sheet = np.zeros(n, i64)
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
    def _reset_slot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        size = ENDLESS_ARENA if self.endless else opts["arena_size"]
        left = arena_left(size)
        allowed = opts["allowed_commands"]
        count_list = opts.get("command_count", [opts.get("initial_command_count")])
        lists = [opts["explosion_duration"], opts["explosion_delay"]]
        if self.clue_phase:
            lists = [opts["command_show_duration"], opts["command_show_delay"], *lists]
        choices = sum(len(values) > 1 for values in lists)
        # Each draw below with a range > 1 uses one word (a list of valid commands holds >= 2 entries), so all
        # words can be drawn at once when the command count is fixed; else the count is drawn first.
        words = 1 + 2 * self.spawn_jitter + (len(count_list) > 1)
        if len(count_list) == 1:
            words += count_list[0] + choices
        draws = BoundedDraws(rng, words, fresh=rng is not self._rng_seen[k])  # a new generator has drawn nothing
        self._rng_seen[k] = rng
        tile = draws.below(size * size)
        x, y = left + TILE * (tile // size) + TILE // 2, left + TILE * (tile % size) + TILE // 2
        if self.spawn_jitter:
            x, y = x + draws.below(4) - 2, y + draws.below(4) - 2
        start_x, start_y = (x - left) // TILE, (y - left) // TILE
        count = int(count_list[draws.below(len(count_list))]) if not self.endless else count_list[0]
        if len(count_list) > 1:
            draws.reserve(count + choices)
        if self.endless:  # uniform over the allowed commands, no validity filter (the targets wrap)
            commands = [draws.below(allowed) for _ in range(count)]
        else:  # a walk that stays inside the arena
            walk = command_walk(size, allowed)
            commands, tile = [], start_x * size + start_y
            for _ in range(count):
                valid, leads_to = walk[tile]
                pick = draws.below(len(valid))
                commands.append(valid[pick])
                tile = leads_to[pick]
        picks = [int(values[draws.below(len(values))]) for values in lists]
        draws.close()
        duration, delay = picks[:2] if self.clue_phase else (0, 0)
        lethal_steps, act_steps = picks[-2:]

        if not self.stale[k]:  # the sprite drawn last is this slot's agent: keep it for the quirks above
            self.drawn_pos[k], self.drawn_sprite[k], self.drawn_sheet[k] = self.pos[k], self.sprite[k], self.sheet_id[k]
        self.stale[k] = True
        self._ensure_commands(count)
        self.commands[k, :count] = commands
        self.num_commands[k], self.allowed[k] = count, allowed
        self.size[k], self.left[k] = size, left
        self.lethal_steps[k], self.act_steps[k] = lethal_steps, act_steps
        self.max_steps[k] = opts.get("max_steps", -1)
        self.reward_failure[k] = opts["reward_command_failure"]
        self.reward_success[k] = opts["reward_command_success"]
        self.reward_episode[k] = opts.get("reward_episode_success", 0.0)
        self.visual_feedback[k] = opts["visual_feedback"]
        scale = AGENT_SCALE if self.grid else opts["agent_scale"]
        self.sheet_id[k] = self._sheet_for(scale)
        if self.grid:
            self.grid_key[k] = self._grid_moves[4][size] + (start_x * size + start_y) * 4
        else:
            radius = int(25 * scale)
            config = (opts["agent_speed"], radius, 0 if self.endless else left, left + TILE * size, self.endless)
            self.move_key[k] = self._free_moves.key(config, x, y)
        self.pos[k] = x, y
        self.sprite[k] = 0
        tx, ty = start_x + COMMAND_DELTAS[commands[0]][0], start_y + COMMAND_DELTAS[commands[0]][1]
        if self.endless:
            tx, ty = tx % size, ty % size
        self.target[k] = tx, ty
        self.target_id[k] = 8 * tx + ty
        self.current[k] = 0
        self.timer[k] = act_steps  # the first act step is not a check (the reference's step counter starts at 0)
        self.tiles_on[k] = False
        self.success[k] = self.completed_total[k] = self.t[k] = 0
        period = duration + delay
        length = count * period
        self._ensure_stream(length)
        if self.clue_phase:
            self.stream[k, :length] = [c for command in commands for c in [command] * duration + [-1] * delay]
        self.clue_pos[k] = 0
        self.clue_left[k] = max(length - 1, 0)  # the reset frame shows the stream's first frame
        self.stream_period[k], self.stream_duration[k] = max(period, 1), duration
        self.debug_lag[k] = 0
        if self.vector_observation:
            vector = self.vector[k]
            vector[:] = 0.0
            vector[[9 * c + ONE_HOT_INDEX[command] for c, command in enumerate(commands)]] = 1.0
        self.background[k] = self.backgrounds[self.background_index[size, 0, 0]]
        self.frames[k] = self.background[k]
        rows = self.frames_rows[k]
        self._sheets[self.sheet_id[k]].paste_one(rows, y, x, 0)  # the new agent, facing up
        if self.clue_phase and duration:
            icon_sheet().paste_one(rows, ICON_CORNER, ICON_CORNER, commands[0])

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
        if self.clue_phase:
            clue = self.clue_left[idx] > 0
            if clue.any():
                clue_slots = slots if clue.all() else slots[clue]
                # the next frame of the command stream; the agent is frozen and the action ignored
                self.clue_pos[clue_slots] += 1
                self.clue_left[clue_slots] -= 1
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
        pos, sprite, sheet = self.pos[drawn], self.sprite[drawn], self.sheet_id[drawn]
        stale = self.stale[drawn] if self.endless else None  # only the endless clue keeps a stale sprite on screen
        if stale is not None and stale.any():  # the stream after a reset shows the sprite of an earlier episode
            pos, sprite, sheet = pos.copy(), sprite.copy(), sheet.copy()
            ks = slots[stale]
            pos[stale], sprite[stale], sheet[stale] = self.drawn_pos[ks], self.drawn_sprite[ks], self.drawn_sheet[ks]
        self._compose(drawn, slots, pos, sprite, sheet, clue_slots)
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
        target = self.target[ks] + np.where(more[:, None], np.stack([COMMAND_DX[command], COMMAND_DY[command]], 1), 0)
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
        which = self.background_index[self.size[ks], np.where(red, 1 + target[:, 0], 0), np.where(red, target[:, 1], 0)]
        self.background[ks] = self.backgrounds[which]

    def _compose(
        self,
        sel: Index,
        slots: np.ndarray,
        pos: np.ndarray,
        sprite: np.ndarray,
        sheet_ids: np.ndarray,
        icon_slots: np.ndarray,
    ) -> None:
        """Frames of ``slots`` (= ``sel`` as an index): background, the agent sprite, and the icon of clue slots."""
        self.frames[sel] = self.background[sel]
        if len(self._sheets) == 1:
            self._sheets[0].paste(self.frames_rows, slots, pos[:, 1], pos[:, 0], sprite)
        else:
            for s in np.unique(sheet_ids):
                mine = sheet_ids == s
                self._sheets[s].paste(self.frames_rows, slots[mine], pos[mine, 1], pos[mine, 0], sprite[mine])
        if len(icon_slots):
            icons = self.stream[icon_slots, self.clue_pos[icon_slots]]
            shown = icons >= 0
            if shown.any():
                ks = icon_slots[shown]
                corner = np.full(len(ks), ICON_CORNER)
                icon_sheet().paste(self.frames_rows, ks, corner, corner, icons[shown])

    def _debug_frame(self, k: int) -> np.ndarray:
        frame = self.background[k].copy()
        rows = frame.reshape(1, SCREEN, SCREEN * 3)
        zero = np.zeros(1, dtype=np.int64)
        if self.stale[k] and self.drawn_valid[k]:
            (x, y), sprite, sheet = self.drawn_pos[k], self.drawn_sprite[k], self.drawn_sheet[k]
        else:
            (x, y), sprite, sheet = self.pos[k], self.sprite[k], self.sheet_id[k]
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

    def _final_info(self, k: int) -> dict[str, Any]:
        if self.endless:
            count = int(self.num_commands[k])
            return {
                "commands_completed": int(self.completed_total[k]),
                "max_command_sequence": count - 1 if count > 1 else 0,
            }
        success = int(self.success[k])
        return {
            "success": success,
            "commands_completed": (int(self.current[k]) - 1 + success) / int(self.num_commands[k]),
        }

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
