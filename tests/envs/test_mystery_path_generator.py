"""The Mystery Path level generator against levels recorded from memory-gym 1.0.2 (tests/data/mp_paths.json.gz)."""

from __future__ import annotations

import numpy as np
import pytest

import envs
from envs.mystery_path.generator import generate_path
from envs.rng import seeded_generator
from scripts.reference.trace_format import load_mp_paths

GRID = 7
SIDES = {  # cardinal_origin_choice value -> (origin, goal) from the two row/column draws
    0: lambda a, b: ((0, a), (6, b)),
    1: lambda a, b: ((6, a), (0, b)),
    2: lambda a, b: ((a, 0), (b, 6)),
    3: lambda a, b: ((a, 6), (b, 0)),
}


@pytest.fixture(scope="module")
def recorded() -> dict:
    return load_mp_paths()


def _level_from_seed(seed: int, choice: list[int]) -> tuple[tuple, tuple, object, np.random.Generator]:
    """Make the draws of a MysteryPath-v0 reset (side, two positions), then the level."""
    rng = seeded_generator(seed)
    side = choice[int(rng.integers(0, len(choice)))]
    origin, goal = SIDES[side](int(rng.integers(0, GRID)), int(rng.integers(0, GRID)))
    return origin, goal, generate_path(rng, GRID, GRID, origin, goal), rng


def test_levels_match_the_reference_tile_for_tile(recorded: dict) -> None:
    layouts = recorded["MysteryPath-v0"]
    assert len(layouts) == 500  # seeds 0..299 with the default sides, 0..49 for each single side
    for record in layouts:
        choice = (record["options"] or {}).get("cardinal_origin_choice", [0, 1, 2, 3])
        origin, goal, layout, _ = _level_from_seed(record["seed"], choice)
        where = f"seed {record['seed']} options {record['options']}"
        assert [list(origin), list(goal)] == [record["origin"], record["goal"]], where
        assert [list(t) for t in layout.path] == record["path"], where
        assert sorted(list(t) for t in layout.walls) == record["walls"], where


def test_environment_levels_match_the_reference(recorded: dict) -> None:
    core = envs.make_core("MysteryPath-v0")
    for record in recorded["MysteryPath-v0"][:100]:
        core.reset_slot(0, seed=record["seed"], options=record["options"])
        origin, goal, layout = core.levels[0]
        assert [list(t) for t in layout.path] == record["path"]
        assert (list(origin), list(goal)) == (record["origin"], record["goal"])


def test_endless_segments_match_the_reference(recorded: dict) -> None:
    core = envs.make_core("Endless-MysteryPath-v0")
    records = recorded["Endless-MysteryPath-v0"]
    assert len(records) == 100
    for record in records:
        core.reset_slot(0, seed=record["seed"])
        xs, ys = core.path_tiles(0)  # the three segments the reference builds at reset
        ends = [0, *core.segment_ends[0]]
        bounds = zip(ends, ends[1:], strict=False)
        segments = [[[x, y] for x, y in zip(xs[a:b], ys[a:b], strict=True)] for a, b in bounds]
        assert segments == record["segments"], f"seed {record['seed']}"


def test_level_properties_over_many_seeds() -> None:
    lengths, border_walls = [], set()
    for seed in range(400):
        origin, goal, layout, _ = _level_from_seed(seed, [0, 1, 2, 3])
        path, walls = layout.path, set(layout.walls)
        assert path[0] == origin and path[-1] == goal
        assert len(set(path)) == len(path)  # a parent chain never repeats a tile
        assert all(abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1 for a, b in zip(path, path[1:], strict=False))
        assert not walls & set(path)
        inner = {w for w in walls if 0 < w[0] < GRID - 1 and 0 < w[1] < GRID - 1}
        assert all(1 <= x <= GRID - 3 and 1 <= y <= GRID - 3 for x, y in inner)  # the lopsided inner-wall loop
        border_walls.add(len(walls - inner))
        lengths.append(len(path))
    assert border_walls <= {4, 8} and border_walls == {4, 8}
    assert min(lengths) >= GRID and 9 < np.mean(lengths) < 11.5  # the reference: 7..15, mean 10.1


def test_generator_leaves_the_rng_where_one_draw_at_a_time_would() -> None:
    # Two consecutive levels from one generator equal the recorded endless segments only if the first level
    # consumed exactly the reference's draws; here: the state after a level is independent of read-ahead.
    for seed in range(50):
        rng = seeded_generator(seed)
        generate_path(rng, GRID, GRID, (0, 3), (6, 4))
        again = seeded_generator(seed)
        generate_path(again, GRID, GRID, (0, 3), (6, 4))
        assert rng.bit_generator.state == again.bit_generator.state
    with pytest.raises(TypeError, match="PCG64"):
        generate_path(np.random.Generator(np.random.Philox(0)), GRID, GRID, (0, 3), (6, 4))


def _walls_by_calls(draws, start: int, end: int, highs: list[int] | None = None) -> list[int]:
    """Stages 1 and 2 with one ``integers`` draw per call (``below``), as the module doc describes them; the bound
    of each call is appended to ``highs``."""
    from envs.mystery_path.generator import BORDER_WALL_COUNTS, WALL_PERCENT, _grid

    def below(high: int) -> int:
        if highs is not None and high > 1:
            highs.append(high)
        return draws.below(high)

    grid = _grid(GRID, GRID)
    walls = [tile for tile in grid.inner if below(100) < WALL_PERCENT]
    wall_bits = sum(1 << tile for tile in walls)
    candidates = [t for t in grid.border_candidates(start, end) if not grid.surrounding[t] & wall_bits]
    for _ in range(BORDER_WALL_COUNTS[below(2)]):
        if candidates:
            walls.append(candidates.pop(below(len(candidates))))
    return walls


def test_rejected_words_are_the_words_numpy_draws_again_after() -> None:
    from envs.mystery_path.generator import rejected_words

    for high in (2, 3, 5, 7, 12, 100):
        words = rejected_words(high)
        assert len(words) == 2**32 % high  # (w * high mod 2**32 takes each multiple of gcd(high, 2**32) that often)
        assert all((w * high) % 2**32 < 2**32 % high for w in words)
        rng = np.random.default_rng(high)
        sample = rng.integers(0, 2**32, 10_000, dtype=np.uint64).tolist()
        assert [w for w in sample if (w * high) % 2**32 < 2**32 % high] == [w for w in sample if w in words]


@pytest.mark.parametrize("rejected", [None, 0, 7, 15, "pick"])
def test_walls_read_from_the_words_equal_one_draw_per_call_also_when_numpy_draws_again(rejected) -> None:
    """``draw_walls`` reads the draws straight from the words; a word that numpy rejects (and draws again after)
    sends it through ``below``: the walls and the words used are those of one ``integers`` call per draw."""
    from envs.mystery_path.generator import _grid, draw_walls, rejected_words
    from envs.rng import BoundedDraws

    start, end = 3, 45  # (0, 3) -> (6, 3)
    tested = 0
    for seed in range(40):
        rng = seeded_generator(seed)
        words = BoundedDraws(rng)
        words.read_ahead(100)
        highs: list[int] = []
        probe = BoundedDraws(rng)
        probe.words, probe.saved = list(words.words), words.saved
        _walls_by_calls(probe, start, end, highs)
        assert len(highs) > 17 and highs[:17] == [100] * 16 + [2]
        if rejected == "pick":  # the first border pick, after the inner walls' 16 words and the count's
            if not rejected_words(highs[17]):
                continue  # a power of two: numpy never draws again
            words.words[17] = sorted(rejected_words(highs[17]))[seed % len(rejected_words(highs[17]))]
            tested += 1
        elif rejected is not None:
            words.words[rejected] = sorted(rejected_words(100))[seed % 96]
        fast, slow = BoundedDraws(rng), BoundedDraws(rng)
        for draws in (fast, slow):
            draws.words, draws.saved = list(words.words), words.saved
        assert draw_walls(fast, _grid(GRID, GRID), start, end) == _walls_by_calls(slow, start, end)
        assert fast.used == slow.used
    assert rejected != "pick" or tested >= 10


def test_free_border_tiles_kept_by_the_touching_inner_walls_equal_a_test_of_every_candidate() -> None:
    from envs.mystery_path.generator import _grid

    grid = _grid(GRID, GRID)
    rng = np.random.default_rng(3)
    for _ in range(300):
        start, end = (int(t) for t in rng.choice(grid.border, size=2, replace=False))
        walls = [t for t in grid.inner if rng.random() < 0.33]
        bits = sum(1 << t for t in walls)
        expected = tuple(t for t in grid.border_candidates(start, end) if not grid.surrounding[t] & bits)
        assert grid.free_border(start, end, bits) == expected


def test_skip_path_makes_the_draws_of_draw_path() -> None:
    """The search without parents uses the same words, so the generator ends where a built level leaves it."""
    from envs.mystery_path.generator import draw_path, skip_path
    from envs.rng import BoundedDraws

    rng = np.random.default_rng(8)
    for seed in range(300):
        origin, goal = (0, int(rng.integers(0, GRID))), (GRID - 1, int(rng.integers(0, GRID)))
        if seed % 3 == 0:
            origin, goal = (int(rng.integers(0, GRID)), GRID - 1), (int(rng.integers(0, GRID)), 0)
        built, skipped = seeded_generator(seed), seeded_generator(seed)
        for generator, make in ((built, draw_path), (skipped, skip_path)):
            draws = BoundedDraws(generator)
            draws.read_ahead(4)  # short blocks: the search reads ahead on the way
            for _ in range(3):
                make(draws, GRID, GRID, origin, goal)
            draws.close()
        assert built.bit_generator.state == skipped.bit_generator.state, seed
