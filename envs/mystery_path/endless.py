"""Endless Mystery Path's tables: segments, path tile flags, ground-truth directions, the scrolling floor drawn band by
band, the stamina bar, and where the past path starts behind the agent (the camera shows the path behind it)."""

from __future__ import annotations

from functools import cache

import numpy as np

from envs.drawing import SCREEN
from envs.mystery_path.level import GRID, PATH_COLOUR, TILE, TILE_BORDER

SEGMENT_COLUMNS = GRID + 1  # an endless segment plus its transition tile
INITIAL_SEGMENTS = 3

ICE_COLOUR = (125, 177, 250)
DEBUG_PATH_ALPHA = 200
STAMINA_BAR_WIDTH = 4
STAMINA_GREEN, STAMINA_RED = (0, 255, 0), (255, 0, 0)

# Endless path tiles: flags for "pays progress on the next visit" and "refills stamina on the next visit".
NEW_TILE, REFILL = 1, 2

# Endless ground truth: the direction from the current tile to the next path tile.
DIRECTIONS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.int64)  # east, north, south
EAST, NORTH, SOUTH, WEST = 0, 1, 2, -1
# By the step (dx, dy) to the next chain tile, at index 2 * dx + dy + 2 (index 2, no step: the last tile of a chain,
# a transition tile, points east).
DIRECTION_OF_STEP = np.array([WEST, NORTH, EAST, SOUTH, EAST], dtype=np.int64)

# The endless floor is drawn band by band: a band is one tile row of the screen, and all its pixel rows equal either
# its "edge" row (first and last row of a tile) or its "middle" row. Bands are padded by one tile on both sides so
# that tiles need no clipping.
BAND_PAD = TILE
BAND_WIDTH = SCREEN + 2 * BAND_PAD
TILE_EDGE_BYTES = np.tile(np.array(TILE_BORDER, dtype=np.uint8), TILE)
TILE_MIDDLE_BYTES = np.concatenate([TILE_BORDER, np.tile(PATH_COLOUR, TILE - 2), TILE_BORDER]).astype(np.uint8)
TILE_BYTE_OFFSETS = np.arange(TILE * 3)
PATH_TILE = np.empty((TILE, TILE, 3), dtype=np.uint8)  # a past-path tile: white with a grey 1-px border
PATH_TILE[:] = TILE_BORDER
PATH_TILE[1:-1, 1:-1] = PATH_COLOUR
BLACK_FLOOR = TILE  # row of the background band tables below


def _background_bands() -> tuple[np.ndarray, np.ndarray]:
    """Edge and middle rows of the endless background: rows 0..11 ice scrolled by that many px, row 12 black."""
    edge = np.zeros((TILE + 1, SCREEN, 3), dtype=np.uint8)
    middle = np.zeros((TILE + 1, SCREEN, 3), dtype=np.uint8)
    for phase in range(TILE):
        local = (np.arange(SCREEN) + phase) % TILE
        border = (local == 0) | (local == TILE - 1)
        edge[phase] = TILE_BORDER
        middle[phase] = np.where(border[:, None], TILE_BORDER, ICE_COLOUR)
    return edge, middle


BACKGROUND_EDGE, BACKGROUND_MIDDLE = _background_bands()


def _stamina_bars() -> np.ndarray:
    """The stamina bar for every red height 0..84: (85, 84, 4, 3)."""
    bars = np.empty((SCREEN + 1, SCREEN, STAMINA_BAR_WIDTH, 3), dtype=np.uint8)
    bars[:] = STAMINA_GREEN
    for height in range(SCREEN + 1):
        bars[height, :height] = STAMINA_RED
    return bars


STAMINA_BARS = _stamina_bars()


@cache
def ice_background(phase: int) -> np.ndarray:
    """The endless view's ice floor scrolled by ``phase`` px (0..11) to the left, as a whole picture."""
    band = np.empty((TILE, SCREEN, 3), dtype=np.uint8)
    band[:] = BACKGROUND_MIDDLE[phase]
    band[0] = band[TILE - 1] = BACKGROUND_EDGE[phase]
    return np.tile(band, (GRID, 1, 1))


def walk_start(xs: list[int], node: int, column: int, depth: int) -> int:
    """First chain tile of the past path drawn behind an agent in ``column + 1`` whose last path tile is ``node``
    (``xs``: the chain's columns; ``depth``: columns drawn behind the agent's column).

    The walk goes back from the tile before ``node`` and stops after the first tile whose column is at most
    ``max(0, column - depth)``, or at the first tile of the path. Nothing is drawn when ``column < 0``.
    """
    if column < 0:
        return node
    last = max(0, column - depth)
    i = node - 1
    while i > 0 and xs[i] > last:
        i -= 1
    return max(i, 0)


def walk_starts(columns: np.ndarray, depth: int) -> np.ndarray:
    """:func:`walk_start` of every tile of several chains at once: ``columns[s, i]`` is the column of tile i of
    chain s (chains shorter than the array's width are padded with anything); returns the first chain tile drawn
    behind an agent on each tile (its column + 1, so ``column = columns[s, i] - 1``).

    The walk from tile i stops at the last tile before i, other than the first, whose column is at most ``max(0,
    column - depth)``, else at the first tile; a tile in column 0 draws nothing behind it (the tile itself). The
    last such tile is found by an argmax over the tiles in reverse order, with the first tile always allowed (the
    default): numpy's max along a short last axis costs several times as much.
    """
    length = columns.shape[1]
    last = np.maximum(columns - 1 - depth, 0)
    behind = (columns[:, None, ::-1] <= last[:, :, None]) & _tiles_before(length)
    starts = length - 1 - behind.argmax(axis=2)
    return np.where(columns == 0, np.arange(length), starts)


@cache
def _tiles_before(length: int) -> np.ndarray:
    """[i, r]: tile j = length - 1 - r may end the walk back from tile i (1 <= j < i), or is the first (j = 0)."""
    tiles = np.arange(length)
    j = tiles[::-1]
    return ((j[None, :] >= 1) & (j[None, :] < tiles[:, None])) | (j[None, :] == 0)
