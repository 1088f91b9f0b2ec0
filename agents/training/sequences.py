"""From a rollout (workers x steps) to minibatches of whole, padded sequences for truncated BPTT.

Steps are numbered flat, worker-major: step ``t`` of worker ``w`` is ``w * steps + t``. A rollout row is split
at episode ends (the step whose action ended the episode closes it) and every piece is cut into sequences of at
most ``max_length`` steps (``None``: whole pieces, i.e. as long as the longest episode allows). The start of a row
is always a sequence start, so the first sequence of a row continues an episode that began in an earlier rollout:
its start state is the memory state the policy carried into that step, stored during the rollout.

A minibatch of S sequences is padded to the longest sequence *in that minibatch* (never to the longest episode of
the batch) and described by a mask (S, P): ``mask[i, j]`` is true for the real steps of sequence i, a prefix of
its row. The real steps are listed flat in sequence order (``step_index``), the order in which ``tensor[mask]``
enumerates a padded (S, P) tensor, so non-recurrent layers and losses work on real steps only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class Sequences:
    """All sequences of one rollout: flat index of each first step and each length (both (S,), int64)."""

    starts: np.ndarray
    lengths: np.ndarray

    def __len__(self) -> int:
        return len(self.starts)


@dataclass(frozen=True)
class SequenceBatch:
    """Some sequences, padded: which steps are real (``mask``), where they are (``step_index``) and where each
    sequence starts (``start_index``, to gather the stored start states)."""

    mask: torch.Tensor  # (S, P) bool
    step_index: torch.Tensor  # (N,) int64, N = mask.sum(), real steps in sequence order
    start_index: torch.Tensor  # (S,) int64

    @property
    def num_steps(self) -> int:
        return int(self.step_index.shape[0])


def split_sequences(terminated: np.ndarray, max_length: int | None) -> Sequences:
    """Split each row of ``terminated`` (workers, steps) at episode ends and every ``max_length`` steps."""
    terminated = np.asarray(terminated, dtype=bool)
    if terminated.ndim != 2:
        raise ValueError(f"terminated must have shape (workers, steps), got {terminated.shape}")
    if max_length is not None and max_length < 1:
        raise ValueError(f"max_length={max_length!r} is invalid: expected an int >= 1 or None")
    workers, steps = terminated.shape
    episode_start = np.zeros((workers, steps), dtype=bool)
    episode_start[:, 0] = True
    episode_start[:, 1:] = terminated[:, :-1]
    is_start = episode_start
    if max_length is not None:
        t = np.broadcast_to(np.arange(steps), (workers, steps))
        first_step = np.maximum.accumulate(np.where(episode_start, t, 0), axis=1)
        is_start = episode_start | ((t - first_step) % max_length == 0)
    starts = np.flatnonzero(is_start)  # row-major: sorted, and every row begins with a start
    lengths = np.diff(np.append(starts, workers * steps))
    return Sequences(starts.astype(np.int64), lengths.astype(np.int64))


def pad_sequences(
    sequences: Sequences, ids: np.ndarray, device: torch.device | str = "cpu", pad_to: int | None = None
) -> SequenceBatch:
    """The padded batch of the sequences ``ids``; padded to their longest length, or to ``pad_to`` if given."""
    ids = np.asarray(ids, dtype=np.int64)
    starts, lengths = sequences.starts[ids], sequences.lengths[ids]
    longest = int(lengths.max())
    width = longest if pad_to is None else pad_to
    if width < longest:
        raise ValueError(f"pad_to={pad_to} is shorter than the longest sequence ({longest})")
    offsets = np.arange(width)
    mask = offsets[None, :] < lengths[:, None]
    step_index = (starts[:, None] + offsets[None, :])[mask]
    return SequenceBatch(
        mask=torch.from_numpy(mask).to(device),
        step_index=torch.from_numpy(step_index).to(device),
        start_index=torch.from_numpy(starts).to(device),
    )


def minibatch_ids(num_sequences: int, minibatches: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Shuffle whole sequences into ``minibatches`` groups whose sizes differ by at most one."""
    if minibatches > num_sequences:
        raise ValueError(
            f"ppo.minibatches={minibatches} exceeds the {num_sequences} sequences of this batch: "
            "use fewer minibatches, more workers/steps or shorter sequences"
        )
    return np.array_split(rng.permutation(num_sequences), minibatches)
