"""Agent locomotion shared by the families, vectorised over slots.

Continuous ("free-moving") control takes MultiDiscrete([3, 3]) actions: ``action[0]`` horizontal (0 none, 1 left,
2 right), ``action[1]`` vertical (0 none, 1 up, 2 down). Grid control takes Discrete(4): 0 no-op, 1 turn left,
2 turn right, 3 forward. Headings are degrees, 0 = up, growing counter-clockwise on screen (90 = left).
"""

from __future__ import annotations

import numpy as np

# Direction (dx, dy) and resulting heading for every (horizontal, vertical) action pair; heading -1 = unchanged.
_DX = np.array([0, -1, 1], dtype=np.float64)
_DY = np.array([0, -1, 1], dtype=np.float64)
_HEADING = np.array(
    [
        [-1, 0, 180],  # horizontal none: vertical none / up / down
        [90, 45, 135],  # left
        [270, 315, 225],  # right
    ],
    dtype=np.int64,
)


def continuous_velocity(actions: np.ndarray, speed: np.ndarray, truncate: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Velocity (vx, vy) of each slot: the normalised direction times ``speed``, cut to ints when ``truncate``."""
    actions = np.asarray(actions, dtype=np.int64).reshape(-1, 2)
    dx, dy = _DX[actions[:, 0]], _DY[actions[:, 1]]
    norm = np.sqrt(dx * dx + dy * dy)
    norm[norm == 0] = 1.0
    vx, vy = dx / norm * speed, dy / norm * speed
    if truncate:
        vx, vy = np.trunc(vx), np.trunc(vy)
    return vx, vy


def continuous_heading(actions: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """New heading of each slot: set by any non-zero action component, diagonal when both are; else unchanged."""
    actions = np.asarray(actions, dtype=np.int64).reshape(-1, 2)
    new = _HEADING[actions[:, 0], actions[:, 1]]
    return np.where(new < 0, heading, new)


def clamp_centre(x: np.ndarray, low: np.ndarray | int, high: np.ndarray | int) -> np.ndarray:
    """Keep a centre coordinate within [low, high]; the upper bound is applied first, as in the reference."""
    x = np.where(x > high, high, x)
    return np.where(x < low, low, x)


# Grid control: heading -> forward step in cells.
_GRID_STEP = {0: (0, -1), 90: (-1, 0), 180: (0, 1), 270: (1, 0)}
GRID_DX = np.array([_GRID_STEP[h][0] for h in (0, 90, 180, 270)], dtype=np.int64)
GRID_DY = np.array([_GRID_STEP[h][1] for h in (0, 90, 180, 270)], dtype=np.int64)


def grid_step(
    actions: np.ndarray, cx: np.ndarray, cy: np.ndarray, heading: np.ndarray, size: np.ndarray | int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Apply grid actions: turn left (+90), turn right (-90) or move one cell forward unless it leaves the grid."""
    actions = np.asarray(actions, dtype=np.int64).reshape(-1)
    heading = np.where(actions == 1, (heading + 90) % 360, heading)
    heading = np.where(actions == 2, (heading - 90) % 360, heading)
    forward = actions == 3
    nx = cx + np.where(forward, GRID_DX[heading // 90], 0)
    ny = cy + np.where(forward, GRID_DY[heading // 90], 0)
    inside = (nx >= 0) & (nx < size) & (ny >= 0) & (ny < size)
    return np.where(inside, nx, cx), np.where(inside, ny, cy), heading
