"""Spotlight holes as row spans: tables that give, per radius and centre, the span of every row of pygame's filled
disc, and the 0/255 rows of those spans (see the package docstring for how a frame is drawn from them)."""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from envs.drawing import disc_mask
from envs.searing_spotlights.pictures import CENTRE, HUD_ROWS, ROW_BYTES, SCREEN, SPOT_ORBIT


def span_code(lo: np.ndarray | int, hi: np.ndarray | int) -> np.ndarray | int:
    """Index of the span [lo, hi] (0 <= lo <= hi <= 83) in :func:`span_rows`; 0 is the empty span."""
    return lo * (2 * SCREEN - 1 - lo) // 2 + hi + 1


@cache
def span_rows() -> np.ndarray:
    """One 0/255 row of 252 bytes per span code: 255 on the three channels of the pixels lo..hi."""
    lo, hi = np.triu_indices(SCREEN)
    codes = span_code(lo, hi)
    table = np.zeros((int(codes.max()) + 1, ROW_BYTES), dtype=np.uint8)
    column = np.arange(ROW_BYTES) // 3
    table[codes] = np.where((column >= lo[:, None]) & (column <= hi[:, None]), 255, 0)
    table.setflags(write=False)
    return table


class HoleTables:
    """Per radius r and integer centre coordinate c, the rows of pygame's filled disc as flat table rows.

    Row ``r * width + c - low`` of ``codes`` holds, for each disc row j (of 2 * max_radius), the code of that row's
    span for a centre column c (0 when the row is empty or off-screen); the same row of ``rows`` holds the screen row
    for a centre row c (0 when it is under the HUD or off-screen, row 0 is never a hole). Spotlight centres stay
    within ``SPOT_ORBIT + radius`` of the screen centre, so ``[low, low + width)`` covers every reachable one.

    Codes index ``span_rows``, the 0/255 rows of only the spans that discs up to ``max_radius`` can make (950 of
    the 3571 spans for radius 13: a 234 KB table, read at random rows every step, stays in the cache).
    """

    def __init__(self, max_radius: int) -> None:
        reach = math.ceil(SPOT_ORBIT + max_radius) + 1
        self.max_radius = max_radius
        self.low = CENTRE - reach
        self.width = 2 * reach + 1
        centres = np.arange(self.low, self.low + self.width)
        depth = 2 * max_radius
        # (int16: small tables and small gathered copies stay in the cache; a code is below 2**12, a row below 84)
        self.codes = np.zeros(((max_radius + 1) * self.width, depth), dtype=np.int16)
        self.rows = np.zeros(((max_radius + 1) * self.width, depth), dtype=np.int16)
        for radius in range(1, max_radius + 1):
            mask, offset = disc_mask(radius)
            block = slice(radius * self.width, (radius + 1) * self.width)
            for j in range(2 * radius):
                filled = np.flatnonzero(mask[j])
                lo, hi = centres + filled[0] + offset, centres + filled[-1] + offset
                visible = (hi >= 0) & (lo < SCREEN)
                code = span_code(np.clip(lo, 0, SCREEN - 1), np.clip(hi, 0, SCREEN - 1))
                self.codes[block, j] = np.where(visible, code, 0)
                row = centres + j + offset
                self.rows[block, j] = np.where((row >= HUD_ROWS) & (row < SCREEN), row, 0)
        used = np.unique(self.codes)  # (0, the empty span, first)
        self.codes = np.searchsorted(used, self.codes).astype(np.int16)
        self.span_rows = span_rows()[used]
        self.span_words = self.span_rows.view(np.uint32)  # 63 words per row, for OR-ing
        # 0/1 per entry: whether the span, the row is visible (multiplying by these is cheaper than comparisons)
        self.codes_visible = np.minimum(self.codes, 1)
        self.rows_visible = np.minimum(self.rows, 1)
        # whether a table row has any visible span (a disc partly on the screen horizontally) or row (vertically)
        self.columns_seen = self.codes.any(axis=1)
        self.rows_seen = self.rows.any(axis=1)
        for table in (self.codes, self.rows, self.codes_visible, self.rows_visible, self.columns_seen, self.rows_seen):
            table.setflags(write=False)
        self.span_rows.setflags(write=False)

    def base(self, radius: np.ndarray | int) -> np.ndarray | int:
        """Offset that turns a spotlight's integer centre coordinate into its table row."""
        return radius * self.width - self.low


@cache
def hole_tables(max_radius: int) -> HoleTables:
    return HoleTables(max_radius)
