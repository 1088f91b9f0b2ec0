"""Frame drawing rules: SDL's blends of the darkness and the rings, the HUD rows, the draw order of visible entities,
the darkness alpha of every step, and sprites pasted into frame rows."""

from __future__ import annotations

from functools import cache

import numpy as np

from envs.drawing import Sprite
from envs.searing_spotlights.pictures import (
    ACTION_COLOURS,
    BLACK,
    GREEN,
    HUD_GREY,
    RED,
    ROW_BYTES,
    SCREEN,
    YELLOW,
)


# ---------------------------------------------------------------------------------------------- blending
def darken(rows: np.ndarray, alpha: np.ndarray | int) -> np.ndarray:
    """SDL's blend of a black overlay with per-surface ``alpha``: ``D - floor(D * A / 255)`` (exact, uint16).

    Every pass has one dtype: numpy's mixed-dtype loops are buffered and several times slower.
    """
    product = rows.astype(np.uint16)
    product *= np.asarray(alpha, np.uint16)
    product //= 255  # (numpy divides by a constant without a division per element)
    share = product.astype(np.uint8)
    return np.subtract(rows, share, out=share)


def lighten(rows: np.ndarray, alpha: int) -> np.ndarray:
    """SDL's blend of a white overlay (the spotlight rings): ``D + floor((255 - D) * A / 255)``."""
    return 255 - darken(255 - rows, np.asarray(alpha))


# ---------------------------------------------------------------------------------------------- HUD rows
def paint_hud_row(
    endless: bool, show_action: bool, show_reward: bool, action: tuple[int, int], reward_state: int, red: int
) -> np.ndarray:
    """One row of the 4-row top bar, painted in the reference's order (all four rows are equal).

    ``action`` is the previous action, ``reward_state`` 0 before the first step, then 1 (previous reward not
    positive) or 2 (positive), ``red`` the width of the red (lost health) part.
    """
    row = np.zeros((SCREEN, 3), dtype=np.uint8)
    row[:] = BLACK if endless else HUD_GREY
    row[: SCREEN // 2] = GREEN
    if show_action:
        row[42:63] = ACTION_COLOURS[action[0]]
        row[63:84] = ACTION_COLOURS[action[1]]
    if red > 0:
        row[:red] = RED
    if show_reward and reward_state:
        block = slice(57, 67) if show_action else slice(42, 84)
        row[block] = YELLOW if reward_state == 2 else HUD_GREY
    return row.reshape(-1)


@cache
def reset_hud_row(endless: bool, show_action: bool, show_reward: bool) -> np.ndarray:
    """The HUD row of a reset frame: full health, grey no-op action blocks, no reward block yet."""
    return paint_hud_row(endless, show_action, show_reward, (0, 0), 0, 0)


@cache
def hud_tables() -> tuple[np.ndarray, np.ndarray]:
    """Left halves by red width (0..42) and right halves by ``flags * 27 + a0 * 9 + a1 * 3 + reward_state``."""
    half = ROW_BYTES // 2
    left = np.stack([paint_hud_row(False, False, False, (0, 0), 0, red)[:half] for red in range(SCREEN // 2 + 1)])
    right = []
    for flags in range(8):
        endless, show_action, show_reward = bool(flags & 4), bool(flags & 2), bool(flags & 1)
        for code in range(27):
            action, reward_state = (code // 9, code // 3 % 3), code % 3
            right.append(paint_hud_row(endless, show_action, show_reward, action, reward_state, 0)[half:])
    return left, np.stack(right)


# ------------------------------------------------------------------------------------------ draw order
def draw_order(entities: list[tuple[str, int, bool]]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Which visible entities go above the darkness, and which (a quirk) above the HUD, in drawing order.

    The reference builds its list ``[floor, darkness, hud]`` and inserts each entity (coins, exit, agent in this
    order) at the darkness position if it is hidden (shifting the darkness back), else at ``darkness + offset``
    with a fixed offset per entity (coins 1, exit 2, agent 3), so some visible entities end up after the HUD.
    Hidden entities are always drawn under the darkness in the order coins, exit, agent.
    """
    layers = ["floor", "darkness", "hud"]
    darkness = 1
    for name, offset, visible in entities:
        if visible:
            layers.insert(darkness + offset, name)
        else:
            layers.insert(darkness, name)
            darkness += 1
    hud = layers.index("hud")
    return tuple(layers[darkness + 1 : hud]), tuple(layers[hud + 1 :])


def paste_centred(sprite: Sprite, rows: np.ndarray, x: int, y: int, centre: int | None = None) -> None:
    """Paste ``sprite`` with its centre pixel on (x, y) into (..., 84, 252) rows, clipped.

    The centre is (height // 2, width // 2), or (centre, centre) when given (the coin's canvas is one px larger).
    """
    frames = rows.reshape(*rows.shape[:-1], SCREEN, 3)
    top, left = (sprite.height // 2, sprite.width // 2) if centre is None else (centre, centre)
    sprite.paste(frames, int(y) - top, int(x) - left)


ALPHA_STEPS = 258  # the darkness alpha is constant after at most 256 increments


def alpha_schedule(duration: int, threshold: int) -> np.ndarray:
    """The darkness alpha at steps 0, 1, ...: the reference's dimming rule, run until it is constant."""
    alpha = 0 if duration > 0 else threshold
    schedule = [alpha]
    for _ in range(ALPHA_STEPS - 1):
        if alpha <= threshold:  # SDL clamps the per-surface alpha to 255
            alpha = min(alpha + int(255 / duration), 255) if duration > 0 else min(threshold, 255)
        schedule.append(alpha)
    return np.array(schedule, np.int16)
