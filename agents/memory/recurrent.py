"""Memory-less and recurrent memories: ``none``, ``gru`` and ``lstm`` (three specs in :data:`MEMORIES`).

The state is one tensor per slot, zeros at an episode start; the buffer keeps the state fed into every step
(:meth:`Memory.record`'s default), and the training pass starts each sequence from its stored start state.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn.utils.rnn import PackedSequence

from agents.layers import HIDDEN_GAIN, compute_dtype, orthogonal
from agents.memory.base import Memory, MemorySpec, ModelSettings
from agents.memory.packed_gru import packed_gru

__all__ = ["NoMemory", "RecurrentMemory"]  # agents.memory exports them too


class NoMemory(Memory):
    """The memory-less model: features pass straight through, the state is empty."""

    def __init__(self, input_size: int) -> None:
        super().__init__()
        self.output_size = input_size
        self.state_shape = self.record_shape = (0,)
        self.stateless = True

    def step(self, features: Tensor, state: Tensor, episode_step: Tensor | None = None) -> tuple[Tensor, Tensor]:
        return features, state

    def sequences(self, features: Tensor, records: Tensor, mask: Tensor, episode_step: Tensor | None = None) -> Tensor:
        return features


class RecurrentMemory(Memory):
    """A GRU or LSTM whose state is one tensor per environment: (layers, H) or, for the LSTM, (2, layers, H)."""

    def __init__(self, kind: str, input_size: int, hidden_size: int, layers: int) -> None:
        super().__init__()
        rnn_class = {"gru": nn.GRU, "lstm": nn.LSTM}[kind]
        self.rnn = orthogonal(rnn_class(input_size, hidden_size, layers, batch_first=True), HIDDEN_GAIN)
        self.kind = kind
        self.output_size = hidden_size
        self.state_shape = (layers, hidden_size) if kind == "gru" else (2, layers, hidden_size)
        self.record_shape = self.state_shape  # the state fed into each step

    def step(self, features: Tensor, state: Tensor, episode_step: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """One step of ``B`` environments: features (B, F), state (B, *state_shape)."""
        if self._packed_gru(features):  # a packed batch of B one-step sequences; each layer's output is its new state
            dtype = compute_dtype(self.rnn.weight_ih_l0)
            states, layer_input = [], features
            for layer, h0 in enumerate(state.transpose(0, 1)):
                layer_input = packed_gru(self.rnn, layer_input, h0[None], [features.shape[0]], dtype, layer)
                states.append(layer_input)
            return layer_input.to(features.dtype), torch.stack(states, dim=1)
        output, final = self.rnn(features.unsqueeze(1), self._to_rnn(state.to(features.dtype)))
        return output.squeeze(1), self._from_rnn(final)

    def sequences(
        self, features: Tensor, start_state: Tensor, mask: Tensor, episode_step: Tensor | None = None
    ) -> Tensor:
        """Run whole sequences: ``features`` (N, F) are the real steps in sequence order, ``mask`` (S, P) marks
        which of the P positions of each of the S sequences are real (a prefix), ``start_state`` (S, ...) is the
        state the policy had at each sequence start. Returns the outputs of the N real steps, in the same order.

        The recurrence runs on the packed layout (at time t, only the sequences still running), so padding costs
        nothing and cannot change any output: what the zero-padded (S, P) layout computes, minus the padding.
        """
        order = torch.argsort(mask.sum(dim=1), descending=True, stable=True)  # packing wants the longest first
        row = torch.zeros(mask.shape, dtype=torch.int64, device=mask.device)
        row[mask] = torch.arange(features.shape[0], device=mask.device)  # where each real step sits in `features`
        sorted_mask = mask[order]
        time_major = row[order].T[sorted_mask.T]  # packed order: step t of every sequence longer than t
        batch_sizes = sorted_mask.sum(dim=0).cpu()
        batch_sizes = batch_sizes[batch_sizes > 0]
        packed_rows = features.index_select(0, time_major)  # gathers of whole rows, both ways (no scatter)
        if self._packed_gru(features):
            dtype = compute_dtype(self.rnn.weight_ih_l0)
            layer_input = packed_rows
            for layer in range(self.rnn.num_layers):
                h0 = start_state[order, layer][None]
                layer_input = packed_gru(self.rnn, layer_input, h0, batch_sizes.tolist(), dtype, layer)
            output = layer_input.to(features.dtype)
        else:
            packed = PackedSequence(packed_rows, batch_sizes, order, torch.argsort(order))
            output = self.rnn(packed, self._to_rnn(start_state.to(features.dtype)))[0].data
        sequence_order = torch.empty_like(time_major)
        sequence_order[time_major] = torch.arange(time_major.shape[0], device=time_major.device)
        return output.index_select(0, sequence_order)

    def _packed_gru(self, features: Tensor) -> bool:
        """Whether the GRU runs through :func:`packed_gru`: on the CPU, where ``nn.GRU``'s packed backward works step
        by step; elsewhere ``nn.GRU`` (cuDNN's fused kernels on CUDA) is the faster one."""
        return self.kind == "gru" and features.device.type == "cpu"

    def _to_rnn(self, state: Tensor) -> Tensor | tuple[Tensor, Tensor]:
        if self.kind == "gru":
            return state.transpose(0, 1).contiguous()
        return state[:, 0].transpose(0, 1).contiguous(), state[:, 1].transpose(0, 1).contiguous()

    def _from_rnn(self, state: Tensor | tuple[Tensor, Tensor]) -> Tensor:
        if self.kind == "gru":
            return state.transpose(0, 1)
        hidden, cell = state
        return torch.stack((hidden.transpose(0, 1), cell.transpose(0, 1)), dim=1)


def build_none(config: ModelSettings, input_size: int) -> NoMemory:
    """No memory: the features pass through."""
    return NoMemory(input_size)


def build_gru(config: ModelSettings, input_size: int) -> RecurrentMemory:
    """A GRU of ``model.memory_layers`` layers of ``model.memory_size`` units."""
    return RecurrentMemory("gru", input_size, config.memory_size, config.memory_layers)


def build_lstm(config: ModelSettings, input_size: int) -> RecurrentMemory:
    """An LSTM of ``model.memory_layers`` layers of ``model.memory_size`` units."""
    return RecurrentMemory("lstm", input_size, config.memory_size, config.memory_layers)


MEMORIES = (
    # the memory-less agent is PPO itself (a run with memory none is named after its other parts, else ppo)
    MemorySpec("none", "PPO", "#d55e00", build_none, stateless=True, order=0),  # vermillion (Okabe-Ito)
    MemorySpec("gru", "GRU-PPO", "#0072b2", build_gru, order=10),  # blue
    MemorySpec("lstm", "LSTM-PPO", "#009e73", build_lstm, order=20),  # bluish green
)
