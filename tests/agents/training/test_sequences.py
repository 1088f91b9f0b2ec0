"""Splitting a rollout into sequences, padding minibatches, and shuffling whole sequences."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.training.sequences import minibatch_ids, pad_sequences, split_sequences


def _terminated(rows: list[str]) -> np.ndarray:
    """'..x..' -> the action of step 2 ended an episode."""
    return np.array([[c == "x" for c in row] for row in rows])


def _pieces(rows: list[str], max_length: int | None) -> list[tuple[int, int, int]]:
    """(worker, first step, length) of every sequence."""
    steps = len(rows[0])
    sequences = split_sequences(_terminated(rows), max_length)
    return [(int(s) // steps, int(s) % steps, int(n)) for s, n in zip(sequences.starts, sequences.lengths, strict=True)]


def test_whole_episodes_with_max() -> None:
    # worker 0: an episode from an earlier rollout ends at step 2, one ends at 6, one crosses the rollout end
    # worker 1: one episode covers the whole rollout; worker 2: episodes end exactly at the rollout end
    rows = ["..x...x..", ".........", "x.......x"]
    assert _pieces(rows, None) == [(0, 0, 3), (0, 3, 4), (0, 7, 2), (1, 0, 9), (2, 0, 1), (2, 1, 8)]


def test_fixed_length_cuts_every_episode_from_its_own_start() -> None:
    rows = ["..x...x..", ".........", "x.......x"]
    assert _pieces(rows, 3) == [
        (0, 0, 3),
        (0, 3, 3),
        (0, 6, 1),  # the rest of the episode ending at 6: shorter than the length
        (0, 7, 2),
        (1, 0, 3),
        (1, 3, 3),
        (1, 6, 3),
        (2, 0, 1),
        (2, 1, 3),
        (2, 4, 3),
        (2, 7, 2),
    ]
    assert _pieces(rows, 1) == [(w, t, 1) for w in range(3) for t in range(9)]


def test_sequences_cover_every_step_once_and_never_cross_an_episode_end() -> None:
    rng = np.random.default_rng(0)
    terminated = rng.random((7, 50)) < 0.1
    for max_length in (None, 1, 4, 16, 100):
        sequences = split_sequences(terminated, max_length)
        covered = np.concatenate(
            [np.arange(s, s + n) for s, n in zip(sequences.starts, sequences.lengths, strict=True)]
        )
        np.testing.assert_array_equal(covered, np.arange(7 * 50))
        flat_done = terminated.reshape(-1)
        for start, length in zip(sequences.starts, sequences.lengths, strict=True):
            assert not flat_done[start : start + length - 1].any()  # an end can only be a sequence's last step
            assert start // 50 == (start + length - 1) // 50  # never crosses into another worker's row
            if max_length is not None:
                assert length <= max_length


def test_padding_goes_to_the_longest_sequence_present_not_the_longest_episode() -> None:
    rows = ["..............x", "..x..x..x..x..x"]  # a 15-step episode and four 3-step ones
    sequences = split_sequences(_terminated(rows), 4)
    short_only = np.flatnonzero(sequences.lengths == 3)
    batch = pad_sequences(sequences, short_only)
    assert batch.mask.shape == (len(short_only), 3)  # not 4 (the length) and not 15 (the longest episode)
    everything = pad_sequences(sequences, np.arange(len(sequences)))
    assert everything.mask.shape[1] == 4


def test_padded_batch_layout() -> None:
    sequences = split_sequences(_terminated(["..x...", "......"]), None)  # (0,3), (3,3), (6,6)
    batch = pad_sequences(sequences, np.array([2, 0]))
    expected_mask = torch.tensor([[True] * 6, [True] * 3 + [False] * 3])
    assert torch.equal(batch.mask, expected_mask)
    assert batch.step_index.tolist() == [6, 7, 8, 9, 10, 11, 0, 1, 2]  # real steps, in sequence order
    assert batch.start_index.tolist() == [6, 0]
    padded = torch.full(batch.mask.shape, -1)
    padded[batch.mask] = batch.step_index
    assert padded.tolist() == [[6, 7, 8, 9, 10, 11], [0, 1, 2, -1, -1, -1]]  # tensor[mask] enumerates step_index
    wider = pad_sequences(sequences, np.array([2, 0]), pad_to=9)
    assert wider.mask.shape == (2, 9) and torch.equal(wider.step_index, batch.step_index)
    with pytest.raises(ValueError, match="shorter than the longest sequence"):
        pad_sequences(sequences, np.array([2]), pad_to=5)


def test_minibatches_hold_whole_shuffled_sequences() -> None:
    groups = minibatch_ids(10, 3, np.random.default_rng(1))
    assert sorted(len(g) for g in groups) == [3, 3, 4]
    assert sorted(np.concatenate(groups).tolist()) == list(range(10))
    again = minibatch_ids(10, 3, np.random.default_rng(1))
    assert all(np.array_equal(a, b) for a, b in zip(groups, again, strict=True))
    with pytest.raises(ValueError, match="ppo.minibatches=11 exceeds the 10 sequences"):
        minibatch_ids(10, 11, np.random.default_rng(1))


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="shape"):
        split_sequences(np.zeros(5, dtype=bool), None)
    with pytest.raises(ValueError, match="max_length=0"):
        split_sequences(np.zeros((2, 5), dtype=bool), 0)
