"""The interface every memory module implements (see the package docstring, :mod:`agents.memory`)."""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor, nn


class Memory(nn.Module):
    """Base class of the memory modules: features of one step in, the memory's output out.

    Subclasses set ``output_size``, ``state_shape`` (the per-slot state), ``record_shape`` (what the rollout buffer
    keeps per step) and ``history`` (None: the training pass reads the record at each sequence start; an int h: it
    reads the h records before each sequence start and the sequence's own), and implement :meth:`step` and
    :meth:`sequences`; the defaults below suit a state that is one tensor whose zeros are an episode start."""

    output_size: int
    state_shape: tuple[int, ...]
    record_shape: tuple[int, ...]
    history: int | None = None
    state_dtype: torch.dtype = torch.float32
    stateless: bool = False  # True: no memory at all, every step is a sequence of its own

    def initial_state(self, batch: int, device: torch.device | str) -> Tensor:
        """The state of ``batch`` slots at an episode start: zeros (the actor clears a slot by zeroing its row)."""
        return torch.zeros((batch, *self.state_shape), dtype=self.state_dtype, device=device)

    def step(self, features: Tensor, state: Tensor, episode_step: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """One step of B slots: features (B, F), state (B, *state_shape), decisions since each slot's episode start
        (B,). Returns the output (B, output_size) and the next state."""
        raise NotImplementedError

    def acting_cache(self, state: Tensor, episode_step: Tensor | None = None) -> Any:
        """What acting may keep from one step to the next instead of recomputing it from the state at every step
        (a transformer's window, as its attention reads it), built from ``state`` (B, ...) at ``episode_step`` (B,), or
        None (the default): nothing. A memory that returns one takes it as :meth:`step`'s ``cache`` and advances it
        in place, with the outputs and next state of a step without it. The actor keeps it while the memory's
        parameters are unchanged and every slot steps, or is cleared to an episode start (which must read nothing
        of it), and builds a new one otherwise."""
        return None

    def record(self, state: Tensor, next_state: Tensor) -> Tensor:
        """What the buffer keeps of one step (B, *record_shape), from the state fed in and the state it gave: by
        default the state fed in (a recurrent memory's start state of any sequence that begins there)."""
        return state

    def history_records(self, state: Tensor) -> Tensor:
        """The ``history`` records before a rollout (B, history, *record_shape), oldest first, from the state the
        slots carry into it (only called when ``history`` is an int)."""
        raise NotImplementedError

    def sequences(self, features: Tensor, records: Tensor, mask: Tensor, episode_step: Tensor | None = None) -> Tensor:
        """Training: ``features`` (N, F) of the real steps of S sequences in sequence order, ``mask`` (S, P) their
        padding mask (a prefix of real steps per row), ``records`` what the buffer gathered for them (``history``
        None: (S, *record_shape), the record at each sequence start; an int h: (S, h + P, *record_shape), the h
        records before each sequence start and the P records of its positions), ``episode_step`` (N,) each step's
        decisions since its episode start. Returns the outputs (N, output_size) of the N steps, in the same order."""
        raise NotImplementedError
