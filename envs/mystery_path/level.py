"""The Mystery Path level: its 7x7 grid of 12-px tiles, colours, controllers (free, grid, endless) as tables, and
what a tile is for the agent."""

from __future__ import annotations

from functools import cache

import numpy as np

from envs.drawing import SCREEN
from envs.movement import continuous_heading, continuous_velocity, grid_step

GRID = 7  # tiles per side of a level (and of an endless segment)
TILE = SCREEN // GRID  # 12 px
GRID_AGENT_SCALE = 0.25  # the grid variant ignores agent_scale

ORIGIN_COLOUR = (0, 0, 255)
GOAL_COLOUR = (0, 255, 0)
PATH_COLOUR = (255, 255, 255)
WALL_COLOUR = (255, 0, 0)
CROSS_COLOUR = (255, 0, 0)
TILE_BORDER = (210, 210, 210)

# Free movement: an action pair (horizontal, vertical) is coded as 3 * horizontal + vertical. Endless actions are
# 0 none, 1 right, 2 up, 3 down. Heading -1 means "unchanged".
FREE_ACTIONS = np.array([(h, v) for h in range(3) for v in range(3)], dtype=np.int64)
ENDLESS_ACTIONS = np.array([[0, 0], [2, 0], [0, 1], [0, 2]], dtype=np.int64)
FREE_HEADINGS = continuous_heading(FREE_ACTIONS, np.full(len(FREE_ACTIONS), -1))
ENDLESS_HEADINGS = continuous_heading(ENDLESS_ACTIONS, np.full(len(ENDLESS_ACTIONS), -1))


def _grid_transitions() -> np.ndarray:
    """Grid movement as a table: state ``4 * tile + heading // 90`` and action -> next state (tile = 7 * x + y)."""
    state = np.arange(GRID * GRID * 4)
    tile, quarter = state // 4, state % 4
    table = np.empty((len(state), 4), dtype=np.int64)
    for action in range(4):
        x, y, heading = grid_step(np.full(len(state), action), tile // GRID, tile % GRID, quarter * 90, GRID)
        table[:, action] = (x * GRID + y) * 4 + heading // 90
    return table


GRID_NEXT = _grid_transitions()
TILE_OF_PIXEL = (np.arange(SCREEN)[:, None] // TILE) * GRID + np.arange(SCREEN)[None, :] // TILE  # [x, y] -> tile
TILE_CENTRES = np.array([(x * TILE + TILE // 2, y * TILE + TILE // 2) for x in range(GRID) for y in range(GRID)])

# What a Mystery Path tile is for the agent; a visited NEW tile becomes PATH.
OFF, PATH, NEW, GOAL = 0, 1, 2, 3
AFTER_VISIT = np.array([OFF, PATH, PATH, GOAL], dtype=np.int64)


@cache
def velocities(endless: bool, speed: float) -> np.ndarray:
    """(vx, vy) of each action code of the free controller at ``speed`` px per step."""
    actions = ENDLESS_ACTIONS if endless else FREE_ACTIONS
    vx, vy = continuous_velocity(actions, np.full(len(actions), speed))
    return np.stack([vx, vy], axis=1).astype(np.int64)


def fill_tile(frame: np.ndarray, tile: tuple[int, int], colour: tuple[int, int, int]) -> None:
    x, y = tile
    frame[y * TILE : (y + 1) * TILE, x * TILE : (x + 1) * TILE] = colour
