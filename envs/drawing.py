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

    __slots__ = ("rgb", "mask", "height", "width", "mask3")

    def __init__(self, rgb: np.ndarray, mask: np.ndarray) -> None:
        self.rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
        self.mask = np.ascontiguousarray(mask, dtype=bool)
        self.height, self.width = mask.shape
        # the mask on every channel: a masked copy then runs along whole rows (a broadcast mask makes numpy step
        # through the pixels three bytes at a time)
        self.mask3 = np.repeat(self.mask[:, :, None], 3, axis=2)

    def paste(self, frame: np.ndarray, top: int, left: int, where: np.ndarray | None = None) -> None:
        """Copy the opaque pixels into ``frame`` (..., H, W, 3) with the sprite's top-left at (top, left), clipped.

        Leading axes of ``frame`` get the same paste. ``where`` ((H, W, 3), like one frame) limits the pasted pixels
        to those whose first channel is nonzero (e.g. a 0/255 mask of the spotlight holes).
        """
        h, w = frame.shape[-3], frame.shape[-2]
        r0, c0 = max(top, 0), max(left, 0)
        r1, c1 = min(top + self.height, h), min(left + self.width, w)
        if r0 >= r1 or c0 >= c1:
            return
        part = slice(r0 - top, r1 - top), slice(c0 - left, c1 - left)
        m = self.mask3[part]
        if where is not None:
            m = m & (where[r0:r1, c0:c1, :1] != 0)
        np.copyto(frame[..., r0:r1, c0:c1, :], self.rgb[part], where=m)


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


class SpriteSheet:
    """Same-anchored sprites (e.g. the eight agent headings) cropped to their common bounding box, pasted in batches.

    Frames are given as a ``(num_frames, H, W * 3)`` uint8 view, so a sprite row is one contiguous run of bytes.
    ``paste`` puts sprite ``which[i]`` into frame ``slots[i]`` with the sprite's anchor on pixel (rows[i], cols[i]).
    Many pastes go through one gather/composite/scatter over strided windows; a few, or clipped ones, are looped.

    Compared with :class:`SpriteScatter` (sprites of mixed sizes scattered pixel by pixel into C-contiguous frames,
    off-screen pixels sent to a margin or a spare frame, optionally masked), this needs sprites of one canvas size
    and composites whole windows, which suits many same-size sprites in frames without a margin or spare frame.
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
        # for batches: frame bytes to keep (255 where transparent) and sprite bytes (0 where transparent)
        self.keep = np.where(self.mask, 0, 255).astype(np.uint8)
        self.ink = np.where(self.mask, self.rgb, 0).astype(np.uint8)
        self._windows: dict[tuple, np.ndarray] = {}

    def _window_view(self, frames: np.ndarray) -> np.ndarray:
        """Every (height x width) window of every frame, as a writeable strided view (no copy)."""
        key = (id(frames), frames.shape, frames.strides)  # the cached view keeps `frames` alive, so its id is unique
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

    def paste_one(self, frame: np.ndarray, row: int, col: int, which: int) -> None:
        """Paste sprite ``which`` into one ``(H, W * 3)`` frame with its anchor on pixel (row, col), clipped."""
        top, left = row + self.top, col + self.left
        height, width = frame.shape[0], frame.shape[1] // 3
        if 0 <= top <= height - self.height and 0 <= left <= width - self.width:
            window = frame[top : top + self.height, 3 * left : 3 * (left + self.width)]
            np.copyto(window, self._rgb_list[which], where=self._mask_list[which])
            return
        r0, r1 = max(top, 0), min(top + self.height, height)
        c0, c1 = max(left, 0), min(left + self.width, width)
        if r0 < r1 and c0 < c1:
            sub = (slice(r0 - top, r1 - top), slice(3 * (c0 - left), 3 * (c1 - left)))
            np.copyto(frame[r0:r1, 3 * c0 : 3 * c1], self._rgb_list[which][sub], where=self._mask_list[which][sub])

    def paste_inside(
        self, frames: np.ndarray, slots: np.ndarray, rows: np.ndarray, cols: np.ndarray, which: np.ndarray
    ) -> None:
        """:meth:`paste` of many sprites whose windows the caller knows to lie inside the frames: one windowed
        composite, without the bounds test and the clipped fallback."""
        windows = self._window_view(frames)
        top, left = rows + self.top, cols + self.left
        patch = windows[slots, top, left]
        patch &= self.keep[which]
        patch |= self.ink[which]
        windows[slots, top, left] = patch

    def paste(
        self, frames: np.ndarray, slots: np.ndarray, rows: np.ndarray, cols: np.ndarray, which: np.ndarray
    ) -> None:
        """Paste sprite ``which[i]`` into frame ``slots[i]`` with its anchor on pixel (rows[i], cols[i]), clipped."""
        if len(slots) >= self.BATCH_MIN:
            top, left = rows + self.top, cols + self.left
            height, width = frames.shape[1], frames.shape[2] // 3
            # unsigned views: a negative corner becomes huge, so one comparison per axis tests both bounds
            inside = (top.view(np.uint64) <= height - self.height) & (left.view(np.uint64) <= width - self.width)
            windows = self._window_view(frames)
            if inside.all():
                k, t, c, w = slots, top, left, which
            else:
                k, t, c, w = slots[inside], top[inside], left[inside], which[inside]
            patch = windows[k, t, c]
            patch &= self.keep[w]  # bitwise compositing: half the cost of copyto(where=) on many small windows
            patch |= self.ink[w]
            windows[k, t, c] = patch
            if inside.all():
                return
            outside = ~inside
            slots, rows, cols, which = slots[outside], rows[outside], cols[outside], which[outside]
        for k, row, col, w in zip(slots.tolist(), rows.tolist(), cols.tolist(), which.tolist(), strict=True):
            self.paste_one(frames[k], row, col, w)


PIXEL = np.dtype((np.void, 3))  # one RGB pixel as a single item: a scatter then moves one item per pixel


class SpriteScatter:
    """Sprites of any sizes pasted into many frames with ONE fancy-index scatter (e.g. agents of several scales).

    Each registered sprite is kept as the offsets of its opaque pixels from its top-left corner and their colours,
    padded to a common length per table (padding repeats the first pixel: writing it twice changes nothing).
    ``paste`` turns every (frame, sprite, corner) into pixel indices and writes all colours in one assignment, so
    its cost grows with the opaque pixels pasted, not with Python calls or window areas.

    The scatter cannot clip, so every index must land somewhere harmless. Two ways, chosen per call:

    * ``clip=False``: the caller guarantees that every sprite lies inside its frame, typically by keeping frames
      with a margin at least :attr:`max_side` wide around the visible picture (no per-pixel test: fastest);
    * ``clip=True``: the last frame of ``frames`` is a spare; pixels off their frame, or outside ``where``, are
      written there instead.

    Compared with :class:`SpriteSheet` (sprites of ONE canvas size, composited through strided windows of frames
    of any layout, clipped pastes looped one by one), this takes mixed sizes, needs C-contiguous frames, handles
    off-screen pixels without a Python loop and can mask the paste. Use :meth:`Sprite.paste` for a single sprite.
    """

    def __init__(self) -> None:
        self.sprites: list[Sprite] = []
        self.heights = np.zeros(0, dtype=np.int64)
        self.widths = np.zeros(0, dtype=np.int64)
        self.max_side = 0
        self._dy = self._dx = np.zeros((0, 0), dtype=np.int64)  # opaque pixels' offsets from the top-left
        self._colours = np.zeros((0, 0), dtype=PIXEL)  # the same pixels' colours, one item each
        self._bytes = np.zeros((0, 0), dtype=np.uint8)  # and as bytes
        self._byte_offsets = np.zeros((0, 0), dtype=np.int64)  # their bytes' offsets in frames `_width` px wide
        self._width = -1

    def add(self, sprites: tuple[Sprite, ...] | list[Sprite]) -> int:
        """Register ``sprites`` (consecutive ids) and return the id of the first; an already known run is reused."""
        for i in range(len(self.sprites) - len(sprites) + 1):
            if all(a is b for a, b in zip(self.sprites[i : i + len(sprites)], sprites, strict=False)):
                return i
        self.sprites.extend(sprites)
        self.heights = np.array([s.height for s in self.sprites], dtype=np.int64)
        self.widths = np.array([s.width for s in self.sprites], dtype=np.int64)
        self.max_side = int(max(self.heights.max(), self.widths.max()))
        pixels = [np.argwhere(s.mask) for s in self.sprites]
        count = max(len(p) for p in pixels)
        pixels = [np.concatenate([p, np.repeat(p[:1], count - len(p), axis=0)]) for p in pixels]
        self._dy = np.stack([p[:, 0] for p in pixels])
        self._dx = np.stack([p[:, 1] for p in pixels])
        colours = np.stack([s.rgb[p[:, 0], p[:, 1]] for s, p in zip(self.sprites, pixels, strict=True)])
        self._bytes = colours.reshape(len(colours), -1)
        self._colours = np.ascontiguousarray(colours).view(PIXEL)[..., 0]
        self._width = -1
        return len(self.sprites) - len(sprites)

    def paste(
        self,
        frames: np.ndarray,
        slots: np.ndarray,
        ids: np.ndarray,
        top: np.ndarray,
        left: np.ndarray,
        clip: bool = False,
        where: np.ndarray | None = None,
    ) -> None:
        """Paste sprite ``ids[i]`` into frame ``slots[i]`` of ``frames`` with its top-left at (top[i], left[i]).

        ``frames`` is a C-contiguous (N, H, W, 3) uint8 array. With ``clip`` its last frame is the spare (see the
        class), and ``where`` (frames' layout, at least the frames pasted into) limits the pixels to those whose
        first channel is nonzero.
        """
        if not frames.flags.c_contiguous:  # a flat reshape would silently copy, and the pastes would be lost
            raise ValueError("SpriteScatter.paste needs C-contiguous frames")
        num, height, width = frames.shape[:3]
        if not clip:  # byte by byte: measured a little faster than pixel items when no index is redirected
            if width != self._width:
                offsets = (self._dy * width + self._dx) * 3
                self._byte_offsets, self._width = (offsets[:, :, None] + np.arange(3)).reshape(len(offsets), -1), width
            base = ((slots * height + top) * width + left) * 3
            frames.reshape(-1)[base[:, None] + self._byte_offsets[ids]] = self._bytes[ids]
            return
        flat = frames.view(PIXEL).reshape(-1)
        py = top[:, None] + self._dy[ids]
        px = left[:, None] + self._dx[ids]
        pixel = (slots[:, None] * height + py) * width + px
        # unsigned views: a negative coordinate becomes huge, so one comparison per axis tests both bounds
        valid = (px.view(np.uint64) < width) & (py.view(np.uint64) < height)
        if where is not None:
            valid &= np.take(where.reshape(-1), 3 * pixel, mode="clip") != 0
        flat[np.where(valid, pixel, (num - 1) * height * width)] = self._colours[ids]
