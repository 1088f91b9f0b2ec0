"""The Searing Spotlights core: state of arrays, step, reset and drawing of every slot (see the package docstring)."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from envs.core import BatchedCore, Index
from envs.drawing import SpriteScatter, agent_sprites, disc_mask
from envs.movement import continuous_heading, continuous_velocity
from envs.records import as_bytes, bind_fields
from envs.rng import DirectDraws
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
from envs.searing_spotlights.holes import hole_tables
from envs.searing_spotlights.options import ESS_OPTIONS, SS_OPTIONS
from envs.searing_spotlights.pictures import (
    CENTRE,
    FLOOR_BLACK,
    FLOOR_CHESS,
    FLOOR_WHITE,
    HUD_ROWS,
    ROW,
    ROW_BYTES,
    SCREEN,
    coin_sprite,
    exit_sprite,
    floor_pair,
    floor_rows,
    ring_mask,
)
from envs.searing_spotlights.records import EPISODE, EXIT_BIT, NEVER, OPEN_EXIT_BIT, SETTINGS, SPOTS, mark_touch
from envs.searing_spotlights.sampler import (
    AGENT_BLOCK,
    ITEM_BLOCK,
    block_position,
    clamp_item,
    orbit_points,
    sample_position,
)

# Heading index (heading // 45; -1: unchanged) per action code ``3 * horizontal + vertical``.
ACTION_PAIRS = np.array([(h, v) for h in range(3) for v in range(3)])
_HEADINGS = continuous_heading(ACTION_PAIRS, np.full(9, -1))
ACTION_HEADING = np.where(_HEADINGS < 0, -1, _HEADINGS // 45)
ACTION_WEIGHTS = np.array([3, 1])
NEXT_HEADING = np.where(ACTION_HEADING[None, :] < 0, np.arange(8)[:, None], ACTION_HEADING[None, :])  # [heading, code]
UNDER_KEY_POSITION = np.array([1 << 1, 1 << 8])  # (x, y) -> their bits in the under key


class SearingSpotlightsCore(BatchedCore):
    """Both Searing Spotlights variants; ``endless=True`` gives ``Endless-SearingSpotlights-v0``."""

    FEW_UNDER_UPDATES = 4  # up to this many changed pictures under the darkness are updated one by one

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
        self._defaults: dict[str, Any] | None = None
        self._defaults = self.resolve(None)  # (cross-checks the constructor options) shared by default resets
        n = self.num_envs
        self.all_slots = np.arange(n)
        self.settings = np.zeros(n, SETTINGS)
        self.settings_bytes = as_bytes(self.settings)
        bind_fields(self, self.settings)  # attribute views of the settings columns
        self.orders: list[dict[bool, tuple[tuple[str, ...], tuple[str, ...]]]] = [{} for _ in range(n)]
        self.agent_sprites = SpriteScatter()  # every agent scale met so far (settings hold the first id)
        self.coin_sprites = SpriteScatter()  # every coin scale met so far
        self._settings_cache: dict[tuple, tuple] = {}
        # episode state
        i64 = np.int64
        self.episode = np.zeros(n, EPISODE)
        self.episode_bytes = as_bytes(self.episode)
        bind_fields(self, self.episode)  # attribute views of the state columns
        self.x, self.y = self.pos[:, 0], self.pos[:, 1]
        self.hud = np.zeros((n, ROW_BYTES), np.uint8)  # the HUD row of the current frame
        self.coin_x = np.zeros((n, 1), i64)
        self.coin_y = np.zeros((n, 1), i64)
        self.coin_alive = np.zeros((n, 1), bool)
        self.item_map = np.zeros((n, SCREEN, SCREEN), np.uint16)  # see EXIT_BIT
        # spotlights (the list capacity grows on demand)
        self.tables = hole_tables(int(self.base_options["spot_max_radius"]))
        self.unused_spot = self._unused_spot_record()
        self.spots = np.zeros((n, 0), SPOTS)
        self.drawn_is_listed = False  # the "drawn" column equals "listed" for every slot
        self._grow_spots(8)
        # pictures, as (84, 252) rows per slot
        self.frame_buffer = np.zeros((n + 1, SCREEN, ROW_BYTES), np.uint8)  # the last frame is scratch
        self.frames = self.frame_buffer[:n]
        self.frames_lent = False  # the frame buffer was handed to a caller (see ``observations``)
        self.stale = np.zeros(n, bool)  # frames to draw again (from the state) before they are read
        self.lit = np.zeros((2, n, SCREEN, ROW_BYTES), np.uint8)  # floor + coins + exit; blue and red floor
        self.under_buffer = np.zeros((n + 1, SCREEN, ROW_BYTES), np.uint8)  # the last frame is scratch
        self.under = self.under_buffer[:n]  # what lies under the darkness: lit (blue or red) + hidden agent
        self.under_key = np.full(n, -1, i64)  # what ``under`` shows (see ``_update_under``); -1: to rebuild
        self.span_index = np.zeros(n * SCREEN, np.int16)  # per frame row: the code of its span (see HoleTables)
        self.span_claim = np.zeros(n * SCREEN, np.intp)  # scratch for ``_or_lost_spans``
        self.positions = np.arange(0)  # 0, 1, 2, ... for ``_or_lost_spans`` (grown on demand)

    # ------------------------------------------------------------------------------------------- options
    def resolve(self, options: dict[str, Any] | None) -> dict[str, Any]:
        if not options and self._defaults is not None:  # (never modified: slots share it read-only)
            return self._defaults
        opts = super().resolve(options)
        for low, high in (("spot_min_radius", "spot_max_radius"), ("spot_min_speed", "spot_max_speed")):
            if opts[low] > opts[high]:
                raise ValueError(f"option {low!r}={opts[low]!r} is invalid: expected a value <= {high}={opts[high]!r}")
        return opts

    def _episode_settings(self, opts: dict[str, Any]) -> tuple[np.void, dict, np.void, np.ndarray, np.ndarray]:
        """The settings record, draw orders and episode start record for ``opts``, and both records as bytes
        (cached: most episodes share their options)."""
        if opts is self._defaults:
            key = None
        else:
            key = tuple(tuple(v) if isinstance(v, list) else v for v in opts.values())
        cached = self._settings_cache.get(key)
        if cached is None:
            if len(self._settings_cache) > 256:
                self._settings_cache.clear()
            record, orders, start = self._derive_settings(opts)
            cached = record, orders, start, as_bytes(record), as_bytes(start)
            self._settings_cache[key] = cached
        return cached

    def _derive_settings(self, opts: dict[str, Any]) -> tuple[np.void, dict, np.void]:
        endless = self.endless
        record = np.zeros((), SETTINGS)
        radius = int(25 * opts["agent_scale"])
        record["end_t"] = opts["max_steps"] if opts["max_steps"] > 0 else NEVER
        record["agent_radius"] = radius
        record["pos_low"] = radius, HUD_ROWS + radius
        record["pos_high"] = SCREEN - radius, SCREEN - radius
        vx, vy = continuous_velocity(ACTION_PAIRS, np.full(9, float(opts["agent_speed"])))
        record["vel"] = np.stack([vx, vy], axis=1)
        record["agent_sprite0"] = self.agent_sprites.add(agent_sprites(float(opts["agent_scale"])))
        record["max_health"] = opts["agent_health"]
        record["spot_damage"] = opts["spot_damage"]
        record["reward_inside"] = opts["reward_inside_spotlight"]
        record["reward_outside"] = opts["reward_outside_spotlight"]
        record["reward_death"] = opts["reward_death"]
        record["reward_coin"] = opts["reward_coin"]
        if opts["black_background"]:
            record["floor_kind"] = FLOOR_BLACK
        elif opts["hide_chessboard"]:
            record["floor_kind"] = FLOOR_WHITE
        else:
            record["floor_kind"] = FLOOR_CHESS
        record["red_feedback"] = opts["visual_feedback"] and record["floor_kind"] == FLOOR_CHESS
        record["rings"] = opts["black_background"]
        alphas = alpha_schedule(opts["light_dim_off_duration"], opts["light_threshold"])
        record["alphas"] = alphas
        dark = np.flatnonzero(alphas == 255)
        record["blend_until"] = NEVER if opts["black_background"] or not dark.size else dark[0]
        record["agent_hidden"] = not opts["agent_visible"]
        record["heading_key"] = int(record["agent_hidden"]) << 15
        record["agent_key"] = (int(record["agent_sprite0"]) + 1) * int(record["heading_key"])
        record["coins_visible"] = opts["coins_visible"]
        record["coin_scale"] = opts["coin_scale"]
        record["coin_sprite"] = self.coin_sprites.add((coin_sprite(float(opts["coin_scale"])),))
        record["coin_reach"] = int(10 * opts["coin_scale"]) + radius
        record["any_visible"] = opts["agent_visible"] or opts["coins_visible"] or opts.get("exit_visible", False)
        record["hud_flags27"] = 27 * (4 * endless + 2 * opts["show_last_action"] + opts["show_last_positive_reward"])
        record["hud_next"] = record["hud_flags27"] + 1
        agent = ("agent", 3, opts["agent_visible"])
        if endless:
            record["spawn_interval"] = opts["spawn_interval"]
            record["steps_per_coin"] = opts["steps_per_coin"] if opts["steps_per_coin"] > 0 else NEVER
            record["coin_show_duration"] = opts["coin_show_duration"]
            orders = {visible: draw_order([("coins", 1, visible), agent]) for visible in (False, True)}
        else:
            # The reference reads the first entry of its interval list and pops the last: a constant interval
            # (an interval below 1 spawns in every step, like 1).
            record["spawn_interval"] = max(int(opts["initial_spawn_interval"] + opts["spawn_interval_threshold"]), 1)
            record["use_exit"] = opts["use_exit"]
            record["exit_scale"] = opts["exit_scale"]
            record["exit_reach"] = 20 / 2 * opts["exit_scale"] + radius
            record["reward_exit"] = opts["reward_exit"]
            entities = [("coins", 1, opts["coins_visible"]), ("exit", 2, opts["exit_visible"]), agent]
            if not opts["use_exit"]:
                entities.pop(1)  # no exit at all (the reference would draw a stale one, or fail)
            order = draw_order(entities)
            orders = {False: order, True: order}
        start = np.zeros((), EPISODE)  # what the level draws (heading, positions, coins, exit) is written later
        start["end_t_now"] = min(record["end_t"], record["steps_per_coin"]) if endless else record["end_t"]
        start["health"] = opts["agent_health"]
        start["next_spawn"] = record["spawn_interval"] if endless or opts["num_spawns"] > 0 else NEVER
        start["spawns_left"] = 0 if endless else opts["num_spawns"]
        start["spot_count"] = opts["initial_spawns"]
        start["num_coins"] = start["coins_left"] = 1 if endless else 0
        start["coin_shown_until"] = record["coin_show_duration"]
        shown = record["coin_show_duration"] if endless else 0
        start["special_until"] = NEVER if record["any_visible"] else shown
        start["next_hud"] = record["hud_flags27"] + 1  # grey no-op action; the reference's last reward is 0.0
        return record[()], orders, start[()]

    # ------------------------------------------------------------------------------------------- spotlights
    def _unused_spot_record(self) -> np.void:
        record = np.zeros((), SPOTS)
        record["base"] = self.tables.base(0)
        record["reach"] = -1.0
        record["start"] = record["target"] = record["offset"] = record["centre"] = complex(CENTRE, CENTRE)
        return record[()]

    def _grow_spots(self, capacity: int) -> None:
        grown = np.full((self.num_envs, capacity), self.unused_spot, SPOTS)
        grown[:, : self.spots.shape[1]] = self.spots
        self.spots = grown
        self.spot_bytes = as_bytes(grown)  # (byte views made once: whole-record copies in resets and removals)
        self.unused_row = np.full(capacity, self.unused_spot, SPOTS)  # a list of unused positions, to copy from
        self.unused_row_bytes = as_bytes(self.unused_row)

    def _use_tables(self, max_radius: int) -> None:
        """Switch to hole tables that cover ``max_radius`` (the spotlights' table offsets are recomputed)."""
        if max_radius > self.tables.max_radius:
            self.tables = hole_tables(max_radius)
            self.unused_spot = self._unused_spot_record()
            self.unused_row = np.full(self.spots.shape[1], self.unused_spot, SPOTS)
            self.unused_row_bytes = as_bytes(self.unused_row)
            self.spots["base"] = self.tables.base(self.spots["radius"])

    def _new_spot(self, k: int, draws: DirectDraws, opts: dict[str, Any]) -> tuple:
        """A spotlight record: radius, speed, then the three angles (the reference's 5 draws, in its order)."""
        radius = draws.integers(opts["spot_min_radius"], opts["spot_max_radius"] + 1)
        speed = draws.uniform(opts["spot_min_speed"], opts["spot_max_speed"])
        start = draws.integers(0, 360)
        target = start + 180 + draws.integers(-45, 45)
        offset = target + draws.integers(-135, 135)
        points = orbit_points(radius)
        start, target, offset = points[start], points[target], points[offset]
        reach = float(radius + self.agent_radius.item(k))
        return (radius, self.tables.base(radius), reach, speed, 0.0, start, target, offset, start, False, True, False)

    def _append_spot(self, k: int) -> None:
        j = int(self.spot_count[k])
        if j == self.spots.shape[1]:
            self._grow_spots(2 * j)
        self.spots[k, j] = self._new_spot(k, DirectDraws(self.rngs[k]), self.slot_options[k])
        self.spot_count[k] = j + 1
        self.drawn_is_listed = False

    # --------------------------------------------------------------------------------------------- reset
    def _reset_slots(self, slots: list[int], rngs: list[np.random.Generator], opts: dict[str, Any]) -> None:
        """New episodes with the same options: per-slot draws in the reference's order, the rest for all at once."""
        record, orders, start, record_bytes, start_bytes = self._episode_settings(opts)
        idx = np.array(slots, dtype=np.int64)
        # (most resets are of one slot: a slice then selects it without the cost of fancy indexing)
        sel = slice(slots[0], slots[0] + 1) if len(slots) == 1 else idx
        self.settings_bytes[sel] = record_bytes
        self.episode_bytes[sel] = start_bytes
        for k in slots:
            self.orders[k] = orders
        self._use_tables(int(opts["spot_max_radius"]))
        count = opts["initial_spawns"]
        if count > self.spots.shape[1]:
            self._grow_spots(max(count, 2 * self.spots.shape[1]))
        self.spot_bytes[sel, count:] = self.unused_row_bytes[count:]
        self.drawn_is_listed = False
        self.item_map[sel] = 0
        if not self.endless:
            most = max(opts["num_coins"], default=0)
            if most > self.coin_x.shape[1]:
                grow = ((0, 0), (0, most - self.coin_x.shape[1]))
                self.coin_x, self.coin_y = np.pad(self.coin_x, grow), np.pad(self.coin_y, grow)
                self.coin_alive = np.pad(self.coin_alive, grow)
            self.coin_alive[sel] = False
        for k, rng in zip(slots, rngs, strict=True):
            self._draw_level(k, DirectDraws(rng), opts)
        self.hud[sel] = reset_hud_row(
            self.endless, bool(opts["show_last_action"]), bool(opts["show_last_positive_reward"])
        )
        for k in slots:
            self._build_lit(k)
        # under the darkness: the blue lit picture with the hidden agent (facing up) on top (see ``_update_under``)
        key = self.agent_key[sel] + self.pos[sel] @ UNDER_KEY_POSITION
        self.under_key[sel] = key
        self.under[sel] = self.lit[0, sel]
        if record["agent_hidden"]:
            self._paste_agents(self.under_buffer, idx, (key >> 15) - 1, self.x[sel], self.y[sel])
        # the reset frames: no holes yet, so the darkness (alpha 0 when the light dims) covers everything
        out = np.empty((len(slots) + 1, SCREEN, ROW_BYTES), np.uint8)  # the frames and a scratch frame
        alpha = int(record["alphas"][0])
        out[:-1] = darken(self.under[sel], np.array(alpha)) if alpha else self.under[sel]
        self._finish_frames(sel, out)
        self._frames_to_write()
        self.frames[sel] = out[:-1]
        self.stale[sel] = False

    def _draw_level(self, k: int, draws: DirectDraws, opts: dict[str, Any]) -> None:
        """Slot k's agent, first spotlights, coins and exit, with the reference's draws in its order."""
        mask = np.zeros((SCREEN, SCREEN), bool)
        self.heading[k] = draws.integers(0, 8)  # heading index (x 45 degrees): what rng.choice draws
        if opts["sample_agent_position"]:
            # (the endless coin is drawn from a cleared sampler: nothing reads the agent's block there)
            x, y = sample_position(mask, draws, 0 if self.endless else AGENT_BLOCK, empty=True)
            x, y = x + draws.integers(2, 4), y + draws.integers(2, 4)  # not clamped (kept quirk)
        else:
            x, y = CENTRE, CENTRE
            block_position(mask, x, y, ITEM_BLOCK)
        self.pos[k] = x, y
        spots = self.spots[k]
        for j in range(opts["initial_spawns"]):
            spots[j] = self._new_spot(k, draws, opts)  # (a record from a tuple: fast, unlike arrays of records)
        if self.endless:
            self._spawn_endless_coin(k, draws, previous=None)
            return
        counts = opts["num_coins"]
        num_coins = int(counts[draws.integers(0, len(counts))]) if counts else 0  # what rng.choice(counts) draws
        self.num_coins[k] = self.coins_left[k] = num_coins
        self.goal_without_exit[k] = not opts["use_exit"] and num_coins > 0
        for j in range(num_coins):
            cx, cy = sample_position(mask, draws, ITEM_BLOCK)
            cx, cy = cx + draws.integers(2, 4), cy + draws.integers(2, 4)
            self._place_coin(k, j, clamp_item(cx), clamp_item(cy))
        if opts["use_exit"]:
            ex, ey = sample_position(mask, draws, 0)  # (the last draw from this mask)
            ex, ey = ex + draws.integers(2, 4), ey + draws.integers(2, 4)
            self.exit_x[k], self.exit_y[k] = clamp_item(ex), clamp_item(ey)
            if num_coins == 0:
                self.item_map[k] |= OPEN_EXIT_BIT  # the exit opens in the first step

    def alpha(self, slots: np.ndarray | int) -> np.ndarray:
        """The darkness alpha of the slots' current frames."""
        return self.alphas[slots, np.minimum(self.t[slots], ALPHA_STEPS - 1)]

    def _place_coin(self, k: int, j: int, x: int, y: int) -> None:
        self.coin_x[k, j], self.coin_y[k, j] = x, y
        self.coin_alive[k, j] = True
        mark_touch(self.item_map[k], x, y, int(self.coin_reach[k]), 1 << j)

    def _spawn_endless_coin(self, k: int, draws: DirectDraws, previous: tuple[int, int] | None) -> None:
        """A new coin: the sampler is cleared, the old coin's place blocked, then a draw (the reference's order)."""
        mask = np.zeros((SCREEN, SCREEN), bool)
        if previous is not None:
            block_position(mask, previous[0], previous[1], AGENT_BLOCK)
        cx, cy = sample_position(mask, draws, 0, empty=previous is None)  # (the mask is not drawn from again)
        cx, cy = cx + draws.integers(2, 4), cy + draws.integers(2, 4)
        self.item_map[k] = 0
        self._place_coin(k, 0, clamp_item(cx), clamp_item(cy))

    # ---------------------------------------------------------------------------------------------- step
    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        act = actions.reshape(-1, 2) @ ACTION_WEIGHTS  # 3 * horizontal + vertical
        n = act.shape[0]
        slots = self.all_slots if isinstance(idx, slice) else idx
        # 1. move, clamped into the walkable area below the HUD
        pos = self.pos[idx] + self.vel[slots, act]
        np.maximum(np.minimum(pos, self.pos_high[idx], out=pos), self.pos_low[idx], out=pos)
        self.pos[idx] = pos
        self.heading[idx] = NEXT_HEADING[self.heading[idx], act]
        # 2. the HUD shows the previous action and whether the previous reward was positive (decided in step 8)
        hud_code = np.array(self.next_hud[idx])  # a copy: next_hud is updated below
        # 3. the light dims until the threshold is passed: the alpha of step t is ``alpha(k)``
        t = self.t[idx] + 1
        self.t[idx] = t
        # 4. spotlights: maybe spawn one, then draw, move and hit-test every spotlight in list order
        spawn = t == self.next_spawn[idx]
        if np.count_nonzero(spawn):
            self._spawn_spots(slots[spawn])
        hit, spots = self._spotlight_pass(idx, pos)
        self.hit[idx] = hit
        dead = None
        if np.count_nonzero(hit):
            rewards = np.where(hit, self.reward_inside[idx], self.reward_outside[idx])
            health = self.health[idx] - self.spot_damage[idx] * hit
            self.health[idx] = health
            self.hud_red[idx] = np.trunc(SCREEN // 2 * (1 - health / self.max_health[idx]))
            dead = health <= 0
            rewards += self.reward_death[idx] * dead
        else:
            rewards = np.array(self.reward_outside[idx])
        # 5.-7. coins and exit (a lookup of what touches the agent's position), termination
        touching = self.item_map[slots, pos[:, 1], pos[:, 0]]
        terminated = t == self.end_t_now[idx]
        if np.count_nonzero(touching):
            self._item_events(slots, touching.nonzero()[0], touching, rewards, terminated, dead)
        if dead is not None:
            terminated |= dead
        # 8. the HUD of the next step shows this action and whether this reward was positive
        self.next_hud[idx] = self.hud_next[idx] + 3 * act + (rewards > 0)
        self._draw(idx, slots, n, hit, hud_code, spots)
        return rewards, terminated

    def _spawn_spots(self, slots: np.ndarray) -> None:
        for k in slots.tolist():
            self._append_spot(k)
        self.next_spawn[slots] += self.spawn_interval[slots]
        if not self.endless:
            left = self.spawns_left[slots] - 1
            self.spawns_left[slots] = left
            self.next_spawn[slots[left == 0]] = NEVER

    def _item_events(
        self,
        slots: np.ndarray,
        local: np.ndarray,
        touching: np.ndarray,
        rewards: np.ndarray,
        terminated: np.ndarray,
        dead: np.ndarray | None,
    ) -> None:
        """Coins, exit and goal for the slots whose agent touches a coin or the exit (in place)."""
        for i in local:
            k = int(slots[i])
            bits = int(touching[i])
            x, y = int(self.x[k]), int(self.y[k])
            if self.endless:
                # The coin clock restarts: it reads 0 after this pickup and 1 after this step, as if it had been
                # set to 0 one step earlier (at reset it is 0 at step 0).
                rewards[i] += self.reward_coin[k]
                self.coins_collected[k] += 1
                zero_t = int(self.t[k]) - 1
                self.coin_shown_until[k] = zero_t + int(self.coin_show_duration[k])
                if not self.any_visible[k]:
                    self.special_until[k] = self.coin_shown_until[k]
                per_coin = int(self.steps_per_coin[k])
                self.end_t_now[k] = min(int(self.end_t[k]), NEVER if per_coin == NEVER else zero_t + per_coin)
                terminated[i] = self.t[k] == self.end_t_now[k]
                previous = (int(self.coin_x[k, 0]), int(self.coin_y[k, 0]))
                self._spawn_endless_coin(k, DirectDraws(self.rngs[k]), previous)
                self._build_lit(k)
                continue
            coin_reward = 0.0
            removed_before = taken = False
            for j in range(self.coin_alive.shape[1]):  # the reference's list iteration with removal
                if not self.coin_alive[k, j]:
                    continue
                got = bool(bits >> j & 1) and not removed_before
                if got:
                    coin_reward += self.reward_coin[k]
                    self.coin_alive[k, j] = False
                    self.coins_collected[k] += 1
                    self.coins_left[k] -= 1
                    self.item_map[k] &= np.uint16(~(1 << j) & 0xFFFF)
                    taken = True
                removed_before = got
            rewards[i] += coin_reward
            coins_done = self.coins_left[k] == 0
            reached = False
            if self.use_exit[k] and coins_done:
                if not self.exit_open[k]:
                    self.exit_open[k] = True
                    taken = True
                    self.item_map[k] &= np.uint16(~OPEN_EXIT_BIT & 0xFFFF)
                    mark_touch(self.item_map[k], int(self.exit_x[k]), int(self.exit_y[k]), self.exit_reach[k], EXIT_BIT)
                reached = math.sqrt((self.exit_x[k] - x) ** 2 + (self.exit_y[k] - y) ** 2) <= self.exit_reach[k]
                if reached:
                    rewards[i] += self.reward_exit[k]
            if taken:
                self._build_lit(k)
            goal = coins_done and (reached or self.goal_without_exit[k])
            if goal:
                self.success[k] = not (dead is not None and dead[i])
                terminated[i] = True

    def _spotlight_pass(self, idx: Index, pos: np.ndarray) -> tuple[np.ndarray, tuple]:
        """Draw (record), move and hit-test the spotlights; finished ones are removed when next visited.

        Returns the per-slot hit flags and what the drawing needs: the centres, table offsets and the drawn
        spotlights.
        """
        width = int(self.spot_count[idx].max())  # list positions past every slot's count are unused
        spots = self.spots[idx, :width] if isinstance(idx, slice) else self.spot_bytes[idx, :width].view(SPOTS)
        tau = spots["tau"]
        rest = 1.0 - tau
        centre = spots["start"] * rest  # pygame's lerp a * (1 - t) + b * t, twice: a curve from S to O
        centre += (spots["target"] * rest + spots["offset"] * tau) * tau
        delta = centre - pos.astype(np.float64).view(np.complex128)
        dx, dy = delta.real, delta.imag
        distance = np.sqrt(dx * dx + dy * dy)
        hits = distance <= spots["reach"]
        base = spots["base"]
        done = spots["done"]
        drawn = spots["listed"]
        removed = None
        if np.count_nonzero(done):  # (done is written below: ``removed`` and ``drawn`` are computed first)
            # The reference removes finished spotlights while iterating over its list, so the spotlight right
            # after a removed one is not visited in that step: not drawn, not moved, unable to hit.
            drawn, removed = drawn.copy(), np.zeros_like(done)
            for i in done.any(axis=1).nonzero()[0]:
                visited, skip = [], False
                for finished in done[i].tolist():
                    visited.append(not skip)
                    skip = not skip and finished
                drawn[i] &= visited & ~done[i]
                removed[i] = visited & done[i]
            hits &= drawn
            speed = spots["speed"] * drawn  # only the visited spotlights move
        else:
            speed = spots["speed"]
        store_drawn = removed is not None or not isinstance(idx, slice) or not self.drawn_is_listed
        if isinstance(idx, slice):  # ``spots`` is a view: update in place
            np.add(tau, speed, out=tau)
            np.minimum(tau, 1.0, out=tau)
            np.greater_equal(tau, 1.0, out=done)
            spots["centre"] = centre
            if store_drawn:
                spots["drawn"] = drawn
        else:
            tau = np.minimum(tau + speed, 1.0)
            self.spots["tau"][idx, :width] = tau
            self.spots["done"][idx, :width] = tau >= 1.0
            self.spots["centre"][idx, :width] = centre
            self.spots["drawn"][idx, :width] = drawn
        if store_drawn:  # (else every listed spotlight was drawn in this and the last step)
            self.drawn_is_listed = removed is None and isinstance(idx, slice)
        if removed is not None and np.count_nonzero(removed):
            base = base.copy()  # a view of the arrays that the removal compacts
            self._remove_spots(idx, removed)
        return hits.any(axis=1), (centre, base, drawn)

    def _remove_spots(self, idx: Index, removed: np.ndarray) -> None:
        """Compact the spotlight lists (keeping their order); freed positions get the unused values."""
        local = removed.any(axis=1).nonzero()[0]
        slots = self.all_slots[idx][local]
        width = removed.shape[1]  # (positions past it are unused)
        spots = self.spot_bytes[slots, :width]
        keep = self.spots["listed"][slots, :width] & ~removed[local]
        order = np.argsort(~keep, axis=1, kind="stable")
        compacted = np.take_along_axis(spots, order, axis=1)
        count = keep.sum(axis=1)
        compacted[np.arange(compacted.shape[1])[None, :] >= count[:, None]] = as_bytes(self.unused_spot)
        self.spot_bytes[slots, :width] = compacted
        self.spot_count[slots] = count

    # ---------------------------------------------------------------------------------------------- draw
    def _draw(self, idx: Index, slots: np.ndarray, n: int, hit: np.ndarray, hud_code: np.ndarray, spots) -> None:
        """Bring the pictures under the darkness and the HUD up to date, then draw the stepped slots' frames."""
        self._update_under(idx, hit & self.red_feedback[idx])
        self.hud[idx, ROW_BYTES // 2 :] = hud_tables()[1][hud_code]
        if np.count_nonzero(hit):
            self._paint_red(idx, slots, hud_code)
        if isinstance(idx, slice):
            self._draw_frames(idx, self._frames_to_write(), spots)
            self.stale.fill(False)
        else:
            out = np.empty((n + 1, SCREEN, ROW_BYTES), np.uint8)
            self._draw_frames(idx, out, spots)
            self._frames_to_write()
            self.frames[idx] = out[:-1]
            self.stale[idx] = False

    def _draw_frames(self, idx: Index, out: np.ndarray, spots: tuple | None = None) -> None:
        """Draw the frames of the slots ``idx`` into ``out`` (their frames, then a scratch frame) from the state: the
        holes of the spotlights drawn in the last step (``spots``: their centres, table offsets and drawn flags, read
        from the spotlight records when not given), the picture under the darkness and the HUD (see the module
        docstring)."""
        if spots is None:
            width = int(self.spot_count[idx].max(initial=0))
            records = self.spot_bytes[idx, :width].view(SPOTS)
            spots = records["centre"], records["base"], records["drawn"]
        frames = out[:-1]
        self._hole_masks(frames, *spots)
        np.bitwise_and(frames, self.under if isinstance(idx, slice) else self.under[idx], out=frames)
        blend = (self.t[idx] < self.blend_until[idx]).nonzero()[0]
        if blend.size:
            self._blend_slots(self.all_slots[idx][blend], blend, frames)
        self._finish_frames(idx, out)

    def _paint_red(self, idx: Index, slots: np.ndarray, hud_code: np.ndarray) -> None:
        """The HUD's health bar after a hit: red from the left, as wide as the lost share of the health."""
        left = hud_tables()[0]
        red = self.hud_red[idx]
        self.hud[idx, : ROW_BYTES // 2] = left[np.minimum(red, SCREEN // 2)]
        for i in (red > SCREEN // 2).nonzero()[0]:  # health below 0: the red part reaches into the right half
            flags, code = divmod(int(hud_code[i]), 27)
            action, reward_state = (code // 9, code // 3 % 3), code % 3
            self.hud[slots[i]] = paint_hud_row(
                bool(flags & 4), bool(flags & 2), bool(flags & 1), action, reward_state, int(red[i])
            )

    def _hole_masks(self, out: np.ndarray, centre: np.ndarray, base: np.ndarray, drawn: np.ndarray) -> None:
        """Write the 0/255 masks of this step's spotlight holes into ``out`` ((n, 84, 252)), gathered row by row.

        Each disc row writes its span code into its frame row; one gather from the span table then yields every
        row with the last span written to it. The spans that lost their row to another one are OR-ed in after.
        """
        tables = self.tables
        flat = np.flatnonzero(drawn)  # (flat positions: ``take`` is cheaper than a 2-d fancy index)
        local = flat // drawn.shape[1]
        centre, base = centre.take(flat), base.take(flat)
        at_x = centre.real.astype(np.intp)  # the table rows of the centres' x and y
        at_x += base
        at_y = centre.imag.astype(np.intp)
        at_y += base
        # spotlights wholly off the screen (about half of them: they start and end outside) are left out at once
        seen = tables.columns_seen.take(at_x)
        seen &= tables.rows_seen.take(at_y)
        if np.count_nonzero(seen) < seen.size:
            seen = seen.nonzero()[0]
            local, at_x, at_y = local.take(seen), at_x.take(seen), at_y.take(seen)
        # (spotlights, disc rows): the span codes and screen rows, 0 unless the span is visible and on a visible row
        codes = tables.codes.take(at_x, axis=0)
        codes *= tables.rows_visible.take(at_y, axis=0)
        keys = tables.rows.take(at_y, axis=0)
        keys *= tables.codes_visible.take(at_x, axis=0)  # empty spans go to row 0 (under the HUD): no collisions
        keys = keys.astype(np.intp)  # (flat intp arrays: several times faster to scatter)
        keys += local[:, None] * SCREEN
        keys, codes = keys.ravel(), codes.ravel()
        index = self.span_index[: out.shape[0] * SCREEN]
        index.fill(0)
        index[keys] = codes
        rows = out.reshape(-1, ROW_BYTES)
        tables.span_rows.take(index, axis=0, out=rows, mode="clip")
        lost = (index[keys] != codes).nonzero()[0]  # spans that lost their row to another one
        if lost.size:
            self._or_lost_spans(rows.view(ROW).reshape(-1), keys[lost], codes[lost])

    def _or_lost_spans(self, rows: np.ndarray, keys: np.ndarray, codes: np.ndarray) -> None:
        """OR the spans ``codes`` into the frame ``rows`` (items of one row) ``keys``, a layer at a time: one span
        per row in each layer (a row crossed by several lost spans takes several layers, usually one or two)."""
        words = self.tables.span_words
        claim = self.span_claim
        if self.positions.size < keys.size:
            self.positions = np.arange(2 * keys.size)
        while True:
            position = self.positions[: keys.size]
            claim[keys] = position  # the last span of each row claims it for this layer
            now = claim[keys] == position
            if np.count_nonzero(now) < keys.size:
                keys_now, codes_now = keys[now], codes[now]
                later = np.logical_not(now, out=now)  # spans left for a later layer
                keys, codes = keys[later], codes[later]
            else:
                keys_now, codes_now, keys = keys, codes, None
            union = rows.take(keys_now)
            union_words = union.view(np.uint32).reshape(keys_now.size, -1)
            np.bitwise_or(union_words, words.take(codes_now, axis=0), out=union_words)
            rows.put(keys_now, union)
            if keys is None:
                return

    def _update_under(self, idx: Index, red: np.ndarray) -> None:
        """Bring the stepped slots' pictures under the darkness up to date: the lit picture (red on hit steps with
        visual feedback) with the hidden agent on top. A slot is rebuilt when its lit picture changed or the floor
        colour flips; an agent that moved or turned is erased (its rows copied back from the lit picture) and
        pasted again.

        What a picture shows is one number per slot, its under key: (hidden agent's sprite id + 1) << 15, the
        agent's centre y << 8 and x << 1, and the red floor bit (a reset frame's key has the agent facing up).
        """
        key = self.heading[idx] * self.heading_key[idx]
        key += self.agent_key[idx]
        key += self.pos[idx] @ UNDER_KEY_POSITION
        key += red
        old = self.under_key[idx]
        changed = (key != old).nonzero()[0]
        if not changed.size:
            return
        if changed.size <= self.FEW_UNDER_UPDATES:
            self._update_few_unders(self.all_slots[idx][changed].tolist(), key[changed].tolist(), old[changed].tolist())
            return
        slots, key, old = self.all_slots[idx][changed], key[changed], old[changed]
        self.under_key[slots] = key
        source = (key & 1) * self.num_envs + slots  # the slots' lit pictures in ``lit`` seen as 2n pictures
        rebuild = (old ^ key | old >> 63) & 1  # the floor colour flipped, or the lit picture changed (key -1)
        erase = (old >> 15) * (1 - rebuild)  # (an agent was drawn, no rebuild)
        if np.count_nonzero(rebuild):
            rebuild = rebuild.nonzero()[0]
            self.under[slots[rebuild]] = self.lit.reshape(-1, SCREEN, ROW_BYTES)[source[rebuild]]
        if np.count_nonzero(erase):  # copy its rows back
            erase = erase.nonzero()[0]
            old_id = (old[erase] >> 15) - 1
            half = self.agent_sprites.heights[old_id] // 2
            top = (old[erase] >> 8 & 127) - half
            height = int(self.agent_sprites.heights[old_id].max())
            rows = np.minimum(np.maximum(top[:, None] + np.arange(height), 0), SCREEN - 1)
            lit_rows, under_rows = self.lit.view(ROW).reshape(-1), self.under.view(ROW).reshape(-1)
            under_rows[slots[erase, None] * SCREEN + rows] = lit_rows[source[erase, None] * SCREEN + rows]
        ids = (key >> 15) - 1
        if np.count_nonzero(ids >= 0) < ids.size:
            paste = (ids >= 0).nonzero()[0]
            slots, ids = slots[paste], ids[paste]
        if slots.size:
            self._paste_agents(self.under_buffer, slots, ids, self.x[slots], self.y[slots])

    def _update_few_unders(self, slots: list[int], keys: list[int], olds: list[int]) -> None:
        """``_update_under`` for a few changed slots (most steps of a batch with few moving agents), on views."""
        heights, sprites = self.agent_sprites.heights, self.agent_sprites.sprites
        for k, key, old in zip(slots, keys, olds, strict=True):
            self.under_key[k] = key
            lit, under = self.lit[key & 1, k], self.under[k]
            if old < 0 or (old ^ key) & 1:  # the lit picture changed, or the floor colour flipped
                under[...] = lit
            elif old >> 15:  # erase the agent: copy its rows back
                height = int(heights[(old >> 15) - 1])
                top = (old >> 8 & 127) - height // 2
                rows = slice(max(top, 0), max(top + height, 0))
                under[rows] = lit[rows]
            if key >> 15:
                sprite_id = (key >> 15) - 1
                paste_centred(sprites[sprite_id], under, key >> 1 & 127, key >> 8 & 127, int(heights[sprite_id]) // 2)

    def _paste_agents(self, frames: np.ndarray, local: np.ndarray, ids: np.ndarray, x: np.ndarray, y: np.ndarray):
        """Paste agent sprites ``ids`` centred on (x, y) into ``frames[local]`` (a buffer ending with a spare frame)."""
        half = self.agent_sprites.heights[ids] // 2  # square sprites, centred on the agent
        self._paste_sprites(self.agent_sprites, frames, local, ids, x, y, half)

    def _paste_coins(self, frames: np.ndarray, local: np.ndarray, slots: np.ndarray) -> None:
        """Paste the first coin of each of ``slots`` into ``frames[local]`` (a buffer ending with a spare frame)."""
        ids = self.coin_sprite[slots]
        radius = self.coin_sprites.heights[ids] // 2 - 1  # the coin's canvas is one px larger than its disc
        self._paste_sprites(self.coin_sprites, frames, local, ids, self.coin_x[slots, 0], self.coin_y[slots, 0], radius)

    @staticmethod
    def _paste_sprites(
        scatter: SpriteScatter,
        frames: np.ndarray,
        local: np.ndarray,
        ids: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        centre: np.ndarray,
    ) -> None:
        """Paste sprites ``ids`` of ``scatter`` with their pixel (centre, centre) on (x, y) into ``frames[local]``."""
        if len(local) <= 2:  # a few sprites: slice pastes are cheaper than the batched scatter
            sprites = scatter.sprites
            for i, sprite_id, cx, cy, c in zip(
                local.tolist(), ids.tolist(), x.tolist(), y.tolist(), centre.tolist(), strict=True
            ):
                paste_centred(sprites[sprite_id], frames[i], cx, cy, centre=c)
            return
        scatter.paste(frames.reshape(-1, SCREEN, SCREEN, 3), local, ids, y - centre, x - centre, True)

    def _agent_ids(self, slots: np.ndarray) -> np.ndarray:
        """The agents' sprite ids in the current frames (the reset frame shows the agent facing up)."""
        return self.agent_sprite0[slots] + (self.t[slots] > 0) * self.heading[slots]

    def _build_lit(self, k: int) -> None:
        """Slot k's lit pictures (blue and red floor) with its coins and exit, in the reference's order."""
        rows = self.lit[:, k]
        self.under_key[k] = -1  # rebuild the picture under the darkness
        rows[...] = floor_pair(int(self.floor_kind[k]), bool(self.red_feedback[k]))
        if self.coins_left[k]:
            coin, radius = coin_sprite(float(self.coin_scale[k])), int(10 * self.coin_scale[k])
            for j in self.coin_alive[k].nonzero()[0]:
                paste_centred(coin, rows, self.coin_x[k, j], self.coin_y[k, j], centre=radius)
        if self.use_exit[k]:
            door = exit_sprite(float(self.exit_scale[k]), bool(self.exit_open[k]))
            paste_centred(door, rows, self.exit_x[k], self.exit_y[k])

    def _paste_entity(self, frames: np.ndarray, i: int, k: int, name: str) -> None:
        """Paste one entity of slot k into frame ``i`` of ``frames`` (a buffer ending with a scratch frame)."""
        if name == "agent":
            slot = np.array([k])
            self._paste_agents(frames, np.array([i]), self._agent_ids(slot), self.x[slot], self.y[slot])
        elif name == "coins":
            coin, radius = coin_sprite(float(self.coin_scale[k])), int(10 * self.coin_scale[k])
            for j in self.coin_alive[k].nonzero()[0]:
                paste_centred(coin, frames[i], self.coin_x[k, j], self.coin_y[k, j], centre=radius)
        else:
            door = exit_sprite(float(self.exit_scale[k]), bool(self.exit_open[k]))
            paste_centred(door, frames[i], self.exit_x[k], self.exit_y[k])

    def _coin_above(self, k: int) -> bool:
        """Whether slot k's coin is drawn above the darkness now (endless: also while it is new)."""
        return bool(self.coins_visible[k]) or (self.endless and self.t[k] < self.coin_shown_until[k])

    def _finish_frames(self, idx: Index, out: np.ndarray) -> None:
        """Entities above the darkness, the HUD, then the entities that the reference draws after the HUD.

        ``out`` holds the frames of the slots ``idx`` followed by a scratch frame.
        """
        slots = self.all_slots[idx]
        if self.endless or np.count_nonzero(self.any_visible):  # slots drawing an entity above the darkness
            special = (self.t[idx] < self.special_until[idx]).nonzero()[0]
        else:
            special = ()
        if self.endless and len(special):  # the new coin, the only entity above the darkness: pasted at once
            alone = ~self.any_visible[slots[special]]
            if np.count_nonzero(alone):
                self._paste_coins(out, special[alone], slots[special[alone]])
                special = special[~alone]
        for i in special:
            k = int(slots[i])
            for name in self.orders[k][self._coin_above(k)][0]:
                self._paste_entity(out, i, k, name)
        out[:-1, :HUD_ROWS] = self.hud[idx][:, None]
        for i in special:
            k = int(slots[i])
            for name in self.orders[k][self._coin_above(k)][1]:
                self._paste_entity(out, i, k, name)

    def _blend_slots(self, slots: np.ndarray, local: np.ndarray, out: np.ndarray) -> None:
        """Frames with a partly transparent darkness or with spotlight rings: lit in the holes, blended elsewhere.

        ``slots`` are slot numbers and ``local`` their frames in ``out``, which hold ``under & hole_mask`` (the lit
        picture in the holes, 0 elsewhere): the blended frame is the bytewise maximum of that and the darkened
        picture, which is nowhere brighter than the lit one. Slot by slot, on views: the few slots blending in a
        step (those in their first steps) cost less so than gathered into and scattered out of a batch.
        """
        for i, k, alpha in zip(local.tolist(), slots.tolist(), self.alpha(slots).tolist(), strict=True):
            under, frame = self.under[k], out[i]
            if alpha:
                np.maximum(frame, darken(under, alpha), out=frame)
                if self.rings[k]:
                    self._draw_rings(k, frame, under)
            else:
                frame[...] = under

    def _draw_rings(self, k: int, frame: np.ndarray, under: np.ndarray) -> None:
        """White 1-px outlines (black_background), blended over ``under`` (what lies beneath the darkness).

        Holes and outlines are painted in list order, so a later hole can cut into an earlier outline.
        """
        state = np.zeros((SCREEN, SCREEN), np.int8)  # 0 darkness, 1 hole, 2 outline
        spots = self.spots[k]
        for j in spots["drawn"].nonzero()[0]:
            centre, radius = spots["centre"][j], int(spots["radius"][j])
            disc, offset = disc_mask(radius)
            ring = ring_mask(radius)
            top, left = int(centre.imag) + offset, int(centre.real) + offset
            r0, c0 = max(top, 0), max(left, 0)
            r1, c1 = min(top + disc.shape[0], SCREEN), min(left + disc.shape[1], SCREEN)
            if r0 < r1 and c0 < c1:
                window = state[r0:r1, c0:c1]
                window[disc[r0 - top : r1 - top, c0 - left : c1 - left]] = 1
                window[ring[r0 - top : r1 - top, c0 - left : c1 - left]] = 2
        outline = np.repeat(state == 2, 3, axis=1)
        frame[outline] = lighten(under, int(self.alpha(k)))[outline]

    # ------------------------------------------------------------------------------------------ faces
    def observations(self, idx: np.ndarray | None = None) -> np.ndarray:
        """Copies of the current observations. All of them come without a copy: the frame buffer itself is handed
        over, and the core continues in a new one (frames it has to read before drawing them again are drawn again
        from the state, see ``_current_frames``)."""
        if idx is not None:
            return super().observations(idx)
        frames = self._current_frames(slice(None))
        self.frames_lent = True
        return frames.reshape(-1, SCREEN, SCREEN, 3)

    def _frames_to_write(self) -> np.ndarray:
        """The frame buffer (the frames, then a scratch frame), ready to be written: a new one, with every frame
        stale, if the current one was handed over."""
        if self.frames_lent:
            self.frame_buffer = np.empty_like(self.frame_buffer)
            self.frames = self.frame_buffer[:-1]
            self.stale.fill(True)
            self.frames_lent = False
        return self.frame_buffer

    def _current_frames(self, idx: Index) -> np.ndarray:
        """The frames, with those of the slots ``idx`` up to date."""
        self._frames_to_write()
        redraw = self.all_slots[idx][self.stale[idx]]
        if redraw.size:
            out = np.empty((redraw.size + 1, SCREEN, ROW_BYTES), np.uint8)
            self._draw_frames(redraw, out)
            self.frames[redraw] = out[:-1]
            self.stale[redraw] = False
        return self.frames

    def _max_episode_steps(self, opts: dict[str, Any]) -> int:
        return int(opts["max_steps"])  # memory-gym reports the option as it is (<= 0: no cap)

    def _observation(self, idx: Index) -> np.ndarray:
        return self._current_frames(idx)[idx].reshape(-1, SCREEN, SCREEN, 3)

    def _final_info(self, k: int) -> dict[str, Any]:
        info: dict[str, Any] = {"agent_health": float(self.health[k] / self.max_health[k])}
        if self.endless:
            info["coins_collected"] = int(self.coins_collected[k])
        else:
            num = int(self.num_coins[k])
            info["coins_collected"] = float(self.coins_collected[k] / num) if num else float("nan")
            info["success"] = int(self.success[k])
        return info

    def _step_info(self, k: int) -> dict[str, Any]:
        if not self.endless:
            return {}
        position = [self.pos.item(k, 0), self.pos.item(k, 1), self.coin_x.item(k, 0), self.coin_y.item(k, 0)]
        return {"ground_truth": np.divide(position, float(SCREEN))}  # float64, as in the reference

    def _step_infos(self) -> dict[str, np.ndarray]:
        if not self.endless:
            return {}
        position = np.concatenate([self.pos, self.coin_x[:, :1], self.coin_y[:, :1]], axis=1)
        return {"ground_truth": np.divide(position, float(SCREEN))}

    def _debug_frame(self, k: int) -> np.ndarray:
        """Floor, the darkness with the last step's holes, then exit, coins, agent and HUD above it."""
        floor = floor_rows(int(self.floor_kind[k]), bool(self.hit[k] and self.red_feedback[k]))
        pixels = np.zeros((SCREEN, SCREEN), bool)
        spots = self.spots[k]
        for j in np.flatnonzero(spots["drawn"]):
            centre = spots["centre"][j]
            disc, offset = disc_mask(int(spots["radius"][j]))
            top, left = int(centre.imag) + offset, int(centre.real) + offset
            # clipped to the screen: large spotlights (radius up to 42) start and end far off-screen
            r0, c0 = max(top, 0), max(left, 0)
            r1, c1 = min(top + disc.shape[0], SCREEN), min(left + disc.shape[1], SCREEN)
            if r0 < r1 and c0 < c1:
                pixels[r0:r1, c0:c1] |= disc[r0 - top : r1 - top, c0 - left : c1 - left]
        holes = np.repeat(pixels, 3, axis=1).astype(np.uint8) * 255
        frames = np.zeros((2, SCREEN, ROW_BYTES), np.uint8)  # the picture and a scratch frame
        frames[0] = np.maximum(darken(floor, np.array(self.alpha(k))), floor & holes)
        if self.rings[k]:
            self._draw_rings(k, frames[0], floor)
        for name in ("coins", "agent") if self.endless else ("exit", "coins", "agent"):
            if name != "exit" or self.use_exit[k]:
                self._paste_entity(frames, 0, k, name)
        frames[0, :HUD_ROWS] = self.hud[k]
        return frames[0].reshape(SCREEN, SCREEN, 3)
