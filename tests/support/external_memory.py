"""A memory defined outside ``agents/``, reached through ``model.memory: "tests.support.external_memory:LeakyMemory"``
(the example of docs/memory.md): a learned projection into a leaky integrator, h_t = leak * h_{t-1} + W x_t."""

from __future__ import annotations

import torch
from torch import Tensor, nn

from agents.config import ModelConfig
from agents.memory import Memory


class LeakyMemory(Memory):
    """A leaky integrator of a projection of the features; ``leak`` comes from ``model.memory_options``."""

    def __init__(self, input_size: int, config: ModelConfig, leak: float = 0.9) -> None:
        super().__init__()
        self.leak = leak
        self.project = nn.Linear(input_size, config.memory_size)
        self.output_size = config.memory_size
        self.state_shape = self.record_shape = (config.memory_size,)

    def step(self, features: Tensor, state: Tensor, episode_step: Tensor | None = None) -> tuple[Tensor, Tensor]:
        h = self.leak * state + self.project(features)
        return torch.tanh(h), h

    def sequences(self, features: Tensor, records: Tensor, mask: Tensor, episode_step: Tensor | None = None) -> Tensor:
        s, p = mask.shape
        inputs = self.project(features.new_zeros((s, p, features.shape[-1])).index_put((mask,), features))
        h, outputs = records, []
        for t in range(p):  # the padding trails the real steps, so it never reaches them
            h = self.leak * h + inputs[:, t]
            outputs.append(torch.tanh(h))
        return torch.stack(outputs, dim=1)[mask]
