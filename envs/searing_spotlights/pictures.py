"""Screen geometry, colours and the static pictures: floors, the coin, the exit door and the spotlight rings.

Frames are kept as (84, 252) byte rows (one row of RGB pixels per item); :data:`ROW` is such a row as one item.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from envs.drawing import KEY_BLUE, Sprite, pygame, surface_to_sprite

SCREEN = 84
ROW_BYTES = SCREEN * 3
HUD_ROWS = 4  # the top bar; the walkable area starts below it
TILE = 12  # chessboard square (int(50 * 0.25))
CENTRE = SCREEN // 2
SPOT_ORBIT = math.sqrt(SCREEN**2 + SCREEN**2) / 2  # spotlights start and end this far (+ radius) from the centre

WHITE, BLACK = (255, 255, 255), (0, 0, 0)
BLUE, RED, GREEN, YELLOW = (0, 0, 255), (255, 0, 0), (0, 255, 0), (255, 255, 0)
HUD_GREY = (50, 50, 50)
ACTION_COLOURS = ((120, 120, 120), (116, 1, 113), (255, 94, 14))
COIN_FILL, COIN_RIM = (255, 255, 0), (255, 165, 0)
EXIT_CLOSED, EXIT_OPEN = (55, 55, 55), (48, 141, 70)

FLOOR_CHESS, FLOOR_WHITE, FLOOR_BLACK = 0, 1, 2

ROW = np.dtype((np.void, ROW_BYTES))  # one frame row as a single item, for fast row gathers and scatters


def _rows(image: np.ndarray) -> np.ndarray:
    """(84, 84, 3) image -> (84, 252) rows, the layout frames are kept in."""
    return np.ascontiguousarray(image.reshape(image.shape[0], -1))


@cache
def floor_rows(kind: int, hit: bool) -> np.ndarray:
    """The floor as (84, 252) rows: the chessboard (blue squares, red on a hit step), white or black."""
    image = np.zeros((SCREEN, SCREEN, 3), dtype=np.uint8)
    if kind == FLOOR_WHITE:
        image[:] = WHITE
    elif kind == FLOOR_CHESS:
        squares = (np.arange(SCREEN) // TILE)[:, None] + (np.arange(SCREEN) // TILE)[None, :]
        image[:] = RED if hit else BLUE
        image[squares % 2 == 0] = WHITE
    rows = _rows(image)
    rows.setflags(write=False)
    return rows


@cache
def floor_pair(kind: int, red_feedback: bool) -> np.ndarray:
    """The floor of the lit pictures (see ``SearingSpotlightsCore.lit``): blue, then red on hit steps if
    ``red_feedback``."""
    pair = np.stack([floor_rows(kind, False), floor_rows(kind, red_feedback)])
    pair.setflags(write=False)
    return pair


@cache
def coin_sprite(scale: float) -> Sprite:
    """A coin: a yellow disc with an orange rim of width int(2 * scale); width 0 makes pygame fill it orange."""
    radius = int(10 * scale)
    size = 2 * radius + 2
    surface = pygame.Surface((size, size))
    surface.fill(KEY_BLUE)
    pygame.draw.circle(surface, COIN_FILL, (radius, radius), radius)
    pygame.draw.circle(surface, COIN_RIM, (radius, radius), radius, int(2 * scale))
    return surface_to_sprite(surface, KEY_BLUE)  # centred on pixel (radius, radius), one above height // 2


@cache
def exit_sprite(scale: float, is_open: bool) -> Sprite:
    """The exit door: rounded top corners, a 1-px black outline, grey while closed and green once open."""
    surface = pygame.Surface((20 * scale, 20 * scale))
    surface.fill(KEY_BLUE)
    rect = surface.get_rect()
    corners = (int(10 * scale), int(10 * scale), 0, 0)
    pygame.draw.rect(surface, EXIT_OPEN if is_open else EXIT_CLOSED, rect, 0, 0, *corners)
    pygame.draw.rect(surface, BLACK, rect, int(2 * scale), 0, *corners)
    return surface_to_sprite(surface, KEY_BLUE)


@cache
def ring_mask(radius: int) -> np.ndarray:
    """Pixels of pygame's 1-px circle outline of ``radius`` (same frame as :func:`envs.drawing.disc_mask`)."""
    size = 2 * radius + 2
    surface = pygame.Surface((size, size))
    surface.fill(BLACK)
    pygame.draw.circle(surface, WHITE, (radius, radius), radius, 1)
    mask = pygame.surfarray.array3d(surface)[:, :, 0].T == 255
    mask.setflags(write=False)
    return mask
