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

# The fixed command list (generation order), its tile offsets, and where each command sits in the one-hot vector.
COMMANDS = ("right", "down", "left", "up", "stay", "right_down", "right_up", "left_down", "left_up")
COMMAND_DX = np.array([1, 0, -1, 0, 0, 1, 1, -1, -1], dtype=np.int64)
COMMAND_DY = np.array([0, 1, 0, -1, 0, 1, -1, 1, -1], dtype=np.int64)
ONE_HOT_INDEX = np.array([1, 4, 2, 3, 0, 5, 6, 7, 8], dtype=np.int64)
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


@cache
def arena_picture(size: int, lethal: bool) -> np.ndarray:
    """The black screen with an all-blue (or all-red) arena of ``size`` x ``size`` tiles centred on it."""
    frame = np.zeros((SCREEN, SCREEN, 3), dtype=np.uint8)
    left = arena_left(size)
    tile = _tile(TILE_RED, TILE_RED_BORDER) if lethal else _tile(TILE_BLUE, TILE_BLUE_BORDER)
    frame[left : left + TILE * size, left : left + TILE * size] = np.tile(tile, (size, size, 1))
    frame.setflags(write=False)
    return frame


@cache
def blue_tile() -> np.ndarray:
    return _tile(TILE_BLUE, TILE_BLUE_BORDER)


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
def valid_commands(size: int, allowed: int) -> tuple[tuple[tuple[int, ...], ...], ...]:
    """For every tile (x, y): the allowed commands, in list order, that keep the walk inside the arena."""
    return tuple(
        tuple(
            tuple(c for c in range(allowed) if 0 <= x + COMMAND_DX[c] < size and 0 <= y + COMMAND_DY[c] < size)
            for y in range(size)
        )
        for x in range(size)
    )


def choice(rng: np.random.Generator, values: list) -> Any:
    """``rng.choice(values)`` with the same RNG consumption (a list of one draws nothing), but faster."""
    return values[int(rng.integers(0, len(values)))] if len(values) > 1 else values[0]


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
    """All Mortar Mayhem variants, batched over ``num_envs`` slots."""

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
        self.background = np.zeros_like(self.frames)  # black screen + arena in its current colours
        self.vector = np.zeros((n, MAX_VECTOR_COMMANDS * 9), dtype=np.float32)
        # level and parameters of each slot's episode
        self.size = np.zeros(n, i64)
        self.left = np.zeros(n, i64)  # arena left/top edge in px
        self.low = np.zeros(n, i64)  # the agent centre is clamped to [low, high] (free movement)
        self.high = np.zeros(n, i64)
        self.speed = np.zeros(n)
        self.radius = np.zeros(n, i64)
        self.sheet_id = np.zeros(n, i64)  # which agent sprite sheet (agent_scale) the slot uses
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
        # dynamic state
        self.x = np.zeros(n, i64)  # agent centre, px
        self.y = np.zeros(n, i64)
        self.heading = np.zeros(n, i64)
        self.target_x = np.zeros(n, i64)  # target tile
        self.target_y = np.zeros(n, i64)
        self.current = np.zeros(n, i64)  # checks so far in this round
        self.command_steps = np.zeros(n, i64)  # counts up to D while the tiles are safe
        self.verify_steps = np.zeros(n, i64)  # counts up to E while the tiles are lethal
        self.tiles_on = np.zeros(n, bool)
        self.success = np.zeros(n, i64)
        self.completed_total = np.zeros(n, i64)  # passed checks over all rounds (endless)
        self.t = np.zeros(n, i64)
        # clue stream: `clue_left` frames still to come; frame f shows command base + f // period if f % period < dur
        self.clue_left = np.zeros(n, i64)
        self.stream_len = np.zeros(n, i64)
        self.stream_base = np.zeros(n, i64)
        self.period = np.ones(n, i64)
        self.duration = np.zeros(n, i64)
        self.debug_lag = np.zeros(n, i64)  # the debug icon runs one frame ahead in the streams between rounds
        self.icon = np.full(n, -1, i64)
        # the sprite drawn last (kept across resets, like the reference's cached sprite and rect)
        self.drawn_x = np.zeros(n, i64)
        self.drawn_y = np.zeros(n, i64)
        self.drawn_heading = np.zeros(n, i64)
        self.drawn_valid = np.zeros(n, bool)
        self.drawn_sheet = np.zeros(n, i64)  # the stale sprite keeps its own agent_scale
        self._sheets: list[SpriteSheet] = [agent_sheet(AGENT_SCALE)]
        self._sheet_scales: list[float] = [AGENT_SCALE]
        self._all = np.arange(n)

    # ------------------------------------------------------------------------------------------------ reset
    def _reset_slot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        size = ENDLESS_ARENA if self.endless else opts["arena_size"]
        left = arena_left(size)
        allowed = opts["allowed_commands"]
        tile = int(rng.integers(0, size * size))
        x, y = left + TILE * (tile // size) + TILE // 2, left + TILE * (tile % size) + TILE // 2
        if self.spawn_jitter:
            jitter = rng.integers(-2, 2, size=2)
            x, y = x + int(jitter[0]), y + int(jitter[1])
        start_x, start_y = (x - left) // TILE, (y - left) // TILE
        if self.endless:
            count = opts["initial_command_count"]
            commands = [int(rng.integers(0, allowed))] if count == 1 else rng.integers(0, allowed, count).tolist()
        else:
            count = int(choice(rng, opts["command_count"]))
            valid = valid_commands(size, allowed)
            commands, cx, cy = [], start_x, start_y
            for _ in range(count):
                options = valid[cx][cy]
                command = options[int(rng.integers(0, len(options)))]
                commands.append(command)
                cx, cy = cx + COMMAND_DX[command], cy + COMMAND_DY[command]
        if self.clue_phase:
            duration = int(choice(rng, opts["command_show_duration"]))
            delay = int(choice(rng, opts["command_show_delay"]))
        else:
            duration = delay = 0
        self.lethal_steps[k] = choice(rng, opts["explosion_duration"])
        self.act_steps[k] = choice(rng, opts["explosion_delay"])

        self._ensure_capacity(count)
        self.commands[k, :count] = commands
        self.num_commands[k] = count
        self.allowed[k] = allowed
        self.size[k], self.left[k] = size, left
        scale = AGENT_SCALE if self.grid else opts["agent_scale"]
        radius = int(25 * scale)
        self.radius[k] = radius
        self.low[k], self.high[k] = left + radius, left + TILE * size - radius
        self.speed[k] = 0.0 if self.grid else opts["agent_speed"]
        self.sheet_id[k] = self._sheet_for(scale)
        self.max_steps[k] = opts.get("max_steps", -1)
        self.reward_failure[k] = opts["reward_command_failure"]
        self.reward_success[k] = opts["reward_command_success"]
        self.reward_episode[k] = opts.get("reward_episode_success", 0.0)
        self.visual_feedback[k] = opts["visual_feedback"]
        self.x[k], self.y[k], self.heading[k] = x, y, 0
        tx, ty = start_x + COMMAND_DX[commands[0]], start_y + COMMAND_DY[commands[0]]
        if self.endless:
            tx, ty = tx % size, ty % size
        self.target_x[k], self.target_y[k] = tx, ty
        self.current[k] = self.command_steps[k] = self.verify_steps[k] = 0
        self.tiles_on[k] = False
        self.success[k] = self.completed_total[k] = self.t[k] = 0
        period = duration + delay
        self.period[k], self.duration[k] = max(period, 1), duration
        self.stream_len[k] = count * period
        self.clue_left[k] = max(count * period - 1, 0)  # the reset frame shows the stream's first frame
        self.stream_base[k] = 0
        self.debug_lag[k] = 0
        self.icon[k] = commands[0] if self.clue_phase else -1
        if self.vector_observation:
            self.vector[k] = 0.0
            self.vector[k, 9 * np.arange(count) + ONE_HOT_INDEX[commands]] = 1.0
        self._paint_background(k)
        one = np.array([k])
        icon_slots = one if self.clue_phase else one[:0]
        self._compose(one, one, np.array([x]), np.array([y]), np.array([0]), self.sheet_id[one], icon_slots)

    def _ensure_capacity(self, count: int) -> None:
        if count > self.commands.shape[1]:
            grown = np.zeros((self.num_envs, max(count, 2 * self.commands.shape[1])), dtype=np.int64)
            grown[:, : self.commands.shape[1]] = self.commands
            self.commands = grown

    def _sheet_for(self, scale: float) -> int:
        if scale not in self._sheet_scales:
            self._sheet_scales.append(scale)
            self._sheets.append(agent_sheet(scale))
        return self._sheet_scales.index(scale)

    # ------------------------------------------------------------------------------------------------- step
    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        slots = self._all[idx]
        rewards = np.zeros(len(slots))
        terminated = np.zeros(len(slots), dtype=bool)
        clue = self.clue_left[idx] > 0
        if clue.any():
            clue_slots = slots[clue]
            self._advance_clue(clue_slots)
            act_at = np.flatnonzero(~clue)
            act: Index = slots[act_at]
        else:
            clue_slots, act_at, act = slots[:0], slice(None), idx
        if not isinstance(act, np.ndarray) or act.size:
            rewards[act_at], terminated[act_at] = self._act(act, actions[act_at])
        if self.endless:
            self.t[idx] += 1
            terminated |= self.t[idx] == self.max_steps[idx]
        drawn = slice(None) if isinstance(idx, slice) else slots
        x, y, heading, sheet = (
            self.drawn_x[drawn],
            self.drawn_y[drawn],
            self.drawn_heading[drawn],
            self.drawn_sheet[drawn],
        )
        self._compose(drawn, slots, x, y, heading, sheet, clue_slots)
        return rewards, terminated

    def _advance_clue(self, ks: np.ndarray) -> None:
        """Show the next frame of the command stream; the agent is frozen and the action ignored."""
        frame = self.stream_len[ks] - self.clue_left[ks]
        period = self.period[ks]
        command = self.commands[ks, self.stream_base[ks] + frame // period]
        self.icon[ks] = np.where(frame % period < self.duration[ks], command, -1)
        self.clue_left[ks] -= 1
        if self.endless:  # the sprite drawn last stays (the reference caches it); only a fresh instance has none
            ks = ks[~self.drawn_valid[ks]]
            self.drawn_heading[ks] = 0
        else:
            self.drawn_heading[ks] = 0  # drawn facing up; a grid agent's heading also stays up until it acts
        self.drawn_x[ks], self.drawn_y[ks], self.drawn_sheet[ks] = self.x[ks], self.y[ks], self.sheet_id[ks]
        self.drawn_valid[ks] = True

    def _act(self, sel: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Move, then run the command checks of the act phase. ``sel`` are slots outside the clue phase."""
        left = self.left[sel]
        if self.grid:
            cx, cy, heading = grid_step(
                actions, (self.x[sel] - left) // TILE, (self.y[sel] - left) // TILE, self.heading[sel], self.size[sel]
            )
            x, y = left + TILE * cx + TILE // 2, left + TILE * cy + TILE // 2
        else:
            actions = actions.reshape(-1, 2)
            heading = continuous_heading(actions, self.heading[sel])
            vx, vy = continuous_velocity(actions, self.speed[sel], truncate=not self.endless)
            if self.endless:  # float moves, rounded by the integer rect, then wrapped around the torus
                x = self._wrap(round_half_away(self.x[sel] + vx), sel)
                y = self._wrap(round_half_away(self.y[sel] + vy), sel)
            else:
                low, high = self.low[sel], self.high[sel]
                x = clamp_centre(self.x[sel] + vx.astype(np.int64), low, high)
                y = clamp_centre(self.y[sel] + vy.astype(np.int64), low, high)
        self.x[sel], self.y[sel], self.heading[sel] = x, y, heading
        self.drawn_x[sel], self.drawn_y[sel], self.drawn_heading[sel] = x, y, heading
        self.drawn_sheet[sel] = self.sheet_id[sel]
        self.drawn_valid[sel] = True
        on_target = ((x - left) // TILE == self.target_x[sel]) & ((y - left) // TILE == self.target_y[sel])

        rewards = np.zeros(len(x))
        terminated = np.zeros(len(x), dtype=bool)
        # copies: with a slice `sel` these would be views, and the tile state is written back below
        command_steps, tiles_on = self.command_steps[sel], self.tiles_on[sel].copy()
        verify = (command_steps % self.act_steps[sel] == 0) & (command_steps > 0) & ~tiles_on
        lethal = tiles_on
        if verify.any():
            slots = self._all[sel]
            current, count = self.current[sel], self.num_commands[sel]
            check = verify & (current < count)
            current = current + check
            passed = check & on_target
            rewards = np.where(check, np.where(on_target, self.reward_success[sel], self.reward_failure[sel]), 0.0)
            terminated = check & ~on_target
            round_over = verify & (current >= count)
            self.current[sel] = current
            self.completed_total[sel] += passed
            command_steps = np.where(verify, 1, command_steps)
            lethal = tiles_on | check
            if self.endless:
                for k in slots[round_over]:
                    self._next_round(int(k))
            else:
                terminated |= round_over
                rewards = rewards + np.where(round_over, self.reward_episode[sel], 0.0)
                self.success[sel] = round_over
            self.tiles_on[sel] = lethal
            for k in slots[check]:
                self._paint_background(int(k))
        if lethal.any():
            slots = self._all[sel]
            verify_steps = self.verify_steps[sel]  # read after the checks: a new endless round restarts the count
            release = lethal & (verify_steps % self.lethal_steps[sel] == 0) & (verify_steps > 0)
            hold = lethal & ~release
            dies = hold & ~on_target
            terminated = terminated | dies
            rewards = np.where(dies, self.reward_failure[sel], rewards)  # an assignment in the reference
            self.verify_steps[sel] = np.where(release, 0, verify_steps + hold)
            if release.any():
                self.tiles_on[sel] = lethal & ~release
                for k in slots[release]:
                    self._release(int(k))
        self.command_steps[sel] = command_steps + ~lethal
        return rewards, terminated

    def _wrap(self, v: np.ndarray, sel: Index) -> np.ndarray:
        """Torus wrap of the endless arena: past half a radius beyond an edge, jump to the opposite side.

        Both tests see the unrounded jump target (-3.5 is not < -3.5); the rect rounds it afterwards.
        """
        margin = self.radius[sel] * 0.5
        v = np.where(v > SCREEN + margin, -margin, v)
        return round_half_away(np.where(v < -margin, SCREEN + margin, v))

    def _next_round(self, k: int) -> None:
        """Endless: after a round's last check, append one command and show only its icon; the tiles stay lethal."""
        count = int(self.num_commands[k])
        self._ensure_capacity(count + 1)
        self.commands[k, count] = int(self.rngs[k].integers(0, int(self.allowed[k])))
        self.num_commands[k] = count + 1
        self.current[k] = 0
        self.verify_steps[k] = 0
        period = int(self.period[k])
        self.stream_len[k] = self.clue_left[k] = period
        self.stream_base[k] = count
        self.debug_lag[k] = 1

    def _release(self, k: int) -> None:
        """The lethal phase is over: tiles back to blue, and the target moves on by the next command."""
        if self.current[k] < self.num_commands[k]:
            command = self.commands[k, self.current[k]]
            tx, ty = self.target_x[k] + COMMAND_DX[command], self.target_y[k] + COMMAND_DY[command]
            if self.endless:
                tx, ty = tx % ENDLESS_ARENA, ty % ENDLESS_ARENA
            self.target_x[k], self.target_y[k] = tx, ty
        self._paint_background(k)

    # ---------------------------------------------------------------------------------------------- drawing
    def _paint_background(self, k: int) -> None:
        size = int(self.size[k])
        if self.tiles_on[k] and self.visual_feedback[k]:
            self.background[k] = arena_picture(size, True)
            left = int(self.left[k])
            r, c = left + TILE * int(self.target_y[k]), left + TILE * int(self.target_x[k])
            self.background[k, r : r + TILE, c : c + TILE] = blue_tile()
        else:
            self.background[k] = arena_picture(size, False)

    def _compose(
        self,
        sel: Index,
        slots: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        heading: np.ndarray,
        sheet_ids: np.ndarray,
        icon_slots: np.ndarray,
    ) -> None:
        """Frames of ``slots`` (= ``sel`` as an index): background, the agent sprite, and the icon of clue slots."""
        self.frames[sel] = self.background[sel]
        which = heading // 45
        if len(self._sheets) == 1:
            self._sheets[0].paste(self.frames_rows, slots, y, x, which)
        else:
            for s in np.unique(sheet_ids):
                mine = sheet_ids == s
                self._sheets[s].paste(self.frames_rows, slots[mine], y[mine], x[mine], which[mine])
        if len(icon_slots):
            icons = self.icon[icon_slots]
            shown = icons >= 0
            if shown.any():
                ks, icons = icon_slots[shown], icons[shown]
                corner = np.full(len(ks), ICON_CORNER)
                icon_sheet().paste(self.frames_rows, ks, corner, corner, icons)

    def _debug_frame(self, k: int) -> np.ndarray:
        frame = self.background[k].copy()
        rows = frame.reshape(1, SCREEN, SCREEN * 3)
        zero = np.zeros(1, dtype=np.int64)
        if self.drawn_valid[k]:
            x, y, heading, sheet = self.drawn_x[k], self.drawn_y[k], self.drawn_heading[k], self.drawn_sheet[k]
        else:
            x, y, heading, sheet = self.x[k], self.y[k], 0, self.sheet_id[k]
        self._sheets[sheet].paste(rows, zero, zero + y, zero + x, zero + heading // 45)
        if self.clue_left[k] > 0:  # the reference's render keeps its own copy of the stream (see the module doc)
            frame_no = self.stream_len[k] - 1 - self.clue_left[k] + self.debug_lag[k]
            if frame_no % self.period[k] < self.duration[k]:
                command = self.commands[k, self.stream_base[k] + frame_no // self.period[k]]
                icon_sheet().paste(rows, zero, zero + ICON_CORNER, zero + ICON_CORNER, zero + command)
        ring, offset = target_ring()
        centre = int(self.left[k]) + TILE // 2
        ring.paste(
            frame, centre + TILE * int(self.target_y[k]) + offset, centre + TILE * int(self.target_x[k]) + offset
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
            return {"ground_truth": np.array([self.target_x[k], self.target_y[k]], dtype=np.float64) / 5.0}
        return {}

    def render_fps(self, k: int) -> int:
        return CLUE_FPS if self.clue_left[k] > 0 else self.base_render_fps
