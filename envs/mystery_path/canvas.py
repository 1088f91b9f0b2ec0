"""The frames of all slots in one padded canvas, into which sprites are scattered without clipping, and the
fall-off cross."""

from __future__ import annotations

from functools import cache

import numpy as np

from envs.drawing import SCREEN, Sprite, SpriteScatter, SpriteSheet, pygame, surface_to_sprite
from envs.mystery_path.level import CROSS_COLOUR, GRID, TILE


@cache
def fall_off_cross() -> Sprite:
    """The red 10x10 cross (two 3-px diagonals) shown where the agent fell off."""
    size, width = int(40 * 0.25), int(12 * 0.25)
    surface = pygame.Surface((size, size))
    surface.fill((0, 0, 0))
    pygame.draw.line(surface, CROSS_COLOUR, (0, 0), (size - 1, size - 1), width)
    pygame.draw.line(surface, CROSS_COLOUR, (size - 1, 0), (0, size - 1), width)
    return surface_to_sprite(surface, (0, 0, 0))


class Canvas:
    """The frames of all slots, with spare rows above and below each so that sprites can be scattered without
    clipping them vertically. Rows are not padded, so that each frame is one contiguous block (copying and filling
    frames is then about twice as fast); the rare sprite with opaque pixels left or right of the screen is pasted
    on its own, clipped."""

    def __init__(self, num_envs: int) -> None:
        self.num_envs = num_envs
        self._columns: dict[int, tuple[int, np.ndarray, np.ndarray]] = {}  # see _opaque_columns
        self._allocate(0)

    def _allocate(self, margin: int) -> None:
        self.margin = margin
        self.buffer = np.zeros((self.num_envs, SCREEN + 2 * margin, SCREEN, 3), dtype=np.uint8)
        self.view = self.buffer[:, margin : margin + SCREEN]
        # The same pixels split into tile bands: (slot, band, row in band, column, channel).
        self.bands = self.view.reshape(self.num_envs, GRID, TILE, SCREEN, 3)
        # The buffer as rows of bytes, for SpriteSheet pastes (one lasting view: a sheet builds its windows once).
        self.rows = self.buffer.reshape(self.num_envs, SCREEN + 2 * margin, SCREEN * 3)
        assert np.shares_memory(self.bands, self.buffer) and np.shares_memory(self.rows, self.buffer)

    def fit(self, sprites: SpriteScatter) -> None:
        """Grow the margin (keeping the frames) until every sprite of ``sprites`` fits into it."""
        if sprites.max_side > self.margin:
            frames = self.view.copy()
            self._allocate(sprites.max_side)
            self.view[:] = frames

    def _opaque_columns(self, sprites: SpriteScatter) -> tuple[np.ndarray, np.ndarray]:
        """First and last opaque column of every sprite of ``sprites`` (kept until sprites are added)."""
        known = self._columns.get(id(sprites))
        if known is None or known[0] != len(sprites.sprites):
            columns = [np.flatnonzero(sprite.mask.any(axis=0)) for sprite in sprites.sprites]
            first = np.array([c[0] for c in columns], dtype=np.int64)
            last = np.array([c[-1] for c in columns], dtype=np.int64)
            known = self._columns[id(sprites)] = (len(sprites.sprites), first, last)
        return known[1], known[2]

    def paste(
        self,
        sprites: SpriteScatter,
        slots: np.ndarray,
        ids: np.ndarray,
        top: np.ndarray,
        left: np.ndarray,
        may_leave_screen: bool = False,
    ) -> None:
        """Paste sprite ``ids[i]`` into slot ``slots[i]`` with its top-left at screen pixel (top[i], left[i]).

        Sprites at least partly on the screen need no vertical clipping (the margin is as high as the largest
        sprite); ``may_leave_screen`` moves sprites that are entirely above or below the screen into the margin.
        """
        first, last = self._opaque_columns(sprites)
        inside = (left + first[ids] >= 0) & (left + last[ids] < SCREEN)
        scattered = top
        if may_leave_screen:
            m = self.margin
            scattered = np.minimum(np.maximum(top, -m), SCREEN + m - sprites.heights[ids])
        if inside.all():
            sprites.paste(self.buffer, slots, ids, scattered + self.margin, left)
            return
        sprites.paste(self.buffer, slots[inside], ids[inside], scattered[inside] + self.margin, left[inside])
        for i in np.flatnonzero(~inside).tolist():  # opaque pixels left or right of the screen: clipped
            sprites.sprites[ids[i]].paste(self.view[slots[i]], int(top[i]), int(left[i]))

    def paste_sheet(
        self,
        sheet: SpriteSheet,
        sprites: SpriteScatter,
        first: int,
        slots: np.ndarray,
        which: np.ndarray,
        top: np.ndarray,
        left: np.ndarray,
        may_leave_screen: bool = False,
    ) -> None:
        """:meth:`paste` of sprites ``first + which[i]`` of ``sprites``, which are also the sprites of ``sheet``
        (anchored at their top-left corner): the same pixels, pasted through the sheet where its window lies within
        the screen's columns.

        The sheet composites whole windows of the frames (two strided copies, an AND and an OR), about two thirds
        of the cost of a pixel scatter for many agents; windows that reach past the left or right edge (an agent
        at the edge) go through :meth:`paste`. ``may_leave_screen`` moves windows that lie entirely above or below
        the screen into the margin (windows that show on the screen stay where they are).
        """
        if may_leave_screen:
            m = self.margin
            top = np.minimum(np.maximum(top + sheet.top, -m), SCREEN + m - sheet.height) - sheet.top
        # unsigned view: a negative column becomes huge, so one comparison tests both edges (rows fit: the margin is
        # as high as the largest sprite, and windows off the screen were moved into it)
        inside = (left + sheet.left).view(np.uint64) <= SCREEN - sheet.width
        if inside.all():
            if len(slots) >= sheet.BATCH_MIN:
                sheet.paste_inside(self.rows, slots, top + self.margin, left, which)
            else:
                sheet.paste(self.rows, slots, top + self.margin, left, which)
            return
        if not inside.any():
            self.paste(sprites, slots, first + which, top, left)
            return
        sheet.paste(self.rows, slots[inside], top[inside] + self.margin, left[inside], which[inside])
        outside = ~inside
        self.paste(sprites, slots[outside], first + which[outside], top[outside], left[outside])
