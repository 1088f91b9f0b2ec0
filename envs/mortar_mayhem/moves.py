"""Mortar Mayhem's movement tables: free movement (clamped, or wrapped on the endless torus) and grid movement, as
transition tables built once per configuration."""

from __future__ import annotations

from functools import cache

import numpy as np

from envs.drawing import SCREEN, round_half_away
from envs.mortar_mayhem.pictures import ENDLESS_ARENA, TILE, arena_left
from envs.movement import clamp_centre, continuous_heading, continuous_velocity, grid_step

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
