"""A selective state-space memory (``model.memory: mamba``; Gu and Dao 2023's Mamba block), in pure PyTorch on the
shared scan.

Per block: the layer-normed input goes to two branches of width E = expand * dim. The main branch passes a causal
depthwise convolution over the last ``conv_size`` steps and SiLU, then a selective SSM: per step, the step size
Delta = softplus(W_dt (W_delta x) + b_dt) (E,) and B, C (``state_size``,) are functions of the input, and every
channel e keeps ``state_size`` states h_t[e, n] = exp(Delta_t[e] A[e, n]) h_{t-1}[e, n] + Delta_t[e] B_t[n] x_t[e],
read out as y_t[e] = sum_n C_t[n] h_t[e, n] + D[e] x_t[e]. A = -exp(A_log) stays negative (every state decays);
A starts at -(1..state_size) per channel and b_dt so that Delta starts log-uniform in [dt_min, dt_max] (the Mamba
initialisation). The output is gated by SiLU of the second branch, projected back to the block's width and added to
its input.

State per block: the convolution's last ``conv_size - 1`` inputs (conv_size - 1, E) and the SSM's h (E, state_size),
flattened into one vector, zeros at an episode start (a convolution over zero-padded steps before the episode).
``mamba-ssm``'s CUDA kernels are not needed and not used: the recurrence is the shared scan on every device.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from agents.layers import orthogonal
from agents.memory.base import MemorySpec, ModelSettings
from agents.memory.scan import Layout, ScanMemory, full_precision, widen
from agents.memory.ssm import causal_conv, check_step_sizes
from agents.settings import Settings, param

__all__ = ["Mamba", "MambaConfig"]  # agents.memory exports them too


@dataclass
class MambaConfig(Settings):
    """A selective state-space memory (``model.memory: mamba``, agents/memory/mamba.py): ``model.memory_layers``
    residual Mamba blocks of width ``model.memory_size``, in pure PyTorch on the shared scan."""

    state_size: int = param(16, "SSM states per inner channel (N)", low=1)
    expand: int = param(2, "inner width = expand x memory_size", low=1)
    conv_size: int = param(4, "steps of the causal depthwise convolution before the SSM (1: none)", low=1)
    dt_rank: int = param(0, "rank of the step-size projection (0: ceil(memory_size / 16))", low=0)
    dt_min: float = param(0.001, "smallest initial step size", low=1e-6)
    dt_max: float = param(0.1, "largest initial step size", low=1e-6)

    def check(self, prefix: str) -> None:
        check_step_sizes(self, prefix)


class MambaBlock(nn.Module):
    """One residual Mamba block of width ``dim``."""

    def __init__(self, dim: int, config: MambaConfig) -> None:
        super().__init__()
        inner, states, kernel = config.expand * dim, config.state_size, config.conv_size
        rank = config.dt_rank or math.ceil(dim / 16)
        self.inner, self.states, self.kernel, self.rank = inner, states, kernel, rank
        self.conv_size = (kernel - 1) * inner
        self.state_size = self.conv_size + inner * states
        self.norm = nn.LayerNorm(dim)
        self.project_in = orthogonal(nn.Linear(dim, 2 * inner, bias=False), 1.0)
        self.conv = nn.Conv1d(inner, inner, kernel, groups=inner)  # applied to (k - 1) earlier steps + the sequence
        self.select = nn.Linear(inner, rank + 2 * states, bias=False)  # Delta's low-rank input, B and C
        self.step_size = nn.Linear(rank, inner)
        step = torch.exp(
            torch.rand(inner) * (math.log(config.dt_max) - math.log(config.dt_min)) + math.log(config.dt_min)
        )
        with torch.no_grad():
            self.step_size.bias.copy_(step + torch.log(-torch.expm1(-step)))  # softplus^-1(step)
        self.a_log = nn.Parameter(torch.log(torch.arange(1, states + 1, dtype=torch.float32)).repeat(inner, 1))
        self.skip = nn.Parameter(torch.ones(inner))
        self.project_out = orthogonal(nn.Linear(inner, dim, bias=False), 1.0)

    def forward(self, x: Tensor, state: Tensor, layout: Layout) -> tuple[Tensor, Tensor]:
        main, gate = self.project_in(self.norm(x)).chunk(2, dim=-1)  # (N, E) each
        main, tail = causal_conv(self.conv, layout.pad(main), state[:, : self.conv_size])  # (S, P, E)
        main = layout.unpad(main)  # (N, E)
        delta, b, c = self.select(main).split((self.rank, self.states, self.states), dim=-1)
        step = F.softplus(widen(self.step_size(delta)))  # (N, E); Delta in fp32: it sets the decays exp(Delta A)
        rate = -torch.exp(self.a_log.to(step.dtype))  # A (E, N)
        wide = widen(main)
        start = widen(state[:, self.conv_size :].reshape(-1, self.inner, self.states))

        def build(step: Tensor, wide: Tensor, b: Tensor, c: Tensor) -> tuple[Tensor, Tensor]:
            # decays exp(Delta A) and inputs Delta x B^T: (n, E, N) each, for a block of n steps only
            return torch.exp(step.unsqueeze(-1) * rate), (step * wide).unsqueeze(-1) * b.unsqueeze(1)

        def readout(h: Tensor, step: Tensor, wide: Tensor, b: Tensor, c: Tensor) -> Tensor:
            # C h: (n, E); a product and a sum, 1.7x faster forward + backward than a batched (E, N) @ (N, 1)
            return (h * c.unsqueeze(1)).sum(-1)

        # the (N, E, N) decays, inputs and states never exist whole: the scan runs in blocks (Layout.scan_readout),
        # in fp32 under bf16 too
        with full_precision(x.device):
            read, last = layout.scan_readout(build, readout, (step, wide, widen(b), widen(c)), start)
        y = self.project_out(((read + self.skip * wide) * F.silu(widen(gate))).to(x.dtype))
        return x + y, torch.cat((tail.to(state.dtype), last.flatten(1).to(state.dtype)), dim=1)


class Mamba(ScanMemory):
    """``layers`` Mamba blocks of width ``dim`` (the model's ``memory_size``)."""

    def __init__(self, config: MambaConfig, input_size: int, dim: int, layers: int) -> None:
        super().__init__(input_size, dim, [MambaBlock(dim, config) for _ in range(layers)])


def build(config: ModelSettings, input_size: int) -> Mamba:
    """``model.memory_layers`` Mamba blocks of width ``model.memory_size``, with the block ``model.mamba``."""
    return Mamba(config.mamba, input_size, config.memory_size, config.memory_layers)


MEMORIES = (MemorySpec("mamba", "Mamba-PPO", "#882255", build, settings=MambaConfig, order=60),)  # wine
