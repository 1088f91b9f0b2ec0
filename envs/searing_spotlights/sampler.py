"""The spawn-position sampler (agent, coins, exit) and the spotlights' orbit points, drawn like memory-gym 1.0.2
draws them."""

from __future__ import annotations

from functools import cache

import numpy as np

from envs.drawing import pygame
from envs.rng import DirectDraws
from envs.searing_spotlights.pictures import CENTRE, SCREEN, SPOT_ORBIT

AGENT_BLOCK, ITEM_BLOCK = 28, 21  # spawn sampler blocking radii (the endless coin uses 28)
ITEM_LOW, ITEM_HIGH = 7, SCREEN - 7  # coins and the exit are clamped into [7, 77]
SCREEN_CENTRE = pygame.math.Vector2(CENTRE, CENTRE)


@cache
def orbit_points(radius: int) -> tuple[complex, ...]:
    """Points at the angles 0..719 degrees on a spotlight's orbit (pygame's rotation, for the reference's floats).

    Spotlights start, turn and end at angles ``start`` (0..359), ``start + 180 + (-45..44)`` and that plus
    ``-135..134``, all within 0..719. (Python complex numbers: a spotlight record is built from a tuple of them.)
    """
    orbit = pygame.math.Vector2(SPOT_ORBIT + radius, 0)
    points = [SCREEN_CENTRE + orbit.rotate(float(angle)) for angle in range(720)]
    return tuple(complex(point.x, point.y) for point in points)


@cache
def _block_disc(radius: int) -> np.ndarray:
    """Pixels at squared distance < radius^2 from the centre, as a (2r-1, 2r-1) mask."""
    offsets = np.arange(-radius + 1, radius)
    return offsets[:, None] ** 2 + offsets[None, :] ** 2 < radius * radius


def block_position(mask: np.ndarray, x: int, y: int, radius: int) -> None:
    """Mark the pixels within ``radius`` (exclusive) of (x, y) as taken in the (84, 84) [y, x] spawn mask."""
    disc = _block_disc(radius)
    top, left = y - radius + 1, x - radius + 1
    r0, c0 = max(top, 0), max(left, 0)
    r1, c1 = min(top + disc.shape[0], SCREEN), min(left + disc.shape[1], SCREEN)
    if r0 < r1 and c0 < c1:
        mask[r0:r1, c0:c1] |= disc[r0 - top : r1 - top, c0 - left : c1 - left]


def sample_position(
    mask: np.ndarray, rng: np.random.Generator | DirectDraws, radius: int, empty: bool = False
) -> tuple[int, int]:
    """A uniformly drawn free pixel (row-major order of the free ones), which is then blocked with ``radius`` (0:
    not blocked, for the last draw from a mask).

    ``empty`` says that nothing is blocked yet, so the drawn index is the pixel itself.
    """
    if empty:
        cell = int(rng.integers(0, SCREEN * SCREEN))
    else:
        free = (~mask).reshape(-1).nonzero()[0]
        if free.size == 0:
            raise RuntimeError("no free spawn position left: too many coins for the arena (reduce num_coins)")
        cell = int(free[rng.integers(0, free.size)])
    y, x = divmod(cell, SCREEN)
    if radius:
        block_position(mask, x, y, radius)
    return x, y


def clamp_item(value: int) -> int:
    return min(max(value, ITEM_LOW), ITEM_HIGH)
