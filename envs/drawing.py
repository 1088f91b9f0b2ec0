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
AGENT_HAND = (50, 50, 50)  # the outline; at scale < 1/3 its width truncates to 0 and it fills the whole hand


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
    hand_outline = int(3 * scale)  # 0 means "filled" to pygame
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
        for hand in hands:
            pos = (hand - centre).rotate(360 - heading) + centre
            pygame.draw.circle(surface, AGENT_HAND_FILL, pos, hand_radius)
        for hand in hands:
            pos = (hand - centre).rotate(360 - heading) + centre
            pygame.draw.circle(surface, AGENT_HAND, pos, hand_radius, hand_outline)
        sprites.append(surface_to_sprite(surface, KEY_BLUE))
    return tuple(sprites)


def paste_agent(frame: np.ndarray, x: int, y: int, heading: int, scale: float = 0.25) -> None:
    """Draw the agent centred on pixel (x, y) with the sprite of ``heading`` (a multiple of 45 degrees)."""
    sprite = agent_sprites(scale)[(int(heading) % 360) // 45]
    sprite.paste(frame, int(y) - sprite.height // 2, int(x) - sprite.width // 2)


class SpriteSheet:
    """Same-anchored sprites (e.g. the eight agent headings) cropped to their common bounding box, pasted in batches.

    Frames are given as a ``(num_frames, H, W * 3)`` uint8 view, so a sprite row is one contiguous run of bytes.
    ``paste`` puts sprite ``which[i]`` into frame ``slots[i]`` with the sprite's anchor on pixel (rows[i], cols[i]).
    Many pastes go through one gather/composite/scatter over strided windows; a few, or clipped ones, are looped.
    """

    BATCH_MIN = 6  # below this many sprites a Python loop of slice pastes is faster than the windowed gather

    def __init__(self, sprites: tuple[Sprite, ...] | list[Sprite], anchor_row: int, anchor_col: int) -> None:
        union = np.zeros_like(sprites[0].mask)
        for sprite in sprites:
            if sprite.mask.shape != union.shape:
                raise ValueError("all sprites of a sheet must have the same canvas size")
            union |= sprite.mask
        rows, cols = np.flatnonzero(union.any(axis=1)), np.flatnonzero(union.any(axis=0))
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        self.height, self.width = int(r1 - r0), int(c1 - c0)
        self.top, self.left = int(r0 - anchor_row), int(c0 - anchor_col)  # window corner relative to the anchor
        self.rgb = np.stack([s.rgb[r0:r1, c0:c1].reshape(self.height, -1) for s in sprites])
        self.mask = np.stack([np.repeat(s.mask[r0:r1, c0:c1], 3, axis=1) for s in sprites])
        self._rgb_list, self._mask_list = list(self.rgb), list(self.mask)
        self._windows: dict[tuple, np.ndarray] = {}

    def _window_view(self, frames: np.ndarray) -> np.ndarray:
        """Every (height x width) window of every frame, as a writeable strided view (no copy)."""
        key = (frames.__array_interface__["data"][0], frames.shape, frames.strides)
        view = self._windows.get(key)
        if view is None:
            n, h, w3 = frames.shape
            shape = (n, h - self.height + 1, (w3 - 3 * self.width) // 3 + 1, self.height, 3 * self.width)
            strides = (
                frames.strides[0],
                frames.strides[1],
                3 * frames.strides[2],
                frames.strides[1],
                frames.strides[2],
            )
            view = np.lib.stride_tricks.as_strided(frames, shape, strides, writeable=True)
            if len(self._windows) >= 4:  # the views keep their frame buffers alive: keep only a few
                self._windows.clear()
            self._windows[key] = view
        return view

    def paste(
        self, frames: np.ndarray, slots: np.ndarray, rows: np.ndarray, cols: np.ndarray, which: np.ndarray
    ) -> None:
        top, left = rows + self.top, cols + self.left
        height, width = frames.shape[1], frames.shape[2] // 3
        inside = (top >= 0) & (left >= 0) & (top <= height - self.height) & (left <= width - self.width)
        if inside.sum() >= self.BATCH_MIN:
            windows = self._window_view(frames)
            k, t, c, w = slots[inside], top[inside], left[inside], which[inside]
            patch = windows[k, t, c]
            np.copyto(patch, self.rgb[w], where=self.mask[w])
            windows[k, t, c] = patch
            if inside.all():
                return
            outside = ~inside
            slots, top, left, which = slots[outside], top[outside], left[outside], which[outside]
        h3 = 3 * self.width
        for k, t, c, w in zip(slots.tolist(), top.tolist(), left.tolist(), which.tolist(), strict=True):
            if 0 <= t <= height - self.height and 0 <= c <= width - self.width:
                np.copyto(
                    frames[k, t : t + self.height, 3 * c : 3 * c + h3], self._rgb_list[w], where=self._mask_list[w]
                )
                continue
            r0, r1 = max(t, 0), min(t + self.height, height)
            c0, c1 = max(c, 0), min(c + self.width, width)
            if r0 >= r1 or c0 >= c1:
                continue
            sub = (slice(r0 - t, r1 - t), slice(3 * (c0 - c), 3 * (c1 - c)))
            np.copyto(frames[k, r0:r1, 3 * c0 : 3 * c1], self._rgb_list[w][sub], where=self._mask_list[w][sub])
