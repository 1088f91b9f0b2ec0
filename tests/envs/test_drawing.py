"""SpriteScatter (envs/drawing.py) against a naive reference: one clipped Sprite.paste per slot."""

import numpy as np
import pytest

from envs.drawing import Sprite, SpriteScatter, agent_sprites

H, W = 20, 24  # a small non-square frame, so rows and columns cannot be mixed up


def random_sprites(rng: np.random.Generator) -> tuple[Sprite, ...]:
    """Sprites of different sizes with scattered transparent pixels (and one opaque pixel at least)."""
    sprites = []
    for height, width in ((3, 5), (7, 4), (1, 1), (6, 6)):
        mask = rng.random((height, width)) < 0.6
        mask[0, 0] = True
        sprites.append(Sprite(rng.integers(1, 256, (height, width, 3), dtype=np.uint8), mask))
    return tuple(sprites)


def naive(frames: np.ndarray, sprites, slots, ids, top, left, where=None) -> np.ndarray:
    out = frames.copy()
    for k, i, t, c in zip(slots, ids, top, left, strict=True):
        sprites[i].paste(out[k], int(t), int(c), None if where is None else where[k])
    return out


def placements(rng: np.random.Generator, count: int, num_frames: int, num_sprites: int, spread: int):
    slots = rng.integers(0, num_frames, count)
    ids = rng.integers(0, num_sprites, count)
    top = rng.integers(-spread, H + spread, count)
    left = rng.integers(-spread, W + spread, count)
    return slots, ids, top, left


def test_add_reuses_a_known_run_and_appends_new_ones() -> None:
    scatter = SpriteScatter()
    a = random_sprites(np.random.default_rng(0))
    assert scatter.add(a) == 0
    assert scatter.add(a[1:3]) == 1
    b = agent_sprites(0.5)
    assert scatter.add(b) == len(a)
    assert scatter.add(a) == 0
    assert scatter.max_side == max(max(s.height, s.width) for s in a + b)
    assert scatter.heights.tolist() == [s.height for s in a + b]


@pytest.mark.parametrize("seed", range(5))
def test_clipped_scatter_matches_per_slot_pastes_at_every_edge(seed: int) -> None:
    rng = np.random.default_rng(seed)
    sprites = random_sprites(rng)
    scatter = SpriteScatter()
    scatter.add(sprites)
    num = 4
    frames = rng.integers(0, 256, (num + 1, H, W, 3), dtype=np.uint8)  # the last frame is the spare
    slots, ids, top, left = placements(rng, 60, num, len(sprites), spread=8)
    # every edge and corner, partly and wholly off the frame
    for t, c in ((-2, 5), (H - 2, 5), (5, -3), (5, W - 1), (-1, -1), (H - 1, W - 2), (-7, 3), (3, W + 1)):
        slots, ids = np.append(slots, 1), np.append(ids, 3)
        top, left = np.append(top, t), np.append(left, c)
    expected = naive(frames[:num], sprites, slots, ids, top, left)
    scatter.paste(frames, slots, ids, top, left, clip=True)
    np.testing.assert_array_equal(frames[:num], expected)


@pytest.mark.parametrize("seed", range(3))
def test_where_limits_the_clipped_scatter_like_sprite_paste(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    sprites = random_sprites(rng)
    scatter = SpriteScatter()
    scatter.add(sprites)
    num = 3
    frames = rng.integers(0, 256, (num + 1, H, W, 3), dtype=np.uint8)
    where = np.repeat((rng.random((num, H, W, 1)) < 0.5).astype(np.uint8) * 255, 3, axis=3)
    slots, ids, top, left = placements(rng, 40, num, len(sprites), spread=6)
    expected = naive(frames[:num], sprites, slots, ids, top, left, where)
    scatter.paste(frames, slots, ids, top, left, clip=True, where=where)
    np.testing.assert_array_equal(frames[:num], expected)


def test_unclipped_scatter_into_a_margin_matches_clipped_pastes_on_the_visible_part() -> None:
    rng = np.random.default_rng(7)
    sprites = random_sprites(rng) + agent_sprites(0.25)
    scatter = SpriteScatter()
    scatter.add(sprites)
    m, num = scatter.max_side, 5
    canvas = rng.integers(0, 256, (num, H + 2 * m, W + 2 * m, 3), dtype=np.uint8)
    visible = canvas[:, m : m + H, m : m + W]
    slots, ids, top, left = placements(rng, 50, num, len(sprites), spread=0)
    # sprites overlapping the visible part by at least one row and column, up to the outermost such corners
    top = np.clip(top, 1 - scatter.heights[ids], H - 1)
    left = np.clip(left, 1 - scatter.widths[ids], W - 1)
    top[:2], left[:2] = 1 - scatter.heights[ids[:2]], 1 - scatter.widths[ids[:2]]
    expected = naive(visible, sprites, slots, ids, top, left)
    scatter.paste(canvas, slots, ids, top + m, left + m)
    np.testing.assert_array_equal(visible, expected)


def test_sprite_paste_with_leading_axes_and_where() -> None:
    rng = np.random.default_rng(3)
    sprite = random_sprites(rng)[3]
    frames = rng.integers(0, 256, (2, H, W, 3), dtype=np.uint8)
    where = np.zeros((H, W, 3), np.uint8)
    where[:, : W // 2] = 255
    both = frames.copy()
    sprite.paste(both, H - 3, W // 2 - 4, where)
    for frame, pasted in zip(frames, both, strict=True):
        single = frame.copy()
        sprite.paste(single, H - 3, W // 2 - 4, where)
        np.testing.assert_array_equal(pasted, single)
        assert (pasted[:, W // 2 :] == frame[:, W // 2 :]).all()  # nothing outside `where`
    assert (both != frames).any()


def test_scatter_refuses_frames_it_could_not_write_in_place() -> None:
    scatter = SpriteScatter()
    scatter.add(random_sprites(np.random.default_rng(1)))
    canvas = np.zeros((2, H + 4, W + 4, 3), np.uint8)
    with pytest.raises(ValueError, match="C-contiguous"):
        scatter.paste(canvas[:, 2:-2, 2:-2], np.array([0]), np.array([0]), np.array([1]), np.array([1]))


@pytest.mark.parametrize("seed", range(4))
def test_sprite_paste_copies_exactly_the_opaque_pixels_that_land_on_the_frame(seed: int) -> None:
    rng = np.random.default_rng(50 + seed)
    for sprite in random_sprites(rng) + agent_sprites(0.25):
        for top, left in ((-2, -3), (H - 2, W - 3), (4, 5), (-sprite.height, 0), (1, W)):
            frame = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
            expected = frame.copy()
            for i, j in zip(*np.nonzero(sprite.mask), strict=True):  # pixel by pixel
                if 0 <= top + i < H and 0 <= left + j < W:
                    expected[top + i, left + j] = sprite.rgb[i, j]
            sprite.paste(frame, top, left)
            np.testing.assert_array_equal(frame, expected)


@pytest.mark.parametrize("seed", range(3))
def test_sheet_paste_inside_matches_per_slot_pastes(seed: int) -> None:
    """SpriteSheet.paste_inside (windows known to lie inside, one composite) pastes what Sprite.paste does (one
    sprite per frame, as the batched cores paste them)."""
    from envs.drawing import SpriteSheet

    rng = np.random.default_rng(seed)
    sprites = agent_sprites(0.25)
    sheet = SpriteSheet(sprites, 3, 5)  # an anchor away from the corner
    height, width, count = 40, 44, 30
    frames = rng.integers(0, 256, (count + 2, height, width, 3), dtype=np.uint8)
    slots, which = rng.permutation(count + 2)[:count], rng.integers(0, len(sprites), count)
    rows = rng.integers(-sheet.top, height - sheet.height - sheet.top + 1, count)
    cols = rng.integers(-sheet.left, width - sheet.width - sheet.left + 1, count)
    expected = frames.copy()
    for k, w, r, c in zip(slots, which, rows, cols, strict=True):
        sprites[w].paste(expected[k], int(r) - 3, int(c) - 5)
    sheet.paste_inside(frames.reshape(count + 2, height, -1), slots, rows, cols, which)
    np.testing.assert_array_equal(frames, expected)
