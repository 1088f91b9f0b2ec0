"""Mortar Mayhem's pictures: the arena in blue and red, the frames of freshly spawned agents, the command icons,
the agent sprite sheets and the debug view's target ring."""

from __future__ import annotations

from functools import cache

import numpy as np
import pygame

from envs.drawing import SCREEN, Sprite, SpriteSheet, agent_sprites, surface_to_sprite
from envs.mortar_mayhem.commands import COMMANDS, ICON_ANGLE

TILE = 14
TILE_BLUE, TILE_BLUE_BORDER = (21, 43, 77), (29, 60, 107)
TILE_RED, TILE_RED_BORDER = (81, 18, 26), (112, 24, 36)
RING_GREEN = (0, 255, 0)
ICON_CORNER = 31  # every icon canvas is blitted with its top-left here, whatever its size after rotation
ENDLESS_ARENA = 6
AGENT_SCALE = 0.25


def _tile(fill: tuple[int, int, int], border: tuple[int, int, int]) -> np.ndarray:
    tile = np.empty((TILE, TILE, 3), dtype=np.uint8)
    tile[:] = fill
    tile[0, :] = tile[-1, :] = tile[:, 0] = tile[:, -1] = border  # a 1-px border on the tile's own edge
    return tile


def arena_picture(size: int, lethal_except: tuple[int, int] | None = None) -> np.ndarray:
    """The black screen with the arena centred on it: all tiles blue, or all red but the ``lethal_except`` tile."""
    frame = np.zeros((SCREEN, SCREEN, 3), dtype=np.uint8)
    left = arena_left(size)
    blue = _tile(TILE_BLUE, TILE_BLUE_BORDER)
    tile = blue if lethal_except is None else _tile(TILE_RED, TILE_RED_BORDER)
    frame[left : left + TILE * size, left : left + TILE * size] = np.tile(tile, (size, size, 1))
    if lethal_except is not None:
        x, y = lethal_except
        frame[left + TILE * y : left + TILE * (y + 1), left + TILE * x : left + TILE * (x + 1)] = blue
    return frame


@cache
def backgrounds() -> tuple[np.ndarray, np.ndarray]:
    """Every arena picture, stacked, and the index of each: ``[size, 0, x, y]`` all blue (for any x, y),
    ``[size, 1, x, y]`` all red but tile (x, y). Painting the backgrounds of many slots is then one gather."""
    pictures = []
    index = np.full((ENDLESS_ARENA + 1, 2, ENDLESS_ARENA, ENDLESS_ARENA), -1, dtype=np.int64)
    for size in range(2, ENDLESS_ARENA + 1):
        index[size, 0] = len(pictures)
        pictures.append(arena_picture(size))
        for x in range(size):
            for y in range(size):
                index[size, 1, x, y] = len(pictures)
                pictures.append(arena_picture(size, (x, y)))
    stack = np.stack(pictures)
    stack.setflags(write=False)
    index.setflags(write=False)
    return stack, index


class SpawnFrames:
    """Frames of a freshly spawned agent (facing up) on the all-blue arena, drawn once each and then copied.

    A reset frame depends only on the arena, the spawn pixel and the sprite scale (a few hundred frames for the
    default options), so a batch of resets gathers its frames in one copy instead of pasting sprites. Past
    ``LIMIT`` frames the store starts over, which keeps its memory bounded for any mix of options.
    """

    LIMIT = 1024  # frames kept (about 22 MB)

    def __init__(self) -> None:
        self.index: dict[tuple[int, int, int, float], int] = {}
        self.stack = np.zeros((0, SCREEN, SCREEN, 3), dtype=np.uint8)

    def ids(self, keys: list[tuple[int, int, int, float]]) -> list[int]:
        """Rows of ``stack`` holding the frames of ``keys`` = (background id, x, y, agent scale), drawn if new."""
        index = self.index
        if len(index) + len(keys) > self.LIMIT:
            index.clear()
        found = [index.get(key) for key in keys]
        if None in found:
            found = [self._draw(key) if row is None else row for key, row in zip(keys, found, strict=True)]
        return found

    def _draw(self, key: tuple[int, int, int, float]) -> int:
        row = self.index.get(key)  # a key met twice in one batch is drawn once
        if row is not None:
            return row
        row = self.index[key] = len(self.index)
        if row >= len(self.stack):
            grown = np.zeros((max(2 * len(self.stack), 64), SCREEN, SCREEN, 3), dtype=np.uint8)
            grown[: len(self.stack)] = self.stack
            self.stack = grown
        background, x, y, scale = key
        frame = self.stack[row]
        frame[:] = backgrounds()[0][background]
        agent_sheet(scale).paste_one(frame.reshape(SCREEN, SCREEN * 3), y, x, 0)
        return row


@cache
def spawn_frames() -> SpawnFrames:
    return SpawnFrames()


def arena_left(size: int) -> int:
    """Pixel of the arena's left (and top) edge: the arena is centred on the 84-px screen."""
    return SCREEN // 2 - TILE * size // 2


def _icon_surface(command: int) -> pygame.Surface:
    """The command's icon canvas: white 2-px strokes on a black key, rotated like the reference rotates it."""
    dim = 88 * AGENT_SCALE  # 22 px; coordinates are the design values times the scale, floats as pygame gets them
    width = int(8 * AGENT_SCALE)
    surface = pygame.Surface((dim, dim))
    surface.fill((0, 0, 0))
    white = (255, 255, 255)
    angle = ICON_ANGLE[command]
    if angle is None:  # "stay": a ring with a horizontal bar through it
        radius = dim // 2 - 4 * AGENT_SCALE
        bar_y = dim // 2 - 8 * AGENT_SCALE
        pygame.draw.circle(surface, white, (radius, radius), radius=radius, width=width)
        pygame.draw.line(surface, white, (0, bar_y), (dim - 12 * AGENT_SCALE, bar_y), width=width)
        return surface
    tail, head, mid = 2 * AGENT_SCALE, 80 * AGENT_SCALE, 40 * AGENT_SCALE  # the right-pointing arrow
    pygame.draw.line(surface, white, (tail, mid), (head, mid), width)
    pygame.draw.line(surface, white, (head, mid), (mid, 0), width)
    pygame.draw.line(surface, white, (head, mid), (mid, head), width)
    return pygame.transform.rotate(surface, angle)


@cache
def icon_sheet() -> SpriteSheet:
    """The nine icons on a common canvas anchored at their top-left corner (diagonals are larger after rotation)."""
    surfaces = [_icon_surface(c) for c in range(len(COMMANDS))]
    size = max(max(s.get_size()) for s in surfaces)
    sprites = []
    for surface in surfaces:
        canvas = pygame.Surface((size, size))
        canvas.fill((0, 0, 0))
        canvas.blit(surface, (0, 0))
        sprites.append(surface_to_sprite(canvas, (0, 0, 0)))
    return SpriteSheet(sprites, 0, 0)


@cache
def agent_sheet(scale: float) -> SpriteSheet:
    sprites = agent_sprites(scale)
    return SpriteSheet(sprites, sprites[0].height // 2, sprites[0].width // 2)


@cache
def target_ring() -> tuple[Sprite, int]:
    """The debug view's green ring (radius 7, width 2) around a tile centre, and its offset from that centre."""
    surface = pygame.Surface((2 * TILE + 2, 2 * TILE + 2))
    surface.fill((0, 0, 0))
    pygame.draw.circle(surface, RING_GREEN, (TILE, TILE), TILE / 2, int(8 * AGENT_SCALE))
    return surface_to_sprite(surface, (0, 0, 0)), -TILE
