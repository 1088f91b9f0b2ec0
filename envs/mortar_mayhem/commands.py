"""The command list of Mortar Mayhem (generation order, tile steps, one-hot positions, icon angles) and the random
walk that draws an episode's commands."""

from __future__ import annotations

from functools import cache

import numpy as np

from envs.rng import BoundedDraws

# The fixed command list (generation order), its tile offsets, and where each command sits in the one-hot vector.
COMMANDS = ("right", "down", "left", "up", "stay", "right_down", "right_up", "left_down", "left_up")
COMMAND_DELTAS = ((1, 0), (0, 1), (-1, 0), (0, -1), (0, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))
COMMAND_STEP = np.array(COMMAND_DELTAS, dtype=np.int64)
ONE_HOT_INDEX = (1, 4, 2, 3, 0, 5, 6, 7, 8)
ONE_HOT = np.eye(9, dtype=np.float32)[list(ONE_HOT_INDEX)]  # the 9-entry block of each command in the vector
ICON_ANGLE = (0, 270, 180, 90, None, 315, 45, 225, 135)  # rotation of the right arrow; None = the "stay" sign
MAX_VECTOR_COMMANDS = 20


@cache
def command_walk(size: int, allowed: int, torus: bool = False) -> tuple[tuple[tuple[int, int], ...], ...]:
    """For every tile ``x * size + y``: (command, tile it leads to) for each of the first ``allowed`` commands, in
    list order, that keeps the walk inside the arena (all of them on the endless variant's torus, which wraps)."""
    steps = []
    for x in range(size):
        for y in range(size):
            moves = []
            for c, (dx, dy) in enumerate(COMMAND_DELTAS[:allowed]):
                nx, ny = x + dx, y + dy
                if torus:
                    nx, ny = nx % size, ny % size
                if 0 <= nx < size and 0 <= ny < size:
                    moves.append((c, nx * size + ny))
            steps.append(tuple(moves))
    return tuple(steps)


def walk_commands(draws: BoundedDraws, walk: tuple, tile: int, count: int) -> list[int]:
    """``count`` commands of a walk from ``tile`` (``walk = command_walk(...)``), each drawn as ``rng.choice`` of the
    commands valid there.

    The hot loop of a reset, so Lemire's method runs inline on the drawn words: a product whose low 32 bits are at
    least n is never rejected (almost always, for n <= 9); the first other word ends the fast loop, and the rest of
    the walk goes through ``draws.below``, which decides exactly (and draws another word when numpy would).
    """
    words, used, walked = draws.words, draws.used, []
    for word in words[used : used + count]:  # the words reserved for the walk
        moves = walk[tile]
        n = len(moves)
        product = word * n
        if product & 0xFFFFFFFF < n:
            break
        command, tile = moves[product >> 32]
        walked.append(command)
    draws.used = used + len(walked)
    for _ in range(count - len(walked)):
        moves = walk[tile]
        command, tile = moves[draws.below(len(moves))]
        walked.append(command)
    return walked
