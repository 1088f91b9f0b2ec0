"""Fast and Forgetful Memory (``model.memory: ffm``; Morad et al., NeurIPS 2023), on the shared scan.

Per block: the layer-normed input u_t is projected to ``trace_size`` channels and gated, x_t = W u_t * sigmoid(G u_t);
every channel j keeps ``context_size`` complex traces S_t[j, k] = gamma[j, k] * S_{t-1}[j, k] + x_t[j], with
gamma = exp(-|alpha| + i omega): alpha sets how fast a trace forgets (initial time constants spread geometrically
from 1 to ``max_horizon`` steps over the channels), omega how it oscillates (initial frequencies spread over
[0, pi/2] over the contexts), both learned per channel x context. The traces' real and imaginary parts go through a
linear layer and a LayerNorm to the block's width, mixed with a skip path of u by an output gate:
y = z * sigmoid(O u) + (K u) * (1 - sigmoid(O u)), added to the block's input. The state is S, stored as
(real, imaginary).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from agents.layers import orthogonal
from agents.memory.base import MemorySpec, ModelSettings
from agents.memory.scan import Layout, ScanMemory, complex_dtype, full_precision, widen
from agents.settings import Settings, param

__all__ = ["FFM", "FfmConfig"]  # agents.memory exports them too


@dataclass
class FfmConfig(Settings):
    """Fast and Forgetful Memory (``model.memory: ffm``, agents/memory/ffm.py): ``model.memory_layers`` residual
    blocks of width ``model.memory_size``, each trace_size x context_size decaying, oscillating complex traces."""

    trace_size: int = param(32, "gated input channels per block, each with context_size traces", low=1)
    context_size: int = param(4, "traces per channel (decay and frequency learned per channel x context)", low=1)
    max_horizon: float = param(1024.0, "longest initial time constant of a trace (steps)", low=1.0)


class FFMBlock(nn.Module):
    """One residual FFM block of width ``dim``."""

    def __init__(self, dim: int, config: FfmConfig) -> None:
        super().__init__()
        traces, contexts = config.trace_size, config.context_size
        self.shape = (traces, contexts)
        self.state_size = 2 * traces * contexts
        horizons = torch.logspace(0, math.log10(config.max_horizon), traces)  # steps until a trace fades to 1/e
        self.alpha = nn.Parameter((1.0 / horizons).unsqueeze(1).repeat(1, contexts))
        self.omega = nn.Parameter(torch.linspace(0, math.pi / 2, contexts).unsqueeze(0).repeat(traces, 1))
        self.norm = nn.LayerNorm(dim)
        self.project = orthogonal(nn.Linear(dim, 2 * traces), 1.0)  # the trace input and its gate
        self.mix = nn.Sequential(orthogonal(nn.Linear(self.state_size, dim), 1.0), nn.LayerNorm(dim))
        self.skip_gate = orthogonal(nn.Linear(dim, 2 * dim), 1.0)  # the skip path and the output gate

    def decay(self) -> Tensor:
        """gamma (trace_size, context_size), complex, |gamma| <= 1; complex64 also from the bfloat16 weights of a
        bf16 acting copy (torch has no complex bfloat16)."""
        return torch.exp(torch.complex(-widen(self.alpha).abs(), widen(self.omega)))

    def forward(self, x: Tensor, state: Tensor, layout: Layout) -> tuple[Tensor, Tensor]:
        u = self.norm(x)  # (N, dim)
        value, gate = widen(self.project(u)).chunk(2, dim=-1)
        with full_precision(value.device):  # the gate, the decays and the traces in fp32 (complex64) under bf16 too
            gated = value * torch.sigmoid(gate)  # (N, m)
            inputs = gated.unsqueeze(-1).expand(*gated.shape, self.shape[1])  # (N, m, c)
            start = torch.view_as_complex(widen(state).reshape(-1, *self.shape, 2).contiguous())
            dtype = complex_dtype(value.dtype)
            traces = torch.view_as_real(layout.scan(self.decay().to(dtype), inputs.to(dtype), start)).flatten(1)
        z = self.mix(traces.to(x.dtype))
        skip, out_gate = self.skip_gate(u).chunk(2, dim=-1)
        out_gate = torch.sigmoid(out_gate)
        return x + z * out_gate + skip * (1 - out_gate), layout.last(traces)


class FFM(ScanMemory):
    """``layers`` FFM blocks of width ``dim`` (the model's ``memory_size``)."""

    def __init__(self, config: FfmConfig, input_size: int, dim: int, layers: int) -> None:
        super().__init__(input_size, dim, [FFMBlock(dim, config) for _ in range(layers)])


def build(config: ModelSettings, input_size: int) -> FFM:
    """``model.memory_layers`` FFM blocks of width ``model.memory_size``, with the block ``model.ffm``."""
    return FFM(config.ffm, input_size, config.memory_size, config.memory_layers)


MEMORIES = (MemorySpec("ffm", "FFM-PPO", "#117733", build, settings=FfmConfig, order=50),)  # green
