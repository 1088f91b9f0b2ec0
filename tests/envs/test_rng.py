"""``BoundedDraws`` must give exactly the values and generator state of numpy's one-by-one bounded draws."""

from __future__ import annotations

import numpy as np
import pytest

from envs import rng as rng_module
from envs.rng import BoundedDraws, DirectDraws, next_word, seeded_generator, seeded_generators


def live_state(rng: np.random.Generator) -> dict:
    """The bit generator's state without the leftover half word when none is held (numpy leaves a stale value)."""
    state = dict(rng.bit_generator.state)
    if not state["has_uint32"]:
        state["uinteger"] = None
    return state


@pytest.mark.parametrize("seed", range(0, 400, 7))
def test_reserved_draws_match_numpy(seed: int) -> None:
    plan_rng = np.random.default_rng(seed)
    # small ranges (the environments' case), ranges of 1 (no draw), and huge ranges that reject often
    plan = [[int(h) for h in plan_rng.integers(1, 40, plan_rng.integers(0, 9))] for _ in range(5)]
    plan[seed % 5] += [3_000_000_000, 2_500_000_001, 1, 4_000_000_000, 2**32]
    ours, theirs = seeded_generator(seed), seeded_generator(seed)
    for i, part in enumerate(plan):
        draws = BoundedDraws(ours, sum(h > 1 for h in part), fresh=i == 0)
        got = [draws.below(h) for h in part]
        if part and plan_rng.random() < 0.5:  # a second reservation in the same object
            draws.reserve(1)
            got.append(draws.below(7))
            part = [*part, 7]
        draws.close()
        assert got == [int(theirs.integers(0, h)) for h in part]
        if plan_rng.random() < 0.5:  # numpy's own calls in between (a continuing generator)
            assert int(ours.integers(0, 9)) == int(theirs.integers(0, 9))
        assert live_state(ours) == live_state(theirs)
    assert ours.choice([3, 4, 5]) == theirs.choice([3, 4, 5])


def test_choice_consumes_like_bounded_draws() -> None:
    ours, theirs = seeded_generator(3), seeded_generator(3)
    draws = BoundedDraws(ours, 2, fresh=True)
    values = [[10, 20, 30][draws.below(3)], [7][draws.below(1)], [1, 2][draws.below(2)]]
    draws.close()
    assert values == [theirs.choice([10, 20, 30]), theirs.choice([7]), theirs.choice([1, 2])]
    assert live_state(ours) == live_state(theirs)


def test_unused_reserved_words_are_an_error() -> None:
    draws = BoundedDraws(seeded_generator(0), 3)
    draws.below(5)
    with pytest.raises(RuntimeError, match="not used"):
        draws.close()


@pytest.mark.parametrize("buffered", [False, True])
def test_read_ahead_draws_equal_numpy_and_rewind(buffered: bool) -> None:
    sizes = [1, 2, 3, 7, 8, 13, 100, 2**31 + 5, 3_000_000_000]
    plan = np.random.default_rng(1)
    for seed in range(400):
        ours, theirs = np.random.default_rng(seed), np.random.default_rng(seed)
        if buffered:  # leave an unused 32-bit half in the generator's state
            ours.integers(0, 5)
            theirs.integers(0, 5)
        ranges = plan.choice(sizes, size=int(plan.integers(0, 200))).tolist()
        draws = BoundedDraws(ours)
        if seed % 2:
            got = [value for n in ranges for value in draws.below_many(n, 1)]
        else:
            draws.read_ahead(int(plan.integers(1, 4)))  # small blocks: below must read ahead again
            got = [draws.below(n) for n in ranges]
        draws.close()
        assert got == [int(theirs.integers(0, n)) for n in ranges], seed
        assert ours.bit_generator.state == theirs.bit_generator.state, seed  # the stale half included


@pytest.mark.parametrize("seed", range(60))
def test_reserved_then_read_ahead_in_one_object(seed: int) -> None:
    plan = np.random.default_rng(seed + 1000)
    ours, theirs = seeded_generator(seed), seeded_generator(seed)
    if seed % 3 == 0:
        ours.integers(0, 5)
        theirs.integers(0, 5)
    exact = plan.integers(2, 30, int(plan.integers(0, 6))).tolist()
    ahead = plan.integers(1, 30, int(plan.integers(0, 120))).tolist()
    draws = BoundedDraws(ours, len(exact), fresh=seed % 3 != 0 and seed % 2 == 0)
    got = [draws.below(h) for h in exact]
    draws.read_ahead(1)
    got += [draws.below(h) for h in ahead]
    draws.close()
    assert got == [int(theirs.integers(0, h)) for h in exact + ahead]
    assert live_state(ours) == live_state(theirs)


@pytest.mark.parametrize("rejected", [0, 42_949_673])
def test_read_ahead_redraws_like_numpy_in_the_biased_case(rejected: int) -> None:
    # For n = 100 numpy redraws when the low 32 bits of x * 100 are below (2**32 - 100) % 100 = 96 (probability
    # 2e-8). Put such an x into the generator's buffered 32-bit half, so that it is the next output drawn.
    assert ((rejected * 100) & 0xFFFFFFFF) < 96
    for seed in range(20):
        ours, theirs = np.random.default_rng(seed), np.random.default_rng(seed)
        state = ours.bit_generator.state
        state.update(has_uint32=1, uinteger=rejected)
        ours.bit_generator.state = theirs.bit_generator.state = state
        draws = BoundedDraws(ours)
        got = draws.below_many(100, 3)
        draws.close()
        assert got == theirs.integers(0, 100, size=3).tolist()
        assert ours.bit_generator.state == theirs.bit_generator.state


def test_only_pcg64_streams_are_reproduced() -> None:
    with pytest.raises(TypeError, match="PCG64"):
        BoundedDraws(np.random.Generator(np.random.Philox(0)))


@pytest.mark.parametrize("leftover", [False, True])
def test_next_word_equals_numpy_32_bit_draws(leftover: bool) -> None:
    assert rng_module._bitgen_functions(np.random.PCG64(0))[1] is not None  # the C path is the one tested
    for seed in range(50):
        ours, theirs = seeded_generator(seed), seeded_generator(seed)
        if leftover:
            ours.integers(0, 9)
            theirs.integers(0, 9)
        got = [next_word(ours) for _ in range(seed % 5 + 1)]
        assert got == [int(theirs.integers(0, 2**32, dtype=np.uint32)) for _ in got]
        assert live_state(ours) == live_state(theirs)
        assert ours.integers(0, 1000, size=9).tolist() == theirs.integers(0, 1000, size=9).tolist()


@pytest.mark.parametrize("count", [1, 2, 3, 7, 64])
def test_batch_seeded_generators_equal_numpy_seeding(count: int) -> None:
    # one-word seeds (batched, including the word's edges), and seeds of two or more words (numpy's own path)
    pool = [0, 1, 2**31, 2**32 - 1, 2**32, 2**40 + 3, 10**30, *np.random.default_rng(count).integers(0, 2**32, 64)]
    seeds = [int(seed) for seed in np.random.default_rng(count + 1).permutation(pool)[:count]]
    for seed, rng in zip(seeds, seeded_generators(seeds), strict=True):
        assert rng.bit_generator.state == seeded_generator(seed).bit_generator.state, seed
        assert rng.integers(0, 2**63, 3).tolist() == seeded_generator(seed).integers(0, 2**63, 3).tolist()


def test_batch_seeded_generators_keep_the_seed_sequence_uses() -> None:
    import copy
    import pickle

    seeds = [5, 6, 7, 8]
    rng, twin = seeded_generators(seeds)[0], seeded_generator(5)
    sequence = rng.bit_generator.seed_seq
    assert sequence.entropy == 5 and sequence.spawn_key == () and repr(sequence) == repr(twin.bit_generator.seed_seq)
    assert (sequence.generate_state(3) == twin.bit_generator.seed_seq.generate_state(3)).all()
    assert [child.integers(0, 1000) for child in rng.spawn(2)] == [child.integers(0, 1000) for child in twin.spawn(2)]
    for clone in (pickle.loads(pickle.dumps(rng)), copy.deepcopy(rng)):
        assert type(clone.bit_generator.seed_seq) is np.random.SeedSequence
        assert clone.integers(0, 2**63, 4).tolist() == seeded_generator(5).integers(0, 2**63, 4).tolist()


@pytest.mark.parametrize("bit_generator", [np.random.PCG64, np.random.Philox, np.random.MT19937])
def test_direct_draws_equal_numpy_draws_and_leave_the_same_generator_state(bit_generator: type) -> None:
    """Bounded ints (with Lemire rejections, float bounds, the full 2**32 range), doubles around a kept half word,
    draws on a generator that holds a kept half when the draws start: values and the generator state."""
    assert rng_module._bitgen_functions(bit_generator(0))[2] is not None  # the C path is the one tested
    rng, twin = np.random.Generator(bit_generator(11)), np.random.Generator(bit_generator(11))
    spans = [(0, 360), (-45, 45), (7.5, 14.75), (0, 1), (5, 6), (0, 3 << 30), (0, 1 << 32), (2, 4), (0, 7056)]
    for round_ in range(60):
        draws = DirectDraws(rng)
        for i in range(round_ % 7 * 11):
            if (i + round_) % 3:  # 32-bit draws leave a half word kept every other time; a double must not touch it
                low, high = spans[(i * 5 + round_) % len(spans)]
                assert draws.integers(low, high) == twin.integers(low, high)
            else:
                low, high = (0.0025, 0.0075) if i % 2 else (0, 1)
                assert draws.uniform(low, high) == twin.uniform(low, high)
        if bit_generator is np.random.PCG64:
            assert live_state(rng) == live_state(twin)
        if round_ % 2:  # leave a kept half (or take it) through numpy itself
            assert rng.integers(0, 10) == twin.integers(0, 10)
    words = [generator.integers(0, 2**32, size=5, dtype=np.uint32).tolist() for generator in (rng, twin)]
    assert words[0] == words[1] and rng.random() == twin.random()  # the same state after all rounds
    with pytest.raises(ValueError, match="high - low"):
        DirectDraws(rng).integers(3, 3)


def test_direct_draws_fall_back_to_numpy_without_the_c_functions(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(rng_module, "_bitgen_functions", lambda bit_generator: (0, None, None))
    rng, twin = seeded_generator(3), seeded_generator(3)
    draws = DirectDraws(rng)
    assert [draws.integers(0, 360), draws.uniform(0.5, 2.0), draws.integers(7.5, 14.75)] == [
        twin.integers(0, 360),
        twin.uniform(0.5, 2.0),
        twin.integers(7.5, 14.75),
    ]
    assert next_word(rng) == int(twin.integers(0, 2**32, dtype=np.uint32))
    assert live_state(rng) == live_state(twin)
