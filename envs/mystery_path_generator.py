"""How Mystery Path levels are made: walls at random, then a randomised best-first search from origin to goal.

The level is a ``width`` x ``height`` grid of tiles (7 x 7 in every Mystery Path environment). The origin and the
goal lie on opposite borders. :func:`generate_path` builds one level in four stages, drawing every random number from
the generator it is given, in a fixed order (so a seed always gives the same level, tile for tile, as memory-gym):

1. **Inner walls.** Each tile with ``1 <= x <= width - 3`` and ``1 <= y <= height - 3`` (visited column by column,
   top to bottom) becomes a wall with probability 33/100 (one ``integers(0, 100)`` draw each). The bounds are
   lopsided (the original loop stops one column and one row early), so column ``width - 2`` and row ``height - 2``
   never hold a wall.
2. **Border walls.** The candidates are the border tiles (column by column) that are neither the origin nor the goal,
   not a 4-neighbour of either, and have no inner wall among their eight surrounding tiles. Then ``4`` or ``8`` of
   them (one coin flip) are picked uniformly one after another, without replacement, and become walls. Border walls
   placed in this stage do not exclude each other, so two may touch.
3. **Search.** A best-first search from the origin whose step costs are random (uniform 1..8, drawn afresh every
   time a neighbour is examined). Each examined tile gets ``f = g + h`` with ``h`` the straight-line distance to the
   goal. Three details make it a *random path maker* rather than a shortest-path search, and they shape the levels:

   * the next tile taken from the open list is the **first** one whose ``f`` is smaller than the ``f`` of the list's
     head (or the head itself when there is none), not the minimum;
   * a cheaper way to a tile that is already open re-points its parent but keeps its old ``g``;
   * a cost is drawn for every examined neighbour that is not closed and not a wall, also for open ones.

   Neighbours are examined in the order right, left, down, up. The search stops when the goal is taken from the list.
4. **Path.** The path is the parent chain from the goal back to the origin, returned origin first. Every tile of it
   is a 4-neighbour of the next one. Over 2000 levels its length (origin and goal included) was 7 to 15 tiles,
   10 on average, and it may double back on itself.

The search never failed on a 7 x 7 grid; if no path exists it raises ``RuntimeError``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np

Tile = tuple[int, int]

WALL_PERCENT = 33  # an inner tile is a wall when integers(0, 100) < 33
BORDER_WALL_COUNTS = (4, 8)
COST_LOW, COST_HIGH = 1, 9  # step costs: integers(1, 9), i.e. 1..8
_COST_BLOCK = 64  # step costs are drawn in blocks (same stream as one draw at a time), unused ones given back


@dataclass(frozen=True)
class MysteryPathLayout:
    """One generated level: the path (origin first, goal last) and the walls (inner ones first, then border ones)."""

    path: tuple[Tile, ...]
    walls: tuple[Tile, ...]


@dataclass(frozen=True)
class _Grid:
    """Neighbour tables of a width x height grid; tile (x, y) has the index ``x * height + y``."""

    width: int
    height: int
    neighbours: tuple[tuple[int, ...], ...]  # 4-neighbours: right, left, down, up
    surrounding: tuple[tuple[int, ...], ...]  # 4-neighbours and diagonal neighbours
    inner: tuple[int, ...]  # tiles that may become inner walls, in draw order
    border: tuple[int, ...]  # border tiles, column by column


@cache
def _grid(width: int, height: int) -> _Grid:
    def index(x: int, y: int) -> int:
        return x * height + y

    def inside(x: int, y: int) -> bool:
        return 0 <= x < width and 0 <= y < height

    neighbours, surrounding = [], []
    for x in range(width):
        for y in range(height):
            four = [(x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)]
            diagonal = [(x + 1, y + 1), (x - 1, y - 1), (x + 1, y - 1), (x - 1, y + 1)]
            neighbours.append(tuple(index(*t) for t in four if inside(*t)))
            surrounding.append(tuple(index(*t) for t in four + diagonal if inside(*t)))
    inner = tuple(index(x, y) for x in range(1, width - 2) for y in range(1, height - 2))
    border = tuple(
        index(x, y) for x in range(width) for y in range(height) if x in (0, width - 1) or y in (0, height - 1)
    )
    return _Grid(width, height, tuple(neighbours), tuple(surrounding), inner, border)


def generate_path(rng: np.random.Generator, width: int, height: int, origin: Tile, goal: Tile) -> MysteryPathLayout:
    """Build one Mystery Path level on a ``width`` x ``height`` grid from ``origin`` to ``goal`` (see the module doc).

    ``origin`` and ``goal`` should lie on the border; ``rng`` is advanced exactly as memory-gym 1.0.2 advances it.
    """
    grid = _grid(int(width), int(height))
    h = grid.height
    start = int(origin[0]) * h + int(origin[1])
    end = int(goal[0]) * h + int(goal[1])
    n = grid.width * h

    # 1. Inner walls.
    wall = [False] * n
    walls: list[int] = []
    if grid.inner:
        for tile, draw in zip(grid.inner, rng.integers(0, 100, size=len(grid.inner)).tolist(), strict=True):
            if draw < WALL_PERCENT:
                wall[tile] = True
                walls.append(tile)

    # 2. Border walls.
    near_ends = {start, end, *grid.neighbours[start], *grid.neighbours[end]}
    candidates = [
        tile
        for tile in grid.border
        if tile not in near_ends and not any(wall[other] for other in grid.surrounding[tile])
    ]
    for _ in range(BORDER_WALL_COUNTS[int(rng.integers(0, len(BORDER_WALL_COUNTS)))]):
        if candidates:
            tile = candidates.pop(int(rng.integers(0, len(candidates))))
            wall[tile] = True
            walls.append(tile)

    # 3. Randomised best-first search.
    gx, gy = divmod(end, h)
    g = [0] * n
    f = [0.0] * n
    parent = [-1] * n
    is_open = [False] * n
    closed = [False] * n
    open_list = [start]
    is_open[start] = True
    # Drawing the costs in blocks gives the same values as drawing them one by one (the generator buffers 32-bit
    # halves in its own state); the state is rewound at the end so that exactly the used draws are consumed.
    state = rng.bit_generator.state
    costs: list[int] = []
    used = 0
    while True:
        if not open_list:
            raise RuntimeError("No valid path found")
        head = f[open_list[0]]
        pick = 0
        for i, tile in enumerate(open_list):
            if f[tile] < head:
                pick = i
                break
        current = open_list[pick]
        if current == end:
            break
        del open_list[pick]
        is_open[current] = False
        closed[current] = True
        g_current = g[current]
        for tile in grid.neighbours[current]:
            if closed[tile] or wall[tile]:
                continue
            if used == len(costs):
                costs += rng.integers(COST_LOW, COST_HIGH, size=_COST_BLOCK).tolist()
            cost = g_current + costs[used]
            used += 1
            if is_open[tile]:
                if cost < g[tile]:
                    parent[tile] = current  # the better cost itself is not kept (f stays as it was)
            else:
                g[tile] = cost
                tx, ty = divmod(tile, h)
                f[tile] = cost + math.sqrt((tx - gx) ** 2 + (ty - gy) ** 2)
                parent[tile] = current
                is_open[tile] = True
                open_list.append(tile)
    rng.bit_generator.state = state
    if used:
        rng.integers(COST_LOW, COST_HIGH, size=used)

    # 4. The parent chain, origin first.
    chain = [end]
    while parent[chain[-1]] >= 0:
        chain.append(parent[chain[-1]])
    chain.reverse()
    return MysteryPathLayout(
        path=tuple(divmod(tile, h) for tile in chain),
        walls=tuple(divmod(tile, h) for tile in walls),
    )
