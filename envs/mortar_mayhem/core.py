"""The Mortar Mayhem core: state of arrays, reset, step and drawing of every slot (see the package docstring)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from envs.core import BatchedCore, Index
from envs.drawing import SCREEN, SpriteSheet
from envs.mortar_mayhem.commands import (
    COMMAND_DELTAS,
    COMMAND_STEP,
    MAX_VECTOR_COMMANDS,
    ONE_HOT,
    command_walk,
    walk_commands,
)
from envs.mortar_mayhem.moves import CODE_WEIGHTS, HEADING_SPRITE, FreeMoves, grid_moves
from envs.mortar_mayhem.options import option_specs, variant_name
from envs.mortar_mayhem.pictures import (
    AGENT_SCALE,
    ENDLESS_ARENA,
    ICON_CORNER,
    TILE,
    agent_sheet,
    arena_left,
    backgrounds,
    icon_sheet,
    spawn_frames,
    target_ring,
)
from envs.mortar_mayhem.records import AGENT_COLUMNS, SLOT_LAYOUT, SLOT_WIDTH
from envs.records import bind_fields
from envs.rng import BoundedDraws

CLUE_FPS = 3  # the human window slows down while commands are shown


class MortarMayhemCore(BatchedCore):
    """All Mortar Mayhem variants, batched over ``num_envs`` slots.

    The act phase of the reference counts up two counters (to D while the tiles are safe, to E while they are
    lethal); here one countdown per slot, ``timer``, holds the steps left until the next event: a check (safe
    phase) or the release (lethal phase). A step with ``timer == 0`` is that event, every other act step counts
    down, and every step of the lethal phase that is not the release checks the agent's tile.
    """

    # checks_passed: the checks the agent actually passed (``commands_completed`` keeps the reference's quirks);
    # command_count: the commands of the episode (finite variants)
    added_info_keys = frozenset({"checks_passed", "command_count"})

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
        bind_fields(self, self.slot_state, SLOT_LAYOUT)  # attribute views of the fields' columns
        self.shown[:] = -1  # nothing drawn yet
        self.commands = np.zeros((n, 16), np.int64)
        self.slot_rewards = np.zeros((n, 3))  # one row per slot, so that a reset writes it in one assignment
        self.reward_failure, self.reward_success, self.reward_episode = self.slot_rewards.T
        self.visual_feedback = np.ones(n, bool)
        self.tiles_on = np.zeros(n, bool)
        # clue stream: the icon (command, or -1 for a blank frame) of every frame; `clue_pos` is the frame on screen
        self.stream = np.full((n, 64), -1, np.int64)
        # The reference caches the sprite (and rect) it drew last, and after a reset still shows it in the debug
        # view and, in the endless variant, during the first clue stream. With ``reference_carryover`` (the parity
        # replays only) this is kept: ``stale``: the slot shows that sprite (``drawn``: x, y, sprite, sheet; valid
        # once anything was drawn) instead of its agent. It is set at reset and cleared by the first step that draws
        # the agent. By default no slot is ever stale: a reset shows the new episode's agent, as on a fresh instance.
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
        if self.reference_carryover:  # the reference's leftover sprite (see ``_first_step``); off by default
            stale = self.stale[ks]  # else the sprite drawn last is this slot's agent: keep it
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
    def _max_episode_steps(self, opts: dict[str, Any]) -> int:
        # memory-gym's bound, from the largest value of every list option: clue stream C = n (shown + delay), then
        # n checks D + E apart, + 1 (one step above the longest episode of the clue variants, kept: clients size their
        # memory from it). The B variants have no clue stream; the endless one reports ``max_steps`` (-1: none).
        if self.endless:
            return int(opts["max_steps"])
        n, act, lethal = max(opts["command_count"]), max(opts["explosion_delay"]), max(opts["explosion_duration"])
        clue = n * (max(opts["command_show_duration"]) + max(opts["command_show_delay"])) if self.clue_phase else 0
        return clue + n * (act + lethal) - lethal + 1

    def _observation(self, idx: Index) -> np.ndarray | dict[str, np.ndarray]:
        if self.vector_observation:
            return {"visual_observation": self.frames[idx], "vector_observation": self.vector[idx]}
        return self.frames[idx]

    def _final_infos(self, slots: list[int]) -> list[dict[str, Any]]:
        counts = self.num_commands[slots].tolist()
        passed = self.completed_total[slots].tolist()  # checks passed (the reference's keys keep its quirks)
        if self.endless:
            return [
                {
                    "commands_completed": completed,
                    "max_command_sequence": count - 1 if count > 1 else 0,
                    "checks_passed": completed,
                }
                for completed, count in zip(passed, counts, strict=True)
            ]
        return [
            {
                "success": success,
                "commands_completed": (current - 1 + success) / count,
                "checks_passed": checks,
                "command_count": count,
            }
            for success, current, count, checks in zip(
                self.success[slots].tolist(), self.current[slots].tolist(), counts, passed, strict=True
            )
        ]

    def _step_info(self, k: int) -> dict[str, Any]:
        if self.endless:
            return {"ground_truth": self.target[k] / 5.0}
        return {}

    def _step_infos(self) -> dict[str, np.ndarray]:
        if self.endless:
            return {"ground_truth": self.target / 5.0}
        return {}

    def render_fps(self, k: int) -> int:
        return CLUE_FPS if self.clue_left[k] > 0 else self.base_render_fps


def _grown(array: np.ndarray, needed: int, fill: int) -> np.ndarray:
    grown = np.full((array.shape[0], max(needed, 2 * array.shape[1])), fill, dtype=array.dtype)
    grown[:, : array.shape[1]] = array
    return grown
