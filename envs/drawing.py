"""Drawing shared by every family: sprites rasterised once, then composited with numpy.

Sprites are rasterised with pygame's own primitives (so circles and lines match the reference's rasters pixel for
pixel) exactly once per process, and cached as small ``(rgb, mask)`` pairs. Frames are then plain uint8 arrays in
(row, column, channel) layout, and pasting a sprite is a masked slice assignment.
"""

from __future__ import annotations

import os
from functools import cache

import numpy as np

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
import pygame  # noqa: E402  (the environment variables above must be set first)

SCREEN = 84
BLACK = (0, 0, 0)
KEY_BLUE = (0, 0, 255)

AGENT_BODY = (250, 204, 153)
AGENT_HAND_FILL = (250, 250, 250)
AGENT_HAND = (50, 50, 50)  # the hand outline; its width int(3 * scale) is 0 at scale 0.25, and width 0 means filled


class Sprite:
    """A small picture with a transparency mask, positioned by its top-left corner."""

    __slots__ = ("rgb", "mask", "height", "width")

    def __init__(self, rgb: np.ndarray, mask: np.ndarray) -> None:
        self.rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
        self.mask = np.ascontiguousarray(mask, dtype=bool)
        self.height, self.width = mask.shape

    def paste(self, frame: np.ndarray, top: int, left: int) -> None:
        """Copy the opaque pixels into ``frame`` (H, W, 3) with the sprite's top-left at (top, left), clipped."""
        h, w = frame.shape[:2]
        r0, c0 = max(top, 0), max(left, 0)
        r1, c1 = min(top + self.height, h), min(left + self.width, w)
        if r0 >= r1 or c0 >= c1:
            return
        m = self.mask[r0 - top : r1 - top, c0 - left : c1 - left]
        frame[r0:r1, c0:c1][m] = self.rgb[r0 - top : r1 - top, c0 - left : c1 - left][m]


def surface_to_sprite(surface: pygame.Surface, key: tuple[int, int, int]) -> Sprite:
    """Convert a pygame surface into a :class:`Sprite`; pixels of the colour ``key`` become transparent."""
    rgb = pygame.surfarray.array3d(surface).transpose(1, 0, 2)
    mask = ~np.all(rgb == np.array(key, dtype=np.uint8), axis=-1)
    return Sprite(rgb, mask)


def round_half_away(value: np.ndarray | float) -> np.ndarray:
    """Round like pygame's ``Rect`` assignment: halves away from zero (10.5 -> 11, -3.5 -> -4)."""
    value = np.asarray(value, dtype=np.float64)
    return (np.sign(value) * np.floor(np.abs(value) + 0.5)).astype(np.int64)


def blend(dst: np.ndarray, src: np.ndarray | int, alpha: int) -> np.ndarray:
    """Per-surface alpha blending as SDL does it: ``D + trunc((S - D) * A / 255)`` per channel (A clamped to 255)."""
    a = min(int(alpha), 255)
    d = dst.astype(np.int32)
    return (d + np.trunc((np.asarray(src, dtype=np.int32) - d) * a / 255).astype(np.int32)).astype(np.uint8)


@cache
def disc_mask(radius: int) -> tuple[np.ndarray, int]:
    """Pixels of pygame's filled circle of ``radius`` around an integer centre: (mask, offset of its top-left)."""
    size = 2 * radius + 2
    surface = pygame.Surface((size, size))
    surface.fill(BLACK)
    pygame.draw.circle(surface, (255, 255, 255), (radius, radius), radius)
    mask = pygame.surfarray.array3d(surface)[:, :, 0].T == 255
    mask.setflags(write=False)
    return mask, -radius


@cache
def agent_sprites(scale: float = 0.25) -> tuple[Sprite, ...]:
    """The agent's eight sprites, indexed by ``heading // 45`` (heading 0 = hands up, growing counter-clockwise).

    The body is a disc; the two hands sit on the leading side and are rotated about the canvas centre with the
    heading (pygame's vector rotation, so diagonal hand centres are the same floats as in the reference).
    """
    radius = int(25 * scale)
    hands_dx = int(18 * scale)
    hand_dy = int(12 * scale)
    hand_radius = int(10 * scale)
    hand_outline = int(3 * scale)
    extension = 14
    dim = radius * 2 + hand_radius + extension
    centre = pygame.math.Vector2(dim // 2, dim // 2)
    hands = (
        pygame.math.Vector2(dim // 2 - hands_dx, hand_dy + extension // 2),
        pygame.math.Vector2(dim // 2 + hands_dx, hand_dy + extension // 2),
    )
    sprites = []
    for heading in range(0, 360, 45):
        surface = pygame.Surface((dim, dim))
        surface.fill(KEY_BLUE)
        pygame.draw.circle(surface, AGENT_BODY, centre, radius)
        positions = [(hand - centre).rotate(360 - heading) + centre for hand in hands]
        for pos in positions:
            pygame.draw.circle(surface, AGENT_HAND_FILL, pos, hand_radius)
        for pos in positions:
            pygame.draw.circle(surface, AGENT_HAND, pos, hand_radius, hand_outline)
        sprites.append(surface_to_sprite(surface, KEY_BLUE))
    return tuple(sprites)


def paste_agent(frame: np.ndarray, x: int, y: int, heading: int, scale: float = 0.25) -> None:
    """Draw the agent centred on pixel (x, y) with the sprite of ``heading`` (a multiple of 45 degrees)."""
    sprite = agent_sprites(scale)[(int(heading) % 360) // 45]
    sprite.paste(frame, int(y) - sprite.height // 2, int(x) - sprite.width // 2)
