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

The search never failed on a 7 x 7 grid; if no path exists it raises ``RuntimeError``. :func:`skip_path` makes the
draws of a level without building its path (for levels that are never played, see the endless core).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cache

import numpy as np

from envs.rng import BoundedDraws

Tile = tuple[int, int]

WALL_PERCENT = 33  # an inner tile is a wall when integers(0, 100) < 33
BORDER_WALL_COUNTS = (4, 8)
COST_LOW, COST_HIGH = 1, 9  # step costs: integers(1, 9), i.e. 1..8

_WORD = 1 << 32
WALL_WORDS = -(-WALL_PERCENT * _WORD // 100)  # integers(0, 100) < 33 for exactly the words below this


@cache
def rejected_words(high: int) -> frozenset[int]:
    """The 32-bit words that numpy's ``integers(0, high)`` rejects (a redraw follows): ``word * high mod 2**32``
    below ``2**32 % high``. (For 100: 96 words of the 2**32.)"""
    threshold = _WORD % high
    g = math.gcd(high, _WORD)
    modulus = _WORD // g
    inverse = pow(high // g, -1, modulus)
    return frozenset((r // g * inverse) % modulus + j * modulus for r in range(0, threshold, g) for j in range(g))


_REJECTED_WALL_WORDS = rejected_words(100)
_BITS = tuple(1 << tile for tile in range(64))  # bit of each tile index (grids up to 64 tiles)
_REDRAWN_BELOW = (0, *(_WORD % choices for choices in range(1, 65)))  # integers(0, n) draws again below this


@dataclass(frozen=True)
class MysteryPathLayout:
    """One generated level: the path (origin first, goal last) and the walls (inner ones first, then border ones)."""

    path: tuple[Tile, ...]
    walls: tuple[Tile, ...]


@dataclass(frozen=True)
class _Grid:
    """Tables of a width x height grid; tile (x, y) has the index ``x * height + y``."""

    width: int
    height: int
    neighbours: tuple[tuple[int, ...], ...]  # 4-neighbours: right, left, down, up
    near: tuple[int, ...]  # bit mask of each tile and its 4-neighbours
    surrounding: tuple[int, ...]  # bit mask of the 4-neighbours and diagonal neighbours of each tile
    inner: tuple[int, ...]  # tiles that may become inner walls, in draw order
    border: tuple[int, ...]  # border tiles, column by column
    distance: tuple[tuple[float, ...], ...]  # distance[goal][tile]: straight-line distance between the two
    tiles: tuple[Tile, ...]  # (x, y) of each index
    touching: int  # bit mask of the inner tiles that surround a border tile
    edges: int  # pairs of 4-neighbours: the most words a search can use (see draw_path)
    level_words: int  # the most words a level uses (unless numpy draws again): walls, count, picks, search
    _candidates: dict[tuple[int, int], tuple[int, ...]] = field(default_factory=dict, compare=False, hash=False)
    _free: dict[tuple[int, int, int], tuple[int, ...]] = field(default_factory=dict, compare=False, hash=False)

    def border_candidates(self, start: int, end: int) -> tuple[int, ...]:
        """Border tiles that are neither ``start`` nor ``end`` nor a 4-neighbour of either (kept once computed)."""
        found = self._candidates.get((start, end))
        if found is None:
            excluded = self.near[start] | self.near[end]
            found = self._candidates[start, end] = tuple(t for t in self.border if not (excluded >> t) & 1)
        return found

    def free_border(self, start: int, end: int, wall_bits: int) -> tuple[int, ...]:
        """The :meth:`border_candidates` without an inner wall (``wall_bits``) among their surrounding tiles.

        Kept once computed: only the inner walls in ``touching`` (7 of 16 tiles on a 7x7 grid) decide, so there are
        few distinct answers, and a lookup is cheaper than testing every candidate.
        """
        key = (start, end, wall_bits & self.touching)
        found = self._free.get(key)
        if found is None:
            surrounding = self.surrounding
            candidates = self.border_candidates(start, end)
            found = self._free[key] = tuple(t for t in candidates if not surrounding[t] & wall_bits)
        return found


@cache
def _grid(width: int, height: int) -> _Grid:
    def index(x: int, y: int) -> int:
        return x * height + y

    def inside(x: int, y: int) -> bool:
        return 0 <= x < width and 0 <= y < height

    tiles = tuple((x, y) for x in range(width) for y in range(height))
    neighbours, near, surrounding = [], [], []
    for x, y in tiles:
        four = [index(*t) for t in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)) if inside(*t)]
        diagonal = [index(*t) for t in ((x + 1, y + 1), (x - 1, y - 1), (x + 1, y - 1), (x - 1, y + 1)) if inside(*t)]
        neighbours.append(tuple(four))
        near.append(sum(1 << t for t in [index(x, y), *four]))
        surrounding.append(sum(1 << t for t in four + diagonal))
    inner = tuple(index(x, y) for x in range(1, width - 2) for y in range(1, height - 2))
    border = tuple(index(x, y) for x, y in tiles if x in (0, width - 1) or y in (0, height - 1))
    distance = tuple(tuple(math.sqrt((x - gx) ** 2 + (y - gy) ** 2) for x, y in tiles) for gx, gy in tiles)
    touching = sum(1 << t for t in inner if any(surrounding[b] >> t & 1 for b in border))
    edges = sum(len(four) for four in neighbours) // 2
    level_words = len(inner) + 1 + max(BORDER_WALL_COUNTS) + edges
    return _Grid(
        width,
        height,
        tuple(neighbours),
        tuple(near),
        tuple(surrounding),
        inner,
        border,
        distance,
        tiles,
        touching,
        edges,
        level_words,
    )


def generate_path(rng: np.random.Generator, width: int, height: int, origin: Tile, goal: Tile) -> MysteryPathLayout:
    """Build one Mystery Path level on a ``width`` x ``height`` grid from ``origin`` to ``goal`` (see the module doc).

    ``origin`` and ``goal`` should lie on the border; ``rng`` is advanced exactly as memory-gym 1.0.2 advances it.
    """
    grid = _grid(int(width), int(height))
    draws = BoundedDraws(rng)
    draws.read_ahead((grid.level_words + 1) // 2)  # one read for the whole level
    path, walls = draw_path(draws, width, height, origin, goal)
    draws.close()
    tiles = grid.tiles
    return MysteryPathLayout(path=tuple(tiles[t] for t in path), walls=tuple(tiles[t] for t in walls))


def draw_walls(draws: BoundedDraws, grid: _Grid, start: int, end: int) -> list[int]:
    """Stages 1 and 2 of :func:`draw_path`: the inner walls, then the border walls, in the order they were made.

    The draws are read straight from the words of ``draws``: ``integers(0, n)`` is ``word * n >> 32`` (numpy's
    Lemire method, see :mod:`envs.rng`) unless the word is one that numpy rejects and draws again after; then
    ``draws`` decides. ``integers(0, 100) < 33`` is ``word < WALL_WORDS``.
    """
    # 1. Inner walls (a bit mask, and a list in the order they were made): one draw per tile, read from the words
    # unless one of them would be redrawn (once in millions of levels).
    inner = grid.inner
    words = draws.words
    if draws.used + len(inner) + 9 > len(words):  # the inner walls' words, the count's and the picks'
        draws.read_ahead()
    used = draws.used
    chunk = words[used : used + len(inner)]
    if _REJECTED_WALL_WORDS.isdisjoint(chunk):
        walls = [tile for tile, word in zip(inner, chunk, strict=True) if word < WALL_WORDS]
        used += len(inner)
    else:
        draws.used = used
        drawn = draws.below_many(100, len(inner))
        walls = [tile for tile, draw in zip(inner, drawn, strict=True) if draw < WALL_PERCENT]
        used = draws.used
    wall_bits = sum(map(_BITS.__getitem__, walls))

    # 2. Border walls: 4 or 8 picks among the candidates, while there are any (a single one is taken without a draw).
    candidates = list(grid.free_border(start, end, wall_bits))
    if used + 9 > len(words):
        draws.used = used
        draws.read_ahead()
    count = BORDER_WALL_COUNTS[words[used] * len(BORDER_WALL_COUNTS) >> 32]  # (a range of 2 never redraws)
    used += 1
    left = len(candidates)
    for choices in range(left, left - min(count, left), -1):  # candidates left before each pick
        index = 0
        if choices > 1:
            product = words[used] * choices
            used += 1
            if product & 0xFFFFFFFF < _REDRAWN_BELOW[choices]:  # numpy draws again
                draws.used = used - 1
                index = draws.below(choices)
                used = draws.used
            else:
                index = product >> 32
        walls.append(candidates.pop(index))
    draws.used = used
    return walls


def level_grid(width: int, height: int) -> _Grid:
    """The tables of a ``width`` x ``height`` grid (built once), for :func:`draw_level` and :func:`skip_level`."""
    return _grid(int(width), int(height))


def draw_path(draws: BoundedDraws, width: int, height: int, origin: Tile, goal: Tile) -> tuple[list[int], list[int]]:
    """:func:`generate_path` on tile indices ``x * height + y``: (path origin first, walls), drawn from ``draws``.

    The caller closes ``draws`` (so that it may make draws of its own before and after, from the same words).
    """
    grid = _grid(int(width), int(height))
    start = int(origin[0]) * grid.height + int(origin[1])
    end = int(goal[0]) * grid.height + int(goal[1])
    return draw_level(draws, grid, start, end)


def draw_level(draws: BoundedDraws, grid: _Grid, start: int, end: int) -> tuple[list[int], list[int]]:
    """:func:`draw_path` from tile index ``start`` to tile index ``end`` of ``grid`` (:func:`level_grid`)."""
    n = grid.width * grid.height
    walls = draw_walls(draws, grid, start, end)

    # 3. Randomised best-first search. Tile states: 0 not seen, 1 open, 2 closed or wall. The open list is kept as
    # two parallel lists (tiles and their f) so that the scan for the next tile reads f directly.
    state = [0] * n
    for tile in walls:
        state[tile] = 2
    neighbours, distance = grid.neighbours, grid.distance[end]
    g = [0] * n
    parent = [-1] * n
    open_tiles, open_f = [start], [0.0]
    state[start] = 1
    # The step costs integers(1, 9) are read inline from the 32-bit outputs: for a range of 8 numpy's method is
    # "the top 3 bits" and never redraws.
    assert COST_HIGH - COST_LOW == 8
    # A word is used when an expanded tile examines a neighbour that is not closed; the neighbour, expanded later,
    # finds the tile closed. So a search uses at most one word per pair of neighbours, and reading that many ahead
    # once spares a test per expanded tile.
    if draws.used + grid.edges > len(draws.words):
        draws.read_ahead(max(BoundedDraws.BLOCK, (grid.edges + 1) // 2))
    words, used = draws.words, draws.used
    while open_tiles:
        head, pick = open_f[0], 0
        for value in open_f:  # the first one below the head (never the head itself), else the head
            if value < head:
                pick = open_f.index(value)
                break
        current = open_tiles[pick]
        if current == end:
            break
        del open_tiles[pick], open_f[pick]
        state[current] = 2
        g_current = g[current] + COST_LOW
        for tile in neighbours[current]:
            seen = state[tile]
            if seen == 2:
                continue
            cost = g_current + (words[used] >> 29)
            used += 1
            if seen:
                if cost < g[tile]:
                    parent[tile] = current  # the better cost itself is not kept (f stays as it was)
            else:
                g[tile] = cost
                parent[tile] = current
                state[tile] = 1
                open_tiles.append(tile)
                open_f.append(cost + distance[tile])
    else:
        raise RuntimeError("No valid path found")
    draws.used = used

    # 4. The parent chain, origin first.
    path = [end]
    tile = parent[end]
    while tile >= 0:
        path.append(tile)
        tile = parent[tile]
    path.reverse()
    return path, walls


def skip_path(draws: BoundedDraws, width: int, height: int, origin: Tile, goal: Tile) -> None:
    """The draws of :func:`draw_path`, without its path: the walls, then the search without parents.

    A continued endless generator must be advanced past levels that are never played. Which words the search uses
    does not depend on the parents (a cheaper way to an open tile re-points its parent and nothing else), so their
    bookkeeping is left out: about a tenth of the search. The loop is :func:`draw_path`'s otherwise (tests keep the
    two in step).
    """
    grid = _grid(int(width), int(height))
    start = int(origin[0]) * grid.height + int(origin[1])
    end = int(goal[0]) * grid.height + int(goal[1])
    skip_level(draws, grid, start, end)


def skip_level(draws: BoundedDraws, grid: _Grid, start: int, end: int) -> None:
    """:func:`skip_path` from tile index ``start`` to tile index ``end`` of ``grid`` (:func:`level_grid`)."""
    n = grid.width * grid.height
    state = [0] * n
    for tile in draw_walls(draws, grid, start, end):
        state[tile] = 2
    neighbours, distance = grid.neighbours, grid.distance[end]
    g = [0] * n
    open_tiles, open_f = [start], [0.0]
    state[start] = 1
    if draws.used + grid.edges > len(draws.words):  # as in draw_path
        draws.read_ahead(max(BoundedDraws.BLOCK, (grid.edges + 1) // 2))
    words, used = draws.words, draws.used
    while open_tiles:
        head, pick = open_f[0], 0
        for value in open_f:
            if value < head:
                pick = open_f.index(value)
                break
        current = open_tiles[pick]
        if current == end:
            break
        del open_tiles[pick], open_f[pick]
        state[current] = 2
        g_current = g[current] + COST_LOW
        for tile in neighbours[current]:
            seen = state[tile]
            if seen == 2:
                continue
            if not seen:  # an open tile's word is used and changes nothing else here
                cost = g_current + (words[used] >> 29)
                g[tile] = cost
                state[tile] = 1
                open_tiles.append(tile)
                open_f.append(cost + distance[tile])
            used += 1
    else:
        raise RuntimeError("No valid path found")
    draws.used = used
