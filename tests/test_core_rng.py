"""``BoundedDraws`` must give exactly the values and generator state of numpy's one-by-one bounded draws."""

from __future__ import annotations

import numpy as np
import pytest

from envs.core import BoundedDraws, seeded_generator


def live_state(rng: np.random.Generator) -> dict:
    """The bit generator's state without the leftover half word when none is held (numpy leaves a stale value)."""
    state = dict(rng.bit_generator.state)
    if not state["has_uint32"]:
        state["uinteger"] = None
    return state


@pytest.mark.parametrize("seed", range(0, 400, 7))
def test_bounded_draws_match_numpy(seed: int) -> None:
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
