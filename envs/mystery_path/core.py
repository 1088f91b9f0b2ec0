"""The Mystery Path core: state of arrays, reset, step and drawing of every slot (see the package docstring)."""

from __future__ import annotations

from itertools import chain
from typing import Any

import gymnasium as gym
import numpy as np

from envs.core import BatchedCore, Index
from envs.drawing import SCREEN, SpriteScatter, SpriteSheet, agent_sprites, blend, round_half_away
from envs.mystery_path.canvas import Canvas, fall_off_cross
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
    INITIAL_SEGMENTS,
    NEW_TILE,
    PATH_TILE,
    REFILL,
    SEGMENT_COLUMNS,
    STAMINA_BAR_WIDTH,
    STAMINA_BARS,
    TILE_BYTE_OFFSETS,
    TILE_EDGE_BYTES,
    TILE_MIDDLE_BYTES,
    WEST,
    ice_background,
    walk_start,
    walk_starts,
)
from envs.mystery_path.generator import draw_level, generate_path, level_grid, skip_level
from envs.mystery_path.level import (
    AFTER_VISIT,
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
    TILE_CENTRES,
    TILE_OF_PIXEL,
    WALL_COLOUR,
    fill_tile,
    velocities,
)
from envs.mystery_path.options import option_specs
from envs.rng import BoundedDraws

SCALAR_SLOTS = 2  # up to this many slots per step are stepped one by one (see MysteryPathCore._step)
BATCHED_WALKS = 4  # a reset of this many endless slots computes their past-path starts with array operations
SEGMENT_GRID = level_grid(GRID, GRID)  # an endless segment's tables; its tiles are indexed 7 * x + y
# 64-bit outputs (two words each) read ahead at once: for a segment that is built, the most words it can use (its
# start and goal rows, its walls and the longest search, see generator.draw_path), so its search needs no second
# read; for a segment that is skipped, a little more than most use (66 words on average, 89 at most in 2000 levels).
LEVEL_OUTPUTS = (2 + SEGMENT_GRID.level_words + 1) // 2
SKIPPED_OUTPUTS = 40
STEP_LIST = DIRECTION_OF_STEP.tolist()  # the same as Python ints


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
        # Agent: centre pixel (x, y) (world coordinates in the endless variant), heading, and where a fall-off puts
        # it back (the free agent is placed `radius` px into the first tile: its centre only with the default scale).
        self.pos = np.zeros((n, 2), dtype=np.int64)
        self.return_pos = np.zeros((n, 2), dtype=np.int64)
        self.heading = np.zeros(n, dtype=np.int64)
        self.velocity = np.zeros((n, len(ENDLESS_ACTIONS if endless else FREE_ACTIONS), 2), dtype=np.int64)
        self.off_path = np.zeros(n, dtype=bool)  # fell off in the last step: goes back this step
        self.cross_visible = np.zeros(n, dtype=bool)
        self.t = np.zeros(n, dtype=np.int64)
        self.num_fails = np.zeros(n, dtype=np.int64)
        self.max_steps = np.zeros(n, dtype=np.int64)
        self.visual_feedback = np.zeros(n, dtype=bool)
        self.reward_table = np.zeros((n, 4), dtype=np.float64)  # reward of a step, by what the agent stepped on
        # Drawing.
        self.agents = SpriteScatter()
        # Endless: the agent sprites of each scale as a sheet (by the id of their first sprite in `agents`), and the
        # sheet of the one scale that every slot uses, if they do: the agents are then pasted through it (see _draw;
        # endless agents stay in one screen column, away from the edges, where a sheet's windows are cheapest).
        self.agent_sheets: dict[int, SpriteSheet] = {}
        self.agent_sheet: tuple[SpriteSheet, int] | None = None  # (sheet, id of its first sprite in `agents`)
        self.crosses = SpriteScatter()
        self.cross_id = self.crosses.add((fall_off_cross(),))
        self.sprite0 = np.zeros(n, dtype=np.int64)  # sprite id of heading 0 at the slot's agent scale
        self.half = np.zeros(n, dtype=np.int64)  # sprite side // 2: top-left = centre - half
        self.canvas = Canvas(n)
        self.canvas.fit(self.crosses)
        if endless:
            self._init_endless(n)
        else:
            self._init_level(n)

    def _init_level(self, n: int) -> None:
        self.status = np.zeros((n, GRID * GRID), dtype=np.int64)  # OFF / PATH / NEW / GOAL per tile 7 * x + y
        self.success = np.zeros(n, dtype=np.int64)
        self.background = np.zeros((n, SCREEN, SCREEN, 3), dtype=np.uint8)
        self.levels: list[Any] = [None] * n  # (origin, goal, layout) per slot, for the debug view
        self.pos_low = np.zeros((n, 1), dtype=np.int64)  # free agent: the centre stays `radius` px inside the screen
        self.pos_high = np.zeros((n, 1), dtype=np.int64)
        self.grid_state = np.zeros(n, dtype=np.int64)  # grid agent: 4 * tile + heading // 90
        self.origin_state = np.zeros(n, dtype=np.int64)  # 4 * origin tile

    def _init_endless(self, n: int) -> None:
        # The path as one chain of tiles (origin first), grown segment by segment; capacities grow on demand.
        capacity = 64
        self.chain_x = np.zeros((n, capacity), dtype=np.int64)
        self.chain_y = np.zeros((n, capacity), dtype=np.int64)
        self.direction = np.full((n, capacity), WEST, dtype=np.int64)  # from chain tile i to tile i + 1
        self.flags = np.zeros((n, capacity), dtype=np.int64)  # NEW_TILE | REFILL
        self.walk_start = np.zeros((n, capacity), dtype=np.int64)  # first tile drawn behind an agent on tile i
        self.chain_lists: list[tuple[list[int], list[int]]] = [([], []) for _ in range(n)]
        # tile_node[slot, x, y + 1]: chain index of a path tile or -1; rows 0 and 8 catch agents above and below.
        self.tile_node = np.full((n, (INITIAL_SEGMENTS + 1) * SEGMENT_COLUMNS, GRID + 2), -1, dtype=np.int64)
        self.num_segments = np.zeros(n, dtype=np.int64)
        self.reference_segments = np.zeros(n, dtype=np.int64)  # segments the reference has built by now
        self.segment_rng: list[np.random.Generator | None] = [None] * n  # the generator that builds them
        self.segment_ends: list[list[int]] = [[] for _ in range(n)]  # chain length after each segment
        self.walks_until = np.zeros(n, dtype=np.int64)  # walk_start is known for the chain tiles before this
        self.prepare_at = np.zeros(n, dtype=np.int64)  # x pixel of the next segment (see _enter_segment)
        self.current_node = np.zeros(n, dtype=np.int64)
        self.draw_from = np.zeros(n, dtype=np.int64)  # past path: chain tiles draw_from .. current_node - 1
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
        self.depth = np.zeros(n, dtype=np.int64)  # columns of past path drawn behind the agent's column
        self.show_past_path = np.zeros(n, dtype=bool)
        self.show_background = np.zeros(n, dtype=bool)
        self.show_stamina = np.zeros(n, dtype=bool)
        self.first_frames: dict[tuple, np.ndarray] = {}  # see _draw_first_frames

    # ------------------------------------------------------------------------------------------- reset
    def _reset_slots(self, slots: list[int], rngs: list[np.random.Generator], opts: dict[str, Any]) -> None:
        # Values that follow from the options are written to all the slots at once; the levels are built slot by slot.
        scale = GRID_AGENT_SCALE if self.grid else opts["agent_scale"]
        first = self.agents.add(agent_sprites(scale))
        self.canvas.fit(self.agents)
        radius = int(25 * scale)
        at = slots[0] if len(slots) == 1 else np.array(slots)  # one slot: scalar writes are cheaper
        self.sprite0[at] = first
        if self.endless:
            sheet = self.agent_sheets.get(first)
            if sheet is None:
                sheet = self.agent_sheets[first] = SpriteSheet(agent_sprites(scale), 0, 0)
            self.agent_sheet = (sheet, first) if self.num_envs == 1 or (self.sprite0 == first).all() else None
        self.half[at] = self.agents.sprites[first].width // 2
        if not self.grid:
            self.velocity[at] = velocities(self.endless, float(opts["agent_speed"]))
        self.t[at] = 0
        self.max_steps[at] = opts["max_steps"]
        self.num_fails[at] = 0
        self.off_path[at] = False
        self.cross_visible[at] = False
        self.visual_feedback[at] = opts["visual_feedback"]
        if self.endless:
            self._reset_endless(slots, at, rngs, opts, radius)
        else:
            for k, rng in zip(slots, rngs, strict=True):
                self._reset_level(k, rng, opts, radius)
                self._draw_slot(k)

    def _reset_level(self, k: int, rng: np.random.Generator, opts: dict[str, Any], radius: int) -> None:
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
        status = self.status[k]
        status[:] = OFF
        for x, y in layout.path[1:-1]:
            status[x * GRID + y] = NEW
        status[origin[0] * GRID + origin[1]] = PATH
        status[goal[0] * GRID + goal[1]] = GOAL
        # Rewards are summed in the reference's order: 0, then the event's reward, then the step reward.
        step = opts["reward_step"]
        self.reward_table[k, OFF] = (0 + opts["reward_fall_off"]) + step
        self.reward_table[k, PATH] = 0 + step
        self.reward_table[k, NEW] = (0 + opts["reward_path_progress"]) + step
        self.reward_table[k, GOAL] = (0 + opts["reward_goal"]) + step
        self.success[k] = 0
        self.heading[k] = 0
        if self.grid:
            self.origin_state[k] = (origin[0] * GRID + origin[1]) * 4
            self.grid_state[k] = self.origin_state[k]  # heading up
            self.pos[k] = TILE_CENTRES[origin[0] * GRID + origin[1]]
        else:
            self.return_pos[k] = (origin[0] * TILE + radius, origin[1] * TILE + radius)
            self.pos[k] = self.return_pos[k]
            self.pos_low[k], self.pos_high[k] = radius, SCREEN - radius
        background = self.background[k]
        background[:] = 0
        if opts["show_origin"]:
            fill_tile(background, origin, ORIGIN_COLOUR)
        if opts["show_goal"]:
            fill_tile(background, goal, GOAL_COLOUR)

    def _reset_endless(
        self, slots: list[int], at: int | np.ndarray, rngs: list[np.random.Generator], opts: dict[str, Any], radius: int
    ) -> None:
        self.depth[at] = int(opts["camera_offset_scale"])
        self.show_past_path[at] = opts["show_past_path"]
        self.show_background[at] = opts["show_background"]
        self.show_stamina[at] = opts["show_stamina"]
        self.current_node[at] = 0
        self.draw_from[at] = 0
        self.heading[at] = 270  # facing right
        step = opts["reward_step"]
        self.reward_table[at, 0] = 0 + step  # index: 1 for a new tile + 2 for a fall-off
        self.reward_table[at, 1] = (0 + opts["reward_path_progress"]) + step
        self.reward_table[at, 2:] = (0 + opts["reward_fall_off"]) + step
        self.stamina_level[at] = opts["stamina_level"]
        self.stamina[at] = opts["stamina_level"]
        self.max_x[at] = 0
        self.tiles_visited[at] = 0
        camera_offset = -TILE * opts["camera_offset_scale"]
        self.camera_offset[at] = camera_offset
        self.camera_x[at] = camera_offset
        self.bg_scroll[at] = 0.0
        # The agent is always drawn at the same screen column: its start column (the path starts in column 0)
        # minus the camera offset.
        self.agent_screen_left[at] = int(radius - self.half[slots[0]] - camera_offset)
        # The levels are drawn slot by slot (each from its own generator, in the reference's order); the arrays of
        # all the slots are then written together: a numpy call costs microseconds whatever its size.
        for k, rng in zip(slots, rngs, strict=True):
            # One block of words for the level (a few dozen words), and before it, if the generator continues, the
            # draws of the segments that the reference built in the last episode and this slot did not.
            draws = BoundedDraws(rng)
            if self.segment_rng[k] is rng:
                skipped = int(self.reference_segments[k]) - len(self.segment_ends[k])
                draws.read_ahead(SKIPPED_OUTPUTS * skipped + LEVEL_OUTPUTS)
                self._skip_segments(k, draws)
            else:
                draws.read_ahead(LEVEL_OUTPUTS)
            self.segment_rng[k] = rng
            self.chain_lists[k] = ([], [])
            self.segment_ends[k] = []
            self._add_segment(k, draws)
            draws.close()
            self.fall_off_tiles[k] = set()
        self.reference_segments[at] = INITIAL_SEGMENTS
        self.num_segments[at] = 1
        self.tile_node[at] = -1
        ends = [self.segment_ends[k][0] for k in slots]
        x, nodes = self._store_chains(slots, [0] * len(slots))
        self.flags[at, 0] = REFILL  # the very first tile pays nothing
        self.ground_truth[at] = self.direction[at, 0]  # never west: the first tile is in column 0
        # The agent enters the first segment: its past-path starts (see _enter_segment).
        if len(slots) < BATCHED_WALKS:
            for k in slots:
                self._store_walks(k, 0, self.segment_ends[k][0])
        else:
            self._store_first_walks(slots, ends, x, nodes, opts)
        self.walks_until[at] = ends[0] if len(slots) == 1 else ends
        self.prepare_at[at] = SEGMENT_COLUMNS * TILE
        start_y = [self.chain_lists[k][1][0] for k in slots]
        y = (start_y[0] if len(slots) == 1 else np.array(start_y)) * TILE + radius
        self.pos[at, 0] = self.return_pos[at, 0] = radius
        self.pos[at, 1] = self.return_pos[at, 1] = y
        self._draw_first_frames(slots, start_y)

    def _draw_first_frames(self, slots: list[int], start_y: list[int]) -> None:
        """Draw the first endless frames of ``slots`` (reset together, so with the same options): a first frame
        depends only on the agent's start row and a few options, so each is drawn once (by :meth:`_draw_slot`) and
        copied afterwards."""
        k = slots[0]
        sprite, offset = int(self.sprite0[k]) + int(self.heading[k]) // 45, int(self.pos[k, 0] - self.half[k])
        options = (int(self.agent_screen_left[k]), bool(self.show_background[k]), bool(self.show_stamina[k]))
        rows: dict[int, list[int]] = {start_y[0]: slots} if len(slots) == 1 else {}
        for k, row in zip(slots, start_y, strict=True) if len(slots) > 1 else ():
            rows.setdefault(row, []).append(k)
        for row, same in rows.items():
            key = (sprite, row * TILE + offset, *options)  # the sprite and its top row (x = radius = y offset)
            frame = self.first_frames.get(key)
            if frame is None:
                self._draw_slot(same[0])
                frame = self.first_frames[key] = self.canvas.view[same[0]].copy()
            self.canvas.view[same[0] if len(same) == 1 else same] = frame

    def _add_segment(self, k: int, draws: BoundedDraws) -> None:
        """Draw the next endless segment of slot ``k`` (a 7x7 level from column 0 to column 6) from ``draws`` (which
        the caller closes) and append its tiles and its transition tile to the chain lists; the caller writes them
        into the arrays (:meth:`_store_chains`)."""
        xs, ys = self.chain_lists[k]
        ends = self.segment_ends[k]
        segment = len(ends)
        start_y = draws.below(GRID) if segment == 0 else ys[-1]  # the last transition tile's row
        goal_y = draws.below(GRID)
        path, _ = draw_level(draws, SEGMENT_GRID, start_y, (GRID - 1) * GRID + goal_y)  # (0, start_y) -> (6, goal_y)
        shift = segment * SEGMENT_COLUMNS
        xs += [t // GRID + shift for t in path]
        xs.append(shift + GRID)  # the transition tile
        ys += [t % GRID for t in path]
        ys.append(goal_y)
        ends.append(len(xs))

    def _store_chains(self, slots: list[int], begins: list[int]) -> tuple[Any, Any]:
        """Write the chain tiles from ``begins[i]`` on of each slot of ``slots`` into the arrays: columns, rows,
        directions, flags (fresh) and the tile -> chain index map. Returns the written tiles' columns and chain
        indices, slot after slot.

        A tile's direction follows from the step to the next chain tile: path tiles are 4-neighbours, a goal's
        transition tile lies east of it and the next segment starts east of the transition tile; the last tile
        written (a transition tile) points east too.
        """
        if len(slots) == 1:  # the same with Python lists (a dozen tiles: cheaper than numpy calls)
            k, begin = slots[0], begins[0]
            xs, ys = self.chain_lists[k]
            end = len(xs)
            self._reserve(end, (len(self.segment_ends[k]) + 1) * SEGMENT_COLUMNS)
            x, y = xs[begin:], ys[begin:]
            self.chain_x[k, begin:end] = x
            self.chain_y[k, begin:end] = y
            steps = zip(x, x[1:], y, y[1:], strict=False)
            self.direction[k, begin:end] = [STEP_LIST[2 * (b - a) + d - c + 2] for a, b, c, d in steps] + [EAST]
            self.flags[k, begin:end] = NEW_TILE | REFILL
            self.tile_node[k].put([a * (GRID + 2) + b + 1 for a, b in zip(x, y, strict=True)], range(begin, end))
            return x, range(begin, end)
        lists = [self.chain_lists[k] for k in slots]
        ends = [len(xs) for xs, _ in lists]
        self._reserve(max(ends), (max(len(self.segment_ends[k]) for k in slots) + 1) * SEGMENT_COLUMNS)
        total = sum(ends) - sum(begins)
        x = np.fromiter(chain.from_iterable(xs[b:] for (xs, _), b in zip(lists, begins, strict=True)), int, total)
        y = np.fromiter(chain.from_iterable(ys[b:] for (_, ys), b in zip(lists, begins, strict=True)), int, total)
        counts = np.array(ends) - begins
        rows = np.repeat(slots, counts)
        last = np.cumsum(counts) - 1  # each slot's last tile in x and y
        nodes = np.arange(len(x)) + np.repeat(np.array(begins) - (last + 1 - counts), counts)  # chain indices
        step = np.zeros(len(x), dtype=np.int64)
        step[:-1] = 2 * (x[1:] - x[:-1]) + (y[1:] - y[:-1])
        step[last] = 0  # no step: east
        self.chain_x[rows, nodes] = x
        self.chain_y[rows, nodes] = y
        self.direction[rows, nodes] = DIRECTION_OF_STEP[step + 2]
        self.flags[rows, nodes] = NEW_TILE | REFILL
        self.tile_node[rows, x, y + 1] = nodes  # tile_node[k, x, y + 1] = chain index
        return x, nodes

    def _store_walks(self, k: int, begin: int, end: int) -> None:
        """Where the past path starts behind an agent on each chain tile begin..end - 1 of slot ``k``."""
        if self.show_past_path[k]:
            xs, depth = self.chain_lists[k][0], int(self.depth[k])
            self.walk_start[k, begin:end] = [walk_start(xs, i, xs[i] - 1, depth) for i in range(begin, end)]
        else:
            self.walk_start[k, begin:end] = range(begin, end)

    def _store_first_walks(
        self, slots: list[int], ends: list[int], x: np.ndarray, cols: np.ndarray, opts: dict[str, Any]
    ) -> None:
        """:meth:`_store_walks` of the first segment of many slots at once (``x`` and ``cols``: their chain tiles'
        columns and chain indices, slot after slot), with :func:`walk_starts`."""
        counts = np.array(ends)
        rows = np.repeat(np.arange(len(slots)), counts)
        if opts["show_past_path"]:
            columns = np.zeros((len(slots), int(counts.max())), dtype=np.int64)
            columns[rows, cols] = x
            starts = walk_starts(columns, int(opts["camera_offset_scale"]))[rows, cols]
        else:
            starts = cols
        self.walk_start[np.array(slots)[rows], cols] = starts

    def _enter_segment(self, k: int, segment: int) -> None:
        """Prepare segment ``segment`` for an agent entering it, and compute where the past path starts for each of
        its tiles (not random, so it is only done for segments that the agent reaches).

        The reference builds three segments at reset and one more whenever the agent enters the last one. Here only
        the first is built at reset; entering the second builds every segment that the reference has built by then,
        in the same order from the same generator, so levels and random streams are the same. An episode that never
        leaves the first segment (most short ones) then costs one level instead of three, unless the next reset
        continues the generator: then :meth:`_skip_segments` makes the missing draws first.
        """
        while segment > self.reference_segments[k] - 2:
            self.reference_segments[k] += 1
        if segment > 0:
            self._catch_up(k)
        begin, end = int(self.walks_until[k]), self.segment_ends[k][segment]
        if end > begin:
            self._store_walks(k, begin, end)
            self.walks_until[k] = end
        self.prepare_at[k] = (segment + 1) * SEGMENT_COLUMNS * TILE

    def _catch_up(self, k: int) -> None:
        """Build the segments that the reference has built by now but this slot has not yet (see _enter_segment)."""
        ends = self.segment_ends[k]
        if len(ends) < self.reference_segments[k]:
            begin = ends[-1]
            draws = BoundedDraws(self.segment_rng[k])
            draws.read_ahead(LEVEL_OUTPUTS * (int(self.reference_segments[k]) - len(ends)))
            while len(ends) < self.reference_segments[k]:
                self._add_segment(k, draws)
            draws.close()
            self._store_chains([k], [begin])
            self.num_segments[k] = len(ends)

    def _skip_segments(self, k: int, draws: BoundedDraws) -> None:
        """Make the draws of the segments that the reference has built by now but this slot has not, without
        building them: at a reset that continues the generator, the finished episode's segments are never seen."""
        ys = self.chain_lists[k][1]
        goal_y = ys[-1] if ys else 0
        for segment in range(len(self.segment_ends[k]), int(self.reference_segments[k])):
            start_y = draws.below(GRID) if segment == 0 else goal_y
            goal_y = draws.below(GRID)
            skip_level(draws, SEGMENT_GRID, start_y, (GRID - 1) * GRID + goal_y)

    def path_tiles(self, k: int) -> tuple[list[int], list[int]]:
        """Endless variant: (x list, y list) of every path tile generated so far in slot ``k``, origin first."""
        self._catch_up(k)
        return self.chain_lists[k]

    def _reserve(self, length: int, columns: int) -> None:
        """Grow the chain and tile arrays of all slots so that they hold ``length`` tiles and ``columns`` columns."""
        capacity = self.chain_x.shape[1]
        if length > capacity:
            extra = max(length, 2 * capacity) - capacity
            for name, fill in (("chain_x", 0), ("chain_y", 0), ("direction", WEST), ("flags", 0), ("walk_start", 0)):
                old = getattr(self, name)
                setattr(self, name, np.concatenate([old, np.full((old.shape[0], extra), fill, old.dtype)], axis=1))
        if columns > self.tile_node.shape[1]:
            extra = max(columns, 2 * self.tile_node.shape[1]) - self.tile_node.shape[1]
            pad = np.full((self.num_envs, extra, GRID + 2), -1, dtype=np.int64)
            self.tile_node = np.concatenate([self.tile_node, pad], axis=1)

    # -------------------------------------------------------------------------------------------- step
    def _slots_of(self, idx: Index) -> np.ndarray:
        return self.all_slots if isinstance(idx, slice) else idx

    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        slots = self._slots_of(idx)
        if len(slots) <= SCALAR_SLOTS:
            # A numpy call costs microseconds whatever its size, so a few slots are stepped one by one with the
            # same rules on the same state (tests check that both ways agree step for step).
            actions = actions.reshape(len(slots), -1).tolist()
            rewards = np.empty(len(slots), dtype=np.float64)
            terminated = np.empty(len(slots), dtype=bool)
            step_slot = self._step_endless_slot if self.endless else self._step_level_slot
            for i, k in enumerate(slots.tolist()):
                rewards[i], terminated[i] = step_slot(k, actions[i])
                self._draw_slot(k)
            return rewards, terminated
        if self.endless:
            rewards, terminated = self._step_endless(idx, slots, actions.reshape(-1))
        else:
            rewards, terminated = self._step_level(idx, slots, actions)
        self._draw(idx)
        return rewards, terminated

    def _step_level_slot(self, k: int, action: list[int]) -> tuple[float, bool]:
        """One Mystery Path step of slot ``k`` (the rules of :meth:`_step_level`, one slot at a time)."""
        back = self.off_path[k]
        if self.grid:
            state = int(self.grid_state[k])
            state = int(self.origin_state[k]) | (state & 3) if back else int(GRID_NEXT[state, action[0]])
            self.grid_state[k] = state
            self.heading[k] = (state & 3) * 90
            tile = state >> 2
            self.pos[k] = TILE_CENTRES[tile]
        else:
            code = 0 if back else action[0] * 3 + action[1]
            x, y = (self.return_pos if back else self.pos)[k].tolist()
            vx, vy = self.velocity[k, code].tolist()
            low, high = int(self.pos_low[k, 0]), int(self.pos_high[k, 0])
            x, y = max(min(x + vx, high), low), max(min(y + vy, high), low)
            self.pos[k] = x, y
            turn = FREE_HEADINGS[code]
            if turn >= 0:
                self.heading[k] = turn
            tile = (x // TILE) * GRID + y // TILE
        status = int(self.status[k, tile])
        self.status[k, tile] = AFTER_VISIT[status]
        fell, goal = status == OFF, status == GOAL
        self.num_fails[k] += fell
        self.off_path[k] = fell
        self.cross_visible[k] = fell and self.visual_feedback[k]
        self.success[k] = goal
        self.t[k] += 1
        return self.reward_table[k, status], goal or self.t[k] == self.max_steps[k]

    def _step_endless_slot(self, k: int, action: list[int]) -> tuple[float, bool]:
        """One Endless Mystery Path step of slot ``k`` (the rules of :meth:`_step_endless`, one slot at a time)."""
        if self.off_path[k]:
            x, y = self.return_pos[k].tolist()
            self.camera_x[k] = self.camera_offset[k]
            self.bg_scroll[k] = 0.0
        else:
            vx, vy = self.velocity[k, action[0]].tolist()
            x, y = self.pos[k].tolist()
            x, y = x + vx, y + vy
            turn = ENDLESS_HEADINGS[action[0]]
            if turn >= 0:
                self.heading[k] = turn
            self.camera_x[k] += vx
            scroll = self.bg_scroll[k] - vx
            if abs(scroll) >= TILE:
                scroll = abs(scroll) % abs(vx) * np.sign(scroll)
            self.bg_scroll[k] = scroll
        self.pos[k] = x, y
        tx, ty = x // TILE, y // TILE
        if x >= self.prepare_at[k]:
            self._enter_segment(k, tx // SEGMENT_COLUMNS)
        node = int(self.tile_node[k, tx, min(max(ty, -1), GRID) + 1])
        on_path = node >= 0
        if on_path:
            self.current_node[k] = node
        else:
            node = int(self.current_node[k])
        flags = int(self.flags[k, node])
        if on_path:
            self.flags[k, node] = 0  # a visited tile pays and refills only once
        new_tile = flags & NEW_TILE
        reward = self.reward_table[k, new_tile + 2 * (not on_path)]
        self.tiles_visited[k] += new_tile
        stamina = (self.stamina_level[k] if flags >= REFILL or not on_path else self.stamina[k]) - 1
        self.stamina[k] = stamina
        self.t[k] += 1
        terminated = stamina == 0 or self.t[k] == self.max_steps[k]
        self.draw_from[k] = self.walk_start[k, node]
        if not on_path:
            terminated = self._fall_off(k, tx, ty, node) or terminated
        self.off_path[k] = not on_path
        self.cross_visible[k] = not on_path and self.visual_feedback[k]
        direction = self.direction[k, node]
        if direction != WEST:
            self.ground_truth[k] = direction
        if on_path and tx > self.max_x[k]:
            self.max_x[k] = tx
        return reward, bool(terminated)

    def _fall_off(self, k: int, column: int, row: int, node: int) -> bool:
        """Endless fall-off bookkeeping of slot ``k`` at tile (column, row); True if it ends the episode.

        Falling off behind the best column, or twice at the same tile, ends the episode. (The tiles are meant to be
        forgotten on reaching a new best column, but the reference never does.) Every tile refills stamina again.
        """
        self.num_fails[k] += 1
        tile, seen = (column, row), self.fall_off_tiles[k]
        ends = column < self.max_x[k] or tile in seen
        if not ends:
            seen.add(tile)
        self.flags[k, : len(self.chain_lists[k][0])] |= REFILL
        if self.show_past_path[k]:
            self.draw_from[k] = walk_start(self.chain_lists[k][0], node, column - 1, int(self.depth[k]))
        else:
            self.draw_from[k] = node
        return ends

    def _step_level(self, idx: Index, slots: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        back = self.off_path[idx]  # fell off last step: back to the origin, the action is ignored
        if self.grid:
            state = self.grid_state[idx]
            moved = GRID_NEXT[state, actions.reshape(-1)]
            state = np.where(back, self.origin_state[idx] | (state & 3), moved)
            self.grid_state[idx] = state
            self.heading[idx] = (state & 3) * 90
            tile = state >> 2
            self.pos[idx] = TILE_CENTRES[tile]
        else:
            actions = actions.reshape(-1, 2)
            code = np.where(back, 0, actions[:, 0] * 3 + actions[:, 1])
            pos = np.where(back[:, None], self.return_pos[idx], self.pos[idx])
            pos += self.velocity[slots, code]
            np.minimum(pos, self.pos_high[idx], out=pos)  # the upper bound first, as in the reference
            np.maximum(pos, self.pos_low[idx], out=pos)
            self.pos[idx] = pos
            turn = FREE_HEADINGS[code]
            self.heading[idx] = np.where(turn < 0, self.heading[idx], turn)
            tile = TILE_OF_PIXEL[pos[:, 0], pos[:, 1]]
        status = self.status[slots, tile]
        self.status[slots, tile] = AFTER_VISIT[status]
        rewards = self.reward_table[slots, status]
        fell = status == OFF
        goal = status == GOAL
        self.num_fails[idx] += fell
        self.off_path[idx] = fell
        self.cross_visible[idx] = fell & self.visual_feedback[idx]
        self.success[idx] = goal
        self.t[idx] += 1
        return rewards, goal | (self.t[idx] == self.max_steps[idx])

    def _step_endless(self, idx: Index, slots: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        back = self.off_path[idx]  # fell off last step: back to the first tile, camera reset, action ignored
        # The camera follows the agent horizontally; the background scrolls the other way and wraps.
        if back.any():
            code = np.where(back, 0, actions)
            velocity = self.velocity[slots, code]
            pos = np.where(back[:, None], self.return_pos[idx], self.pos[idx])
            pos += velocity
            vx = velocity[:, 0]
            self.camera_x[idx] = np.where(back, self.camera_offset[idx], self.camera_x[idx] + vx)
            scroll = np.where(back, 0.0, self.bg_scroll[idx] - vx)
        else:  # the same without the selections (most steps: no slot fell off in the last one)
            code = actions
            velocity = self.velocity[slots, code]
            pos = self.pos[idx] + velocity
            vx = velocity[:, 0]
            self.camera_x[idx] += vx
            scroll = self.bg_scroll[idx] - vx
        self.pos[idx] = pos
        turn = ENDLESS_HEADINGS[code]
        self.heading[idx] = np.where(turn < 0, self.heading[idx], turn)
        wrap = np.abs(scroll) >= TILE
        if wrap.any():
            scroll = np.where(wrap, np.abs(scroll) % np.where(vx != 0, np.abs(vx), 1) * np.sign(scroll), scroll)
        self.bg_scroll[idx] = scroll

        px = pos[:, 0]
        tx = px // TILE
        ahead = px >= self.prepare_at[idx]
        if ahead.any():
            for k, column in zip(slots[ahead].tolist(), tx[ahead].tolist(), strict=True):
                self._enter_segment(k, column // SEGMENT_COLUMNS)
        ty = pos[:, 1] // TILE
        node = self.tile_node[slots, tx, np.minimum(np.maximum(ty, -1), GRID) + 1]
        on_path = node >= 0
        fell = ~on_path
        node = np.where(on_path, node, self.current_node[idx])
        self.current_node[idx] = node
        flags = self.flags[slots, node]
        self.flags[slots, node] = np.where(on_path, 0, flags)  # a visited tile pays and refills only once
        new_tile = flags & NEW_TILE
        rewards = self.reward_table[slots, new_tile + 2 * fell]
        self.tiles_visited[idx] += new_tile
        stamina = np.where((flags >= REFILL) | fell, self.stamina_level[idx], self.stamina[idx]) - 1
        self.stamina[idx] = stamina
        self.t[idx] += 1
        terminated = (stamina == 0) | (self.t[idx] == self.max_steps[idx])
        self.draw_from[idx] = self.walk_start[slots, node]
        for i in np.flatnonzero(fell).tolist():
            terminated[i] |= self._fall_off(int(slots[i]), int(tx[i]), int(ty[i]), int(node[i]))
        self.off_path[idx] = fell
        self.cross_visible[idx] = fell & self.visual_feedback[idx]
        direction = self.direction[slots, node]
        self.ground_truth[idx] = np.where(direction == WEST, self.ground_truth[idx], direction)
        self.max_x[idx] = np.maximum(self.max_x[idx], tx * on_path)
        return rewards, terminated

    # ------------------------------------------------------------------------------------------- drawing
    def _draw_slot(self, k: int) -> None:
        """Draw the agent view of slot ``k`` (the picture of :meth:`_draw`, one slot at a time)."""
        frame = self.canvas.view[k]
        if self.endless:
            self._draw_floor_slot(k, frame)
            left = int(self.agent_screen_left[k])
        else:
            frame[:] = self.background[k]
            left = int(self.pos[k, 0] - self.half[k])
        self._paste_agent_slot(k, frame, left)
        if self.endless and self.show_stamina[k]:
            frame[:, SCREEN - STAMINA_BAR_WIDTH :] = STAMINA_BARS[self._stamina_bar_heights(k)]
        if self.cross_visible[k]:
            self._paste_cross_slot(k, frame)

    def _paste_agent_slot(self, k: int, frame: np.ndarray, left: int) -> None:
        """Paste slot ``k``'s agent into ``frame`` with its sprite's left edge at column ``left``."""
        half = int(self.half[k])
        sprite = self.agents.sprites[int(self.sprite0[k]) + int(self.heading[k]) // 45]
        sprite.paste(frame, int(self.pos[k, 1]) - half, left)

    def _paste_cross_slot(self, k: int, frame: np.ndarray) -> None:
        """Paste the fall-off cross of slot ``k`` into ``frame``, centred on :meth:`_cross_centres`."""
        cross = self.crosses.sprites[self.cross_id]
        centre_x, centre_y = self._cross_centres(k)
        cross.paste(frame, int(centre_y) - cross.height // 2, int(centre_x) - cross.width // 2)

    def _draw_floor_slot(self, k: int, frame: np.ndarray) -> None:
        """The endless floor of slot ``k``: black or ice, then the path tiles behind the agent."""
        if self.show_background[k]:
            frame[:] = ice_background(int(-self.bg_scroll[k]) % TILE)
        else:
            frame[:] = 0
        first, stop = int(self.draw_from[k]), int(self.current_node[k])
        if stop > first:
            camera = float(self.camera_x[k])
            xs, ys = self.chain_lists[k]
            for tx, ty in zip(xs[first:stop], ys[first:stop], strict=True):
                left = int(tx * TILE - camera)  # pygame cuts float rects toward zero
                c0, c1 = max(left, 0), min(left + TILE, SCREEN)
                if c0 < c1:
                    frame[ty * TILE : (ty + 1) * TILE, c0:c1] = PATH_TILE[:, c0 - left : c1 - left]

    def _draw(self, idx: Index) -> None:
        slots = self._slots_of(idx)
        pos = self.pos[idx]
        top = pos[:, 1] - self.half[idx]
        if self.endless:
            self._draw_floor(idx, slots)
            left = self.agent_screen_left[idx]
        else:
            self.canvas.view[idx] = self.background[idx]
            left = pos[:, 0] - self.half[idx]
        if self.agent_sheet is not None:
            sheet, first = self.agent_sheet
            self.canvas.paste_sheet(sheet, self.agents, first, slots, self.heading[idx] // 45, top, left, self.endless)
        else:
            sprite = self.sprite0[idx] + self.heading[idx] // 45
            self.canvas.paste(self.agents, slots, sprite, top, left, may_leave_screen=self.endless)
        if self.endless:
            bar = self.show_stamina[idx]
            if bar.any():
                with_bar = slots[bar]
                heights = self._stamina_bar_heights(with_bar)
                self.canvas.view[with_bar, :, SCREEN - STAMINA_BAR_WIDTH :] = STAMINA_BARS[heights]
        cross = self.cross_visible[idx]
        if cross.any():
            with_cross = slots[cross]
            centre_x, centre_y = self._cross_centres(with_cross)
            half = self.crosses.widths[self.cross_id] // 2
            ids = np.full(len(with_cross), self.cross_id)
            self.canvas.paste(self.crosses, with_cross, ids, centre_y - half, centre_x - half, self.endless)

    def _cross_centres(self, slots: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """Screen centre of the fall-off cross: the agent's centre (rounded after the endless camera shift)."""
        x, y = self.pos[slots, 0], self.pos[slots, 1]
        if self.endless:
            return round_half_away(x - self.camera_x[slots]), y
        return x, y

    def _stamina_bar_heights(self, slots: np.ndarray | int) -> np.ndarray:
        level = self.stamina_level[slots]
        return (SCREEN * (1 - np.minimum(self.stamina[slots], level) / level)).astype(np.int64)

    def _draw_floor(self, idx: Index, slots: np.ndarray) -> None:
        """The endless floor (black or scrolling ice) and the path tiles behind the agent, band by band.

        Black frames are cleared in one fill; then only the bands that hold something are written: every band of
        an ice floor, and the bands of a black floor that hold past-path tiles."""
        ice = self.show_background[idx]
        if isinstance(idx, slice) and not ice.any():
            self.canvas.view.fill(0)
        elif not ice.all():
            self.canvas.view[slots[~ice]] = 0
        drawn = np.repeat(ice, GRID)  # (row of slots, band) -> band is written
        first = self.draw_from[idx]
        count = self.current_node[idx] - first
        most = int(count.max())
        if most > 0:
            rows, cols = np.nonzero(np.arange(most) < count[:, None])
            owner = slots[rows]
            chain = first[rows] + cols
            tile_band = rows * GRID + self.chain_y[owner, chain]
            drawn[tile_band] = True
        band_of = np.flatnonzero(drawn)
        if len(band_of) == 0:
            return
        phase = np.where(ice, (-self.bg_scroll[idx]).astype(np.int64) % TILE, BLACK_FLOOR)
        band_slots = band_of // GRID
        edge = np.empty((len(band_of), BAND_WIDTH, 3), dtype=np.uint8)
        middle = np.empty((len(band_of), BAND_WIDTH, 3), dtype=np.uint8)
        edge[:, BAND_PAD : BAND_PAD + SCREEN] = BACKGROUND_EDGE[phase[band_slots]]
        middle[:, BAND_PAD : BAND_PAD + SCREEN] = BACKGROUND_MIDDLE[phase[band_slots]]
        if most > 0:
            # Each tile's screen column is truncated on its own (pygame cuts float rects toward zero).
            left = np.trunc(self.chain_x[owner, chain] * TILE - self.camera_x[owner]).astype(np.int64)
            left = np.minimum(np.maximum(left, -BAND_PAD), SCREEN) + BAND_PAD
            position = np.cumsum(drawn) - 1  # (row of slots, band) -> its row in edge / middle
            at = ((position[tile_band] * BAND_WIDTH + left) * 3)[:, None] + TILE_BYTE_OFFSETS
            edge.reshape(-1)[at] = TILE_EDGE_BYTES
            middle.reshape(-1)[at] = TILE_MIDDLE_BYTES
        frame_slots, bands = slots[band_slots], band_of % GRID
        visible = slice(BAND_PAD, BAND_PAD + SCREEN)
        target = self.canvas.bands
        target[frame_slots, bands, 0] = edge[:, visible]
        target[frame_slots, bands, TILE - 1] = edge[:, visible]
        target[frame_slots, bands, 1 : TILE - 1] = middle[:, None, visible]

    # ------------------------------------------------------------------------------------------ outputs
    def _max_episode_steps(self, opts: dict[str, Any]) -> int:
        return int(opts["max_steps"])  # memory-gym reports the option as it is (<= 0: no cap)

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

    def _step_infos(self) -> dict[str, np.ndarray]:
        if self.endless:
            return {"ground_truth": DIRECTIONS[self.ground_truth]}
        return {}

    def _debug_frame(self, k: int) -> np.ndarray:
        """Ground truth: the whole level (path white, origin blue, goal green, walls red) or, in the endless
        variant, every generated path tile at alpha 200 and the stamina bar; plus the agent and the cross."""
        frame = np.zeros((SCREEN, SCREEN, 3), dtype=np.uint8)
        if self.endless:
            if self.show_background[k]:
                frame[:] = ice_background(int(-self.bg_scroll[k]) % TILE)
            shift = int(-self.camera_x[k])  # the whole path picture is placed once, so it is truncated once
            xs, ys = self.path_tiles(k)
            for tx, ty in zip(xs, ys, strict=True):
                left = tx * TILE + shift
                if -TILE < left < SCREEN:
                    area = frame[ty * TILE : (ty + 1) * TILE, max(left, 0) : left + TILE]
                    area[:] = blend(area, np.array(PATH_COLOUR), DEBUG_PATH_ALPHA)
            left = int(self.agent_screen_left[k])
        else:
            origin, goal, layout = self.levels[k]
            for tile in layout.path[1:-1]:
                fill_tile(frame, tile, PATH_COLOUR)
            fill_tile(frame, origin, ORIGIN_COLOUR)
            fill_tile(frame, goal, GOAL_COLOUR)
            for tile in layout.walls:
                fill_tile(frame, tile, WALL_COLOUR)
            left = int(self.pos[k, 0] - self.half[k])
        self._paste_agent_slot(k, frame, left)
        if self.cross_visible[k]:
            self._paste_cross_slot(k, frame)
        if self.endless:
            frame[:, SCREEN - STAMINA_BAR_WIDTH :] = STAMINA_BARS[self._stamina_bar_heights(k)]
        return frame
